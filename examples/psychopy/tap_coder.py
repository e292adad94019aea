"""A vibrofocus tap in a PsychoPy Coder experiment: a fixation cross, and on the frame that
shows "tap" a tap at location 5, 6 dB below the design; its onsets go to the data file.

Run it with a running ``vibrofocus serve-osc --port 9000 --log taps.csv`` (the default), or
with ``--in-process`` to open the simulated rig here. Needs ``pip install 'vibrofocus[psychopy]'``
in PsychoPy's Python (or PsychoPy installed beside vibrofocus).
"""

import argparse

from psychopy import core, data, visual

from vibrofocus.psychopy import TapStimulus

parser = argparse.ArgumentParser()
parser.add_argument("--in-process", action="store_true", help="open the simulated rig here (no serve-osc)")
parser.add_argument("--port", type=int, default=9000, help="serve-osc's UDP port")
parser.add_argument("--out", default="data/tap_coder", help="data file name, without .csv")
parser.add_argument("--trials", type=int, default=3)
args = parser.parse_args()

win = visual.Window(size=(800, 600), units="height", fullscr=False)
text = visual.TextStim(win, text="+")
exp = data.ExperimentHandler(name="tap_coder", dataFileName=args.out)
tap = (TapStimulus.in_process("simulated", seed=1, anywhere=False, name="tap") if args.in_process
       else TapStimulus.osc(port=args.port, name="tap"))

for trial in range(args.trials):
    text.text = "+"
    for _ in range(30):  # half a second of fixation at 60 Hz
        text.draw()
        win.flip()
    tap.set(location=5, level_db=-6.0)
    text.text = "tap"
    text.draw()
    win.callOnFlip(tap.play)  # the tap is asked on the flip that shows "tap"
    flip_s = win.flip()
    exp.addData("trial", trial)
    exp.addData("text_onset_s", flip_s)
    result = tap.store(exp)  # tap.tap_id, tap.onset_host_s, tap.onset_device_s, ... in the data file
    if not result.played:
        print("tap refused:", result.error)
    exp.nextEntry()

print("data file:", exp.saveAsWideText(args.out + ".csv", delim=","))
tap.close()
win.close()
core.quit()
