"""
Trial markers on Lab Streaming Layer
====================================

``vibrofocus simulate-study --lsl`` (and ``study run --lsl``, ``serve --lsl``) opens the LSL
outlet ``vibrofocus-markers`` (type ``Markers``) and sends one short event code per cue,
stimulus onset and answer (``cue``, ``tap/<method>/<phase>/study<N>``, ``answer``), with
the marker's whole record as JSON on a second stream, ``vibrofocus-markers-detail``, at the
same timestamp. Each is stamped with the event's own time on LSL's clock, so a recorder
(LabRecorder, an EEG amplifier's LSL app) puts the onsets on the same time axis as its
other streams. Here two pylsl inlets in the same script receive the markers of one
simulated participant (a perceptual model, not data). Needs ``pip install
'vibrofocus[lsl]'``.
"""

import json
import tempfile
from collections import Counter
from pathlib import Path

import pylsl

from vibrofocus.io.lsl import stable_source_id
from vibrofocus.participant_models import simulate_studies
from vibrofocus.studies import lsl_markers


def pull_all(inlet):
    """Every sample the inlet holds, with its timestamp."""
    got = []
    while True:
        sample, stamp = inlet.pull_sample(timeout=2.0)
        if sample is None:
            return got
        got.append((stamp, sample[0]))


with tempfile.TemporaryDirectory() as tmp:
    db = Path(tmp) / "study.sqlite"
    # The source id the commands derive from the study database: a resumed run keeps it.
    with lsl_markers(source_id=stable_source_id(db)) as outlet:
        # The inlets connect before the first trial: LSL keeps no marker sent to nobody.
        inlets = []
        for source_id in (outlet.source_id, f"{outlet.source_id}-detail"):
            found = pylsl.resolve_bypred(f"source_id='{source_id}'", 1, 30.0)
            inlets.append(pylsl.StreamInlet(found[0], max_buflen=600))
            inlets[-1].open_stream(timeout=30.0)
        simulate_studies(db, n_participants=1, seed=2)
        codes, details = (pull_all(inlet) for inlet in inlets)

print(f"{len(codes)} markers, {len(set(c for _, c in codes))} distinct codes:")
for code, n in sorted(Counter(c for _, c in codes).items()):
    print(f"  {code:32s} {n:4d}")
for (stamp, code), (_, detail) in list(zip(codes, details))[:6]:
    marker = json.loads(detail)
    print(f"{stamp:14.6f} s  {code:30s} trial {marker['trial']:2d} target {marker['target']}  "
          f"response {marker['response']}")
