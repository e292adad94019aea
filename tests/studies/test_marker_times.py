"""The times of the study engine's markers: onsets at the device's output, answers in their trial."""

from __future__ import annotations

import numpy as np
import pytest

from vibrofocus.studies import StudyStore
from vibrofocus.studies.markers import sending_markers


class Clock:
    """The engine's ``time.monotonic``, moving 1 ms per reading and as long as each play lasts."""

    def __init__(self):
        self.now = 1000.0

    def monotonic(self):
        self.now += 1e-3
        return self.now


class LaggingRig:
    """The simulated rig, as an audio interface whose output runs 25 ms behind the hand-over.

    Like the audio rig, its play returns once the drive has played out: the clock moves on
    by the latency and the drive's duration.
    """

    LATENCY_S = 0.025

    def __init__(self, rig, clock):
        self.rig, self.clock, self.onsets = rig, clock, []

    def play(self, drives):
        from vibrofocus.rigs import DeviceOnset

        onset = self.rig.play(drives)
        host = self.clock.monotonic()
        self.clock.now += self.LATENCY_S + drives.shape[1] / self.rig.fs
        self.onsets.append(DeviceOnset(host, onset.device_s, onset.clock, latency_s=self.LATENCY_S))
        return self.onsets[-1]


class Answering:
    """Answers location 4 with a fixed response time (s), whatever time really passed."""

    def __init__(self, rt_s):
        self.rt_s = rt_s

    def respond(self, presentation):
        from vibrofocus.studies.engine import Response

        return Response(4, self.rt_s)


@pytest.mark.parametrize("rt_s", [30.0, 0.001])  # longer than the run takes; shorter than the output latency
def test_onsets_are_stamped_at_the_output_and_answers_between_their_stimulus_and_the_next_cue(tmp_path, monkeypatch,
                                                                                              rt_s):
    from types import SimpleNamespace

    from vibrofocus.rendering import render
    from vibrofocus.rigs import make_rig
    from vibrofocus.studies import engine as engine_module
    from vibrofocus.studies.engine import StudyEngine

    clock = Clock()
    monkeypatch.setattr(engine_module, "time", SimpleNamespace(monotonic=clock.monotonic, sleep=None))

    rig = make_rig("simulated", seed=3)
    H = rig.transfer(rig.layout.points_xy, np.fft.rfftfreq(4096, 1 / rig.fs))
    lagging = LaggingRig(rig, clock)
    got: list[tuple[dict, float]] = []
    with StudyStore(tmp_path / "s.db") as store:
        store.add_participant("p1")
        sid = store.create_session("p1", 1, seed=5, config={"repetitions": 2, "n_training": 0, "methods": ["inverse"],
                                                            "locations": [4, 6]})
        engine = StudyEngine(store, sid, lagging, renderer=lambda m, t: render(m, H, rig.fs, rig.layout, t).drives)
        with sending_markers(lambda marker, t: got.append((dict(marker), t))):
            engine.run(Answering(rt_s))
        stored = [e.payload for e in store.events(sid, kind="answer")]
    assert [m["event"] for m, _ in got] == ["cue", "stimulus_onset", "answer"] * 4
    onsets = [t for m, t in got if m["event"] == "stimulus_onset"]
    # At the drive's first sample leaving the device: the hand-over plus the latency the rig gave.
    assert onsets == [o.host_s + LaggingRig.LATENCY_S for o in lagging.onsets]
    assert {m["onset_latency_s"] for m, _ in got if m["event"] == "stimulus_onset"} == {LaggingRig.LATENCY_S}
    assert [a["onset_s"] for a in stored] == [o.host_s for o in lagging.onsets]  # the stored onsets are unchanged
    stamps = [t for _, t in got]
    assert stamps == sorted(stamps)  # no answer before its stimulus, none after the next cue
    answers = [t for m, t in got if m["event"] == "answer"]
    if rt_s > 1.0:  # a response time longer than the run took: stamped when the answer came
        assert all(o < a < o + rt_s for a, o in zip(answers, onsets))
    else:  # shorter than the output latency: at the stimulus, not before it
        assert answers == onsets
    assert [m["rt_s"] for m, _ in got if m["event"] == "answer"] == [rt_s] * 4  # the response time as given
