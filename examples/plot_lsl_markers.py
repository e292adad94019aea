"""
Trial markers on Lab Streaming Layer
====================================

``vibrofocus simulate-study --lsl`` (and ``study run --lsl``, ``serve --lsl``) opens the LSL
outlet ``vibrofocus-markers`` (type ``Markers``) and sends one JSON marker per cue,
stimulus onset and answer. Each is stamped with the event's own time on LSL's clock, so a
recorder (LabRecorder, an EEG amplifier's LSL app) puts the onsets on the same time axis
as its other streams. Here a pylsl inlet in the same script receives the markers of one
simulated participant (a perceptual model, not data). Needs ``pip install
'vibrofocus[lsl]'``.
"""

import json
import tempfile
from collections import Counter
from pathlib import Path

import pylsl

from vibrofocus.simulation import simulate_studies
from vibrofocus.studies import lsl_markers

with tempfile.TemporaryDirectory() as tmp, lsl_markers() as outlet:
    # The inlet connects before the first trial: LSL keeps no marker sent to nobody.
    found = pylsl.resolve_bypred(f"source_id='{outlet.source_id}'", 1, 30.0)
    inlet = pylsl.StreamInlet(found[0], max_buflen=600)
    inlet.open_stream(timeout=30.0)
    simulate_studies(Path(tmp) / "study.sqlite", n_participants=1, seed=2)
    markers = []
    while True:
        sample, stamp = inlet.pull_sample(timeout=2.0)
        if sample is None:
            break
        markers.append((stamp, json.loads(sample[0])))

print(f"{len(markers)} markers:", dict(Counter(m["event"] for _, m in markers)))
for stamp, marker in markers[:6]:
    print(f"{stamp:14.6f} s  {marker['event']:15s} study {marker['study']} {marker['phase']:8s} trial "
          f"{marker['trial']:2d}  {marker['method']:11s} target {marker['target']}  response {marker['response']}")
