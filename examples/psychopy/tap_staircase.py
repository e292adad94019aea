"""A staircase on a tap's level, headless, on the simulated rig: PsychoPy's StairHandler
varies the level (dB re the design) by a 1-up/2-down rule, a model observer answers, and each
tap's level and onsets (host and device clocks) are stored in PsychoPy's data file.

The observer is a model, not a participant: it feels a tap with probability
``1 / (1 + exp(-(level - threshold) / slope))`` (threshold -18 dB, slope 2 dB), drawn from a
seeded generator. Swap it for a keyboard response in a real experiment. No window is opened,
so it runs on a server. Needs ``pip install 'vibrofocus[psychopy]'`` (or PsychoPy beside
vibrofocus).
"""

import argparse
import math

import numpy as np
from psychopy import data

from vibrofocus.psychopy import TapStimulus

parser = argparse.ArgumentParser()
parser.add_argument("--out", default="data/tap_staircase", help="data file name, without .csv")
parser.add_argument("--seed", type=int, default=7)
parser.add_argument("--port", type=int, default=0, help="play through serve-osc on this port (0: in-process)")
args = parser.parse_args()

rng = np.random.default_rng(args.seed)
THRESHOLD_DB, SLOPE_DB = -18.0, 2.0

exp = data.ExperimentHandler(name="tap_staircase", dataFileName=args.out)
stairs = data.StairHandler(startVal=-6.0, stepType="lin", stepSizes=[4.0, 2.0, 1.0], nUp=1, nDown=2,
                           nTrials=20, nReversals=6, minVal=-40.0, maxVal=0.0, name="stairs")
exp.addLoop(stairs)
tap = (TapStimulus.osc(port=args.port, name="tap") if args.port
       else TapStimulus.in_process("simulated", seed=args.seed, anywhere=False, name="tap"))

for level in stairs:
    tap.set(location=5, level_db=float(level))
    tap.play()  # with a window: win.callOnFlip(tap.play), then win.flip()
    result = tap.store(exp)
    felt = result.played and rng.random() < 1 / (1 + math.exp(-(level - THRESHOLD_DB) / SLOPE_DB))
    stairs.addResponse(int(felt))
    exp.addData("felt", int(felt))
    exp.nextEntry()

tap.close()
print(f"levels played: {sorted(set(stairs.intensities))}")
print("data file:", exp.saveAsWideText(args.out + ".csv", delim=","))
