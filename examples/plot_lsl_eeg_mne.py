"""
Tap markers and an EEG recording in MNE
=======================================

An EEG lab records the amplifier and vibrofocus's marker stream together with LabRecorder,
reads the XDF file with ``pyxdf`` and epochs the EEG on the taps in MNE-Python. This example
does all of it on one computer, with stand-ins for the two things it does not have:

- a **simulated EEG amplifier**: an LSL stream of 8 channels at 250 Hz (noise, plus a
  made-up evoked response 50 ms after each tap over the contralateral C3; not a model of
  real somatosensory potentials);
- a **minimal recorder**: pylsl inlets on both streams, written to an XDF file with a
  few lines of Python (LabRecorder writes the same chunks).

The participant is simulated too (a perceptual model, not data). The markers are the short
codes of :doc:`/lab-streaming-layer` (``cue``, ``tap/<method>/<phase>/study<N>``,
``answer``): they become ``mne.Annotations``, then events and epochs, one condition per
method. The evoked response peaks 50 ms after the tap markers: the two streams are aligned
on LSL's clock. Needs ``pip install 'vibrofocus[lsl]' mne pyxdf``.
"""

import shutil
import struct
import tempfile
import threading
from pathlib import Path

import matplotlib.pyplot as plt
import mne
import numpy as np
import pylsl
import pyxdf

from vibrofocus.io.lsl import stable_source_id
from vibrofocus.rendering import render
from vibrofocus.rigs import make_rig
from vibrofocus.participant_models import SimulatedParticipant
from vibrofocus.studies import StudyEngine, StudyStore, lsl_markers, sending_markers

FS_EEG = 250.0
CHANNELS = ["Fz", "FCz", "Cz", "C3", "C4", "CP3", "CP4", "Pz"]
LATENCY_S = 0.050  # of the made-up evoked response after each tap

# %%
# The simulated EEG amplifier
# ---------------------------
# It stamps its samples on LSL's clock, as an amplifier's LSL app does. A tap it learns
# of through the marker sink (the marker's own time on LSL's clock) adds a response to
# the samples it has not sent yet; it sends only samples 0.2 s old, so no tap comes late.


class SimulatedAmplifier(threading.Thread):
    def __init__(self, seed=0):
        super().__init__(daemon=True)
        info = pylsl.StreamInfo("simulated-eeg", "EEG", len(CHANNELS), FS_EEG, pylsl.cf_float32,
                                f"simulated-eeg-{seed}")
        chans = info.desc().append_child("channels")
        for name in CHANNELS:
            ch = chans.append_child("channel")
            ch.append_child_value("label", name)
            ch.append_child_value("unit", "microvolts")
            ch.append_child_value("type", "EEG")
        self.outlet = pylsl.StreamOutlet(info, chunk_size=10)
        self.rng = np.random.default_rng(seed)
        self.taps = []  # LSL times
        self.done = threading.Event()
        self.start_s = pylsl.local_clock()
        self.sent = 0
        self.end_s = None  # set by finish()

    def on_marker(self, to_lsl):
        def sink(marker, host_time_s):
            if marker["event"] == "stimulus_onset":
                self.taps.append(to_lsl(host_time_s))
        return sink

    def samples(self, n):
        t = self.start_s + (self.sent + np.arange(n)) / FS_EEG
        x = 2.0 * self.rng.standard_normal((n, len(CHANNELS)))  # µV
        for tap in list(self.taps):
            lag = t - tap - LATENCY_S
            wave = -8.0 * np.exp(-0.5 * (lag / 0.012) ** 2) + 4.0 * np.exp(-0.5 * ((lag - 0.05) / 0.02) ** 2)
            x[:, CHANNELS.index("C3")] += wave
            x[:, CHANNELS.index("CP3")] += 0.6 * wave
            x[:, CHANNELS.index("Cz")] += 0.3 * wave
        return x.astype(np.float32), t

    def run(self):
        while not self.done.wait(0.04):
            n = self.until() - self.sent
            if n > 0:
                x, t = self.samples(n)
                self.outlet.push_chunk(x, float(t[-1]))  # the stamp of the last sample
                self.sent += n

    def until(self):
        now = pylsl.local_clock() - 0.2
        if self.end_s is not None and now >= self.end_s:
            self.done.set()
            now = self.end_s
        return int((now - self.start_s) * FS_EEG)

    def finish(self, after_s=0.5):
        """Record ``after_s`` more seconds, then stop."""
        self.end_s = pylsl.local_clock() + after_s
        self.join()


# %%
# A minimal XDF recorder
# ----------------------
# XDF is a sequence of chunks (length, tag, content): a file header, one header per
# stream (its LSL metadata as XML), samples, clock offsets and a footer per stream.


def _chunk(tag, content):
    body = struct.pack("<H", tag) + content
    return struct.pack("<BQ", 8, len(body)) + body


def _n(value):
    return struct.pack("<BQ", 8, value)


def write_xdf(path, recorded):
    """``recorded``: (stream id, StreamInfo, samples, timestamps, clock offset) per stream."""
    out = [b"XDF:", _chunk(1, b'<?xml version="1.0"?><info><version>1.0</version></info>')]
    for sid, info, samples, stamps, offset in recorded:
        out.append(_chunk(2, struct.pack("<I", sid) + info.as_xml().encode()))
        body = bytearray(struct.pack("<I", sid) + _n(len(stamps)))
        for sample, stamp in zip(samples, stamps):
            body += struct.pack("<Bd", 8, stamp)
            if info.channel_format() == pylsl.cf_string:
                for value in sample:
                    body += _n(len(value.encode())) + value.encode()
            else:
                body += np.asarray(sample, "<f4").tobytes()
        out.append(_chunk(3, bytes(body)))
        # The recorder's clock minus the stream's (zero here: one computer), as LabRecorder measures it.
        out.append(_chunk(4, struct.pack("<Idd", sid, stamps[-1], offset)))
        footer = (f'<?xml version="1.0"?><info><first_timestamp>{stamps[0]}</first_timestamp><last_timestamp>'
                  f"{stamps[-1]}</last_timestamp><sample_count>{len(stamps)}</sample_count></info>")
        out.append(_chunk(6, struct.pack("<I", sid) + footer.encode()))
    Path(path).write_bytes(b"".join(out))


def connect(source_id):
    found = pylsl.resolve_bypred(f"source_id='{source_id}'", 1, 30.0)
    inlet = pylsl.StreamInlet(found[0], max_buflen=600)
    inlet.open_stream(timeout=30.0)
    return inlet


# %%
# One session with the EEG running
# --------------------------------
# Twelve trials (funneling and the inverse filter at three locations, twice), 0.6 s apart
# so that the epochs do not overlap, on the simulated forearm. The amplifier hears of each
# tap from the same marker sink as the LSL outlet.

tmp = Path(tempfile.mkdtemp())
rig = make_rig("simulated", seed=3)
H = rig.transfer(rig.layout.points_xy, np.fft.rfftfreq(4096, 1 / rig.fs))
with StudyStore(tmp / "study.sqlite") as store, lsl_markers(source_id=stable_source_id(tmp / "study.sqlite")) as markers:
    store.add_participant("sim-eeg", simulated=True)
    sid = store.create_session("sim-eeg", 1, seed=1, config={
        "repetitions": 2, "n_training": 0, "methods": ["funneling", "inverse"], "locations": [3, 5, 7]})
    amplifier = SimulatedAmplifier()
    eeg_in, marker_in = connect(amplifier.outlet.get_info().source_id()), connect(markers.source_id)
    amplifier.start()
    engine = StudyEngine(store, sid, rig, renderer=lambda m, t: render(m, H, rig.fs, rig.layout, t).drives)
    with sending_markers(amplifier.on_marker(markers.lsl_time)):
        engine.run(SimulatedParticipant(rig, seed=11), pace_s=0.6)
    amplifier.finish()  # the last tap's epoch is whole
    recorded = []
    for sid_xdf, inlet in enumerate((eeg_in, marker_in), start=1):
        samples, stamps = [], []
        while True:
            chunk, times = inlet.pull_chunk(timeout=1.0, max_samples=100_000)
            if not times:
                break
            samples += chunk
            stamps += times
        recorded.append((sid_xdf, inlet.info(), samples, stamps, inlet.time_correction()))
write_xdf(tmp / "session.xdf", recorded)

# %%
# pyxdf, then MNE
# ---------------
# The marker stream's codes become annotations on the EEG's time axis; the taps become
# events, one event id per code, and epochs around them.

streams, _ = pyxdf.load_xdf(str(tmp / "session.xdf"))
eeg = next(s for s in streams if s["info"]["type"][0] == "EEG")
codes = next(s for s in streams if s["info"]["name"][0] == "vibrofocus-markers")
acquisition = codes["info"]["desc"][0]["acquisition"][0]
print("marker stream made by", acquisition["software"][0], acquisition["version"][0])

raw = mne.io.RawArray(eeg["time_series"].T * 1e-6, mne.create_info(CHANNELS, FS_EEG, "eeg"), verbose=False)
t0 = eeg["time_stamps"][0]
raw.set_annotations(mne.Annotations(onset=codes["time_stamps"] - t0, duration=0.0,
                                    description=[c[0] for c in codes["time_series"]]))
events, event_id = mne.events_from_annotations(raw, regexp="^tap/", verbose=False)
print("event codes:", sorted(set(raw.annotations.description)))
epochs = mne.Epochs(raw, events, event_id, tmin=-0.1, tmax=0.4, baseline=(None, 0), preload=True, verbose=False)
print(epochs)

# %%
# The evoked response per method, at C3: its trough 50 ms after the tap markers, within
# an EEG sample (an event is placed on the nearest sample).

fig, ax = plt.subplots(figsize=(6, 3.2), layout="constrained")
for method in ("funneling", "inverse"):
    evoked = epochs[method].average()
    trace = evoked.get_data(picks="C3")[0] * 1e6
    ax.plot(evoked.times * 1e3, trace, label=f"{method} ({len(epochs[method])} taps)")
    print(f"{method}: C3 trough at {1e3 * evoked.times[np.argmin(trace)]:.0f} ms after the tap marker "
          f"(made at {1e3 * LATENCY_S:.0f} ms; one EEG sample is {1e3 / FS_EEG:.0f} ms)")
ax.axvline(0, color="0.5", lw=0.8)
ax.set(xlabel="time after the tap marker (ms)", ylabel="C3 (µV)", title="Epochs on vibrofocus's tap markers")
ax.legend(frameon=False)

shutil.rmtree(tmp)
