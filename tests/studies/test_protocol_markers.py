"""The markers (LSL codes and details) of a protocol's sessions: protocol and block on every
marker, a threshold block's taps coded ``.../threshold`` with their staircase level."""

from __future__ import annotations

from vibrofocus.io.lsl import marker_code
from vibrofocus.studies import StudyStore
from vibrofocus.studies.engine import Response, StudyEngine
from vibrofocus.studies.markers import sending_markers
from vibrofocus.studies.protocol_files import parse_protocol
from tests.web.tiny_protocol import FELT, TINY_PROTOCOL


class _Felt:
    """Answers the threshold block with :data:`FELT`, in order."""

    def __init__(self) -> None:
        self.k = 0

    def respond(self, presentation):
        self.k += 1
        return Response(FELT[self.k - 1], 0.4)


def test_a_threshold_blocks_markers_name_the_protocol_and_their_level(tmp_path):
    protocol = parse_protocol(TINY_PROTOCOL, "tiny.toml")
    got = []
    with StudyStore(tmp_path / "s.sqlite") as store:
        store.add_participant("P01")
        sid = store.create_session("P01", 1, seed=1, config=protocol.session_config(0))
        engine = StudyEngine(store, sid, None, dry_run=True)
        with sending_markers(lambda marker, t: got.append(marker)):
            engine.run(_Felt(), max_trials=3)
    taps = [m for m in got if m["event"] == "stimulus_onset"]
    assert [marker_code(m) for m in taps] == ["dry/funneling/main/threshold"] * 3
    assert [m["level_db"] for m in taps] == [-6.0, -10.0, -8.0]  # the staircase's, from the answers so far
    assert {(m["protocol"], m["block"], m["task"]) for m in got} == {("tiny-threshold", 0, "threshold")}
    assert [marker_code(m) for m in got if m["event"] != "stimulus_onset"] == ["cue", "answer"] * 3


def test_a_localization_tap_keeps_its_study_code():
    assert marker_code({"event": "stimulus_onset", "method": "inverse", "phase": "main", "study": 1,
                        "protocol": "paper-study1", "block": 0}) == "tap/inverse/main/study1"


def test_a_presentation_names_its_sessions_block(tmp_path):
    """The engine tells a responder which block of its protocol a trial is from (simulated
    participants draw a later block's noise from streams of its own)."""
    protocol = parse_protocol(TINY_PROTOCOL, "tiny.toml")
    seen = []

    class _Blocks(_Felt):
        def respond(self, presentation):
            seen.append(presentation.block)
            return super().respond(presentation)

    with StudyStore(tmp_path / "s.sqlite") as store:
        store.add_participant("P01")
        for block in (0, 1):
            config = {**protocol.session_config(0), "block": block}
            sid = store.create_session("P01", 1, seed=1, config=config)
            StudyEngine(store, sid, None, dry_run=True).run(_Blocks(), max_trials=1)
    assert seen == [0, 1]
