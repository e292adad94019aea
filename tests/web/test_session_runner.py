"""The trial loop on its own, with a real StudyStore, and the serve command's output."""

from __future__ import annotations

import contextlib
import os
import subprocess
import sys
import time

import httpx
import numpy as np
import pytest

from vibrofocus.studies import StudyStore
from vibrofocus.web.session_runner import Pace, SessionRunner, drive_sha256

from .conftest import free_port

QUICK = Pace(ready_s=0.02, cue_to_stimulus_s=0.02, after_answer_s=0.0)


class CountingRig:
    """A stand-in rig that records what it was asked to play (the real rigs are tested elsewhere)."""

    def __init__(self):
        self.played = []
        self.stops = 0

    def play(self, drive):
        self.played.append(np.array(drive))

    def stop(self):
        self.stops += 1

    @contextlib.contextmanager
    def reserve(self, owner):
        # As Rig.reserve on a rig that is not one job at a time: nothing to hold.
        yield self


def wait_for(predicate, timeout=5.0):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return
        time.sleep(0.01)
    raise AssertionError("condition not reached")


def one_trial_runner(store):
    """A session of one Study 1 trial, its counting rig, and a runner that needs a page."""
    sid = store.create_session("P01", 1, seed=2, config={"n_training": 0, "repetitions": 1, "methods": ["inverse"], "locations": [4]})
    rig = CountingRig()
    return sid, rig, SessionRunner(store, sid, stimulus=lambda trial: np.ones((4, 8)), rig=rig, pace=QUICK)


@pytest.fixture
def store(tmp_path):
    with StudyStore(tmp_path / "s.sqlite") as st:
        st.add_participant("P01")
        yield st


def test_runner_plays_answers_and_completes(store):
    sid = store.create_session("P01", 1, seed=3, config={"n_training": 1, "repetitions": 1, "methods": ["funneling"], "locations": [2, 5]})
    rig = CountingRig()
    drive = lambda trial: np.full((4, 8), float(trial.target))  # noqa: E731
    runner = SessionRunner(store, sid, stimulus=drive, rig=rig, pace=QUICK, require_page=False)
    store.set_status(sid, "running")
    runner.start()
    for trial in store.planned_trials(sid):
        wait_for(lambda: runner.snapshot()["state"] == "respond" and runner.snapshot()["trial_index"] == trial.trial_index)
        store.record_answer(sid, trial.trial_index, trial.target, 0.3, answer_id=f"id-{trial.trial_index}",
                            drive_sha256=runner.drive_sha_for(trial.trial_index))
        runner.notify_answer(trial.trial_index)
    wait_for(lambda: runner.snapshot()["state"] == "done")
    assert store.session(sid).status == "completed"
    assert [int(d[0, 0]) for d in rig.played] == [t.target for t in store.planned_trials(sid)]
    assert [a.drive_sha256 for a in store.answers(sid)] == [drive_sha256(d) for d in rig.played]
    assert rig.stops >= 1, "the rig is left silent at the end"


def test_runner_holds_the_cue_until_a_page_is_there_and_while_paused(store):
    sid = store.create_session("P01", 2, seed=1, config={"n_training": 0, "repetitions": 1, "methods": ["inverse"], "locations": [1]})
    runner = SessionRunner(store, sid, pace=QUICK)
    runner.start()
    time.sleep(0.3)
    snap = runner.snapshot()
    assert snap["state"] == "ready" and snap["waiting_for_page"]
    assert store.events(sid, kind="cue") == [], "no cue without a participant page"
    runner.pause()
    token = runner.page_attach(-1)
    wait_for(lambda: runner.snapshot()["state"] == "paused")
    time.sleep(0.2)
    assert store.events(sid, kind="cue") == [], "no cue while paused"
    runner.resume()
    wait_for(lambda: runner.snapshot()["state"] == "cue")
    # The page learns of the cue and asks again, saying it has seen it.
    runner.page_detach(token)
    runner.page_attach(runner.snapshot()["seq"])
    wait_for(lambda: runner.snapshot()["state"] == "respond")
    assert [e.payload["trial_index"] for e in store.events(sid, kind="cue")] == [0]
    runner.stop()
    assert not runner.running
    assert runner.snapshot()["state"] == "stopped"


def test_no_stimulus_once_the_page_that_was_cued_has_gone(store):
    sid, rig, runner = one_trial_runner(store)
    token = runner.page_attach(-1)
    runner.start()
    wait_for(lambda: runner.snapshot()["state"] == "cue")
    cue_seq = runner.snapshot()["seq"]
    runner.page_detach(token)  # the page is closed (or reloaded) right after the cue
    wait_for(lambda: store.events(sid, kind="cue_cancelled"), timeout=3)
    assert rig.played == [] and store.events(sid, kind="stimulus_onset") == []
    # A page that has not seen the new cue does not count either; one that has, does.
    token = runner.page_attach(cue_seq)
    wait_for(lambda: runner.snapshot()["state"] == "cue" and runner.snapshot()["seq"] != cue_seq)
    assert rig.played == []
    runner.page_detach(token)
    runner.page_attach(runner.snapshot()["seq"])
    wait_for(lambda: runner.snapshot()["state"] == "respond")
    assert len(rig.played) == 1 and len(store.events(sid, kind="stimulus_onset")) == 1
    runner.stop()


def test_with_two_screens_the_stimulus_waits_for_the_one_catching_up(store):
    # One screen shows the cue; the other's request still carries an older state. The
    # stimulus waits (within the grace period) until both show the cue, so neither misses
    # the onset and asks for the trial again while the participant answers on the other.
    sid, rig, runner = one_trial_runner(store)
    token_a = runner.page_attach(-1)
    token_b = runner.page_attach(-1)
    runner.start()
    wait_for(lambda: runner.snapshot()["state"] == "cue")
    cue_seq = runner.snapshot()["seq"]
    runner.page_detach(token_a)
    runner.page_attach(cue_seq)  # screen A shows the cue; screen B is behind
    time.sleep(0.25)  # past the cue-to-stimulus time, within the grace period
    assert rig.played == [], "played while a connected screen had not shown the cue"
    runner.page_detach(token_b)
    runner.page_attach(cue_seq)
    wait_for(lambda: runner.snapshot()["state"] == "respond", timeout=1.0)
    assert len(rig.played) == 1
    runner.stop()


def test_a_screen_that_never_catches_up_does_not_hold_the_study(store):
    sid, rig, runner = one_trial_runner(store)
    token_a = runner.page_attach(-1)
    runner.page_attach(-1)  # screen B's request hangs on an old state
    runner.start()
    wait_for(lambda: runner.snapshot()["state"] == "cue")
    runner.page_detach(token_a)
    runner.page_attach(runner.snapshot()["seq"])
    wait_for(lambda: runner.snapshot()["state"] == "respond", timeout=3.0)
    assert len(rig.played) == 1 and store.events(sid, kind="cue_cancelled") == []
    runner.stop()


def test_serve_prints_token_and_warns_off_localhost(tmp_path):
    port = free_port()
    env = dict(os.environ, VIBROFOCUS_TOKEN="t" * 24)
    # 127.0.0.2 is loopback on Linux but not one of the addresses serve treats as local,
    # so it exercises the warning without exposing anything.
    proc = subprocess.Popen(
        [sys.executable, "-m", "vibrofocus", "serve", "--db", str(tmp_path / "s.sqlite"), "--host", "127.0.0.2",
         "--port", str(port), "--no-browser"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env,
    )
    try:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and proc.poll() is None:
            try:
                if httpx.get(f"http://127.0.0.2:{port}/api/rigs", headers={"X-Vibrofocus-Token": "t" * 24}, timeout=1).status_code == 200:
                    break
            except httpx.HTTPError:
                time.sleep(0.1)
    finally:
        proc.terminate()
        out, err = proc.communicate(timeout=10)
    assert "WARNING" in err and "127.0.0.2" in err
    assert "experimenter token (for the login page): " + "t" * 24 in out
    (link,) = [line.rsplit(" ", 1)[1] for line in out.splitlines() if line.startswith("one-time login link")]
    assert link.startswith(f"http://127.0.0.2:{port}/login/") and "t" * 24 not in link
    assert "?token=" not in out, "the token is never put in a URL"
    bad = subprocess.run([sys.executable, "-m", "vibrofocus", "serve", "--rig", "laser", "--no-browser",
                          "--db", str(tmp_path / "s.sqlite")], capture_output=True, text=True, timeout=60)
    assert bad.returncode == 2 and "rig" in bad.stderr


def test_the_web_writes_the_engines_payloads_and_a_paused_session_stays_paused(store):
    sid = store.create_session("P01", 1, seed=3, config={"n_training": 0, "repetitions": 1, "methods": ["inverse"], "locations": [2]})
    rig = CountingRig()
    runner = SessionRunner(store, sid, renderer=lambda method, target: np.ones((4, 8)), rig=rig, pace=QUICK, require_page=False)
    runner.start()
    wait_for(lambda: runner.snapshot()["state"] == "respond")
    (cue,) = store.events(sid, kind="cue")
    (onset,) = store.events(sid, kind="stimulus_onset")
    # The keys the study engine writes for every responder (tests/studies/test_engine.py).
    assert cue.payload == {"trial_index": 0, "beep": "page"}
    assert onset.payload == {"trial_index": 0, "method": "inverse", "target": 2, "played": True,
                             "drive_sha256": drive_sha256(np.ones((4, 8))), "levels": "paper", "level_db": 0.0,
                             "drive_peak_v": 1.0, "target_peak_um": None}  # a bare renderer predicts nothing
    runner.stop()
    assert store.session(sid).status == "running", "a stop (server shutdown) leaves the session to resume"
    # Rebuilt for a session stored as paused (a restart), the runner waits and sets nothing.
    store.set_status(sid, "paused")
    again = SessionRunner(store, sid, renderer=lambda method, target: np.ones((4, 8)), rig=rig, pace=QUICK, require_page=False)
    again.pause()
    again.start()
    wait_for(lambda: again.snapshot()["state"] == "paused")
    time.sleep(0.1)
    assert store.session(sid).status == "paused" and len(rig.played) == 1
    store.set_status(sid, "running")
    again.resume()
    wait_for(lambda: again.snapshot()["state"] == "respond")
    assert len(rig.played) == 2 and len(store.events(sid, kind="cue")) == 2
    again.stop()


class TroubledRig(CountingRig):
    """A stand-in rig whose first play is refused for 0.3 s to cool, and whose third loses samples."""

    _stop_epoch = 0  # read by the pacing of plays (rigs.safety.play_paced)

    def __init__(self):
        super().__init__()
        self.tries = 0

    def play(self, drive):
        from vibrofocus.errors import CoolingError
        from vibrofocus.rigs import XrunError

        self.tries += 1
        if self.tries == 1:
            raise CoolingError("drive refused: together with the plays before it, ... wait 0.3 s", wait_s=0.3)
        super().play(drive)
        if self.tries == 3:
            raise XrunError(None, "the audio stream reported output underflow while playing (injected)")


def test_the_web_and_the_terminal_wait_to_cool_and_present_an_xrun_trial_again_alike(store, tmp_path):
    # Issue 56, part C: one implementation (the engine) under both front-ends.
    import io

    from rich.console import Console

    from vibrofocus.studies import StudyEngine
    from vibrofocus.studies.terminal import TerminalResponder
    from vibrofocus.workflows import run_session

    config = {"n_training": 0, "repetitions": 1, "methods": ["inverse"], "locations": [2, 5]}
    renderer = lambda method, target: np.full((4, 8), float(target))  # noqa: E731
    web, terminal = (store.create_session("P01", 1, seed=3, config=config) for _ in range(2))
    rig = TroubledRig()
    runner = SessionRunner(store, web, renderer=renderer, rig=rig, pace=QUICK, require_page=False)
    runner.start()
    wait_for(lambda: runner.snapshot().get("cooling_s", 0) > 0, timeout=2)  # the experimenter's "cooling: N s"
    for trial in store.planned_trials(web):  # answered as the answer route does
        wait_for(lambda: runner.snapshot()["state"] == "respond" and runner.snapshot()["trial_index"] == trial.trial_index)
        store.record_answer(web, trial.trial_index, trial.target, 0.3, answer_id=f"id-{trial.trial_index}",
                            drive_sha256=runner.drive_sha_for(trial.trial_index))
        runner.notify_answer(trial.trial_index)
    wait_for(lambda: runner.snapshot()["state"] == "done")
    targets = [t.target for t in store.planned_trials(web)]
    out, keys = io.StringIO(), iter(str(t) for t in targets)
    rig = TroubledRig()
    summary = run_session(StudyEngine(store, terminal, rig, renderer=renderer),
                          TerminalResponder(console=Console(file=out, width=200), input_fn=lambda _: next(keys)))
    assert summary.status == "completed"
    printed = out.getvalue()
    assert "waiting 0.3 s for the actuators to cool" in printed and "presenting it again (1 of at most 1)" in printed

    def log(sid):
        return [(e.kind, e.payload.get("trial_index")) for e in store.events(sid)
                if e.kind in ("cue", "cooling", "stimulus_onset", "xrun", "answer")]

    assert log(web) == log(terminal) == [
        ("cue", 0), ("stimulus_onset", 0), ("cooling", 0), ("answer", 0),
        ("cue", 1), ("stimulus_onset", 1), ("xrun", 1), ("cue", 1), ("stimulus_onset", 1), ("answer", 1)]
    for sid in (web, terminal):  # every answer stored once
        assert [(a.trial_index, a.response) for a in store.answers(sid)] == [(0, (targets[0],)), (1, (targets[1],))]
