"""StudyEngine: every presented trial logged, every answer committed with its drive hash,
pause / abort / resume without loss or duplicates."""

import numpy as np
import pytest

from vibrofocus.errors import StudyError
from vibrofocus.rendering import render
from vibrofocus.rigs import make_rig
from vibrofocus.studies import StudyStore
from vibrofocus.studies.engine import ABORT, PAUSE, STOP, Again, Response, StudyEngine, calibration_renderer, drive_sha256

N = 4096  # the default window (a shorter one fails the causality check)


@pytest.fixture
def rig():
    return make_rig("simulated", seed=3)


@pytest.fixture
def renderer(rig):
    # Rendered from the forearm's true transfer: real drives without a calibration run.
    H = rig.transfer(rig.layout.points_xy, np.fft.rfftfreq(N, 1 / rig.fs))

    def _render(method, target):
        return render(method, H, rig.fs, rig.layout, target).drives

    return _render


@pytest.fixture
def store(tmp_path):
    with StudyStore(tmp_path / "s.db") as s:
        s.add_participant("p1")
        yield s


class Scripted:
    """A participant answering from a script: location numbers, 'pause' or 'abort'."""

    def __init__(self, script, resume=True):
        self.script = list(script)
        self.resume = resume
        self.seen = []

    def respond(self, presentation):
        self.seen.append(presentation.trial.trial_index)
        item = self.script.pop(0)
        return item if isinstance(item, str) else Response(item, 0.5 + 0.01 * len(self.seen))

    def wait_resume(self):
        return self.resume


def test_run_commits_each_answer_with_its_drive_hash_and_logs_cue_then_stimulus(store, rig, renderer):
    sid = store.create_session("p1", 1, seed=2, config={"repetitions": 1, "n_training": 1})
    engine = StudyEngine(store, sid, rig, renderer=renderer)
    summary = engine.run(Scripted([5] * 28))
    assert (summary.status, summary.n_answered, summary.n_trials, summary.n_run) == ("completed", 28, 28, 28)
    plan = store.planned_trials(sid)
    answers = store.answers(sid)
    for trial, ans in zip(plan, answers):
        assert ans.drive_sha256 == drive_sha256(renderer(trial.method, trial.target))
    assert rig.n_played == 28
    kinds = [e.kind for e in store.events(sid) if e.kind in ("cue", "stimulus_onset", "answer")]
    assert kinds == ["cue", "stimulus_onset", "answer"] * 28
    onsets = store.events(sid, kind="stimulus_onset")
    assert [e.payload["trial_index"] for e in onsets] == list(range(28))


def test_max_trials_then_resume_continues_at_first_unanswered(store, rig, renderer):
    sid = store.create_session("p1", 2, seed=4, config={"repetitions": 1, "n_training": 2})
    first = StudyEngine(store, sid, rig, renderer=renderer).run(Scripted([[5, 4]] * 10), max_trials=10)
    assert (first.status, first.n_answered) == ("running", 10)
    before = store.answers(sid)
    # A new engine (as after a crash) starts where the store says.
    participant = Scripted([[1, 2]] * 19)
    second = StudyEngine(store, sid, rig, renderer=renderer).run(participant)
    assert participant.seen[0] == 10
    assert second.status == "completed" and second.n_answered == 29
    after = store.answers(sid)
    assert after[:10] == before
    assert [a.trial_index for a in after] == list(range(29))
    assert {a.response for a in after[10:]} == {(1, 2)}


def test_pause_presents_the_trial_again_and_abort_keeps_answers(store, rig, renderer):
    sid = store.create_session("p1", 1, seed=6, config={"repetitions": 1, "n_training": 0})
    participant = Scripted([3, PAUSE, 4, ABORT])
    summary = StudyEngine(store, sid, rig, renderer=renderer).run(participant)
    assert participant.seen == [0, 1, 1, 2]
    assert summary.status == "aborted"
    assert [a.response for a in store.answers(sid)] == [(3,), (4,)]
    kinds = [e.kind for e in store.events(sid) if e.kind in ("pause", "resume", "abort")]
    assert kinds == ["pause", "resume", "abort"]
    # Resuming an aborted session continues at trial 2.
    participant = Scripted([7] * 25)
    assert StudyEngine(store, sid, rig, renderer=renderer).run(participant).status == "completed"
    assert participant.seen[0] == 2


def test_pause_then_no_resume_aborts(store, rig, renderer):
    sid = store.create_session("p1", 1, seed=6, config={"repetitions": 1, "n_training": 0})
    summary = StudyEngine(store, sid, rig, renderer=renderer).run(Scripted([PAUSE], resume=False))
    assert summary.status == "aborted" and summary.n_answered == 0


def test_bad_setup_and_bad_responder_are_refused(store, rig, renderer):
    with pytest.raises(StudyError, match="unknown session 42"):
        StudyEngine(store, 42, rig, renderer=renderer)
    sid = store.create_session("p1", 1, seed=1)
    with pytest.raises(StudyError, match="calibration"):
        StudyEngine(store, sid, rig)
    with pytest.raises(StudyError, match="expected a Response"):
        StudyEngine(store, sid, rig, renderer=renderer).run(Scripted(["maybe"]))
    with pytest.raises(StudyError, match="outside"):
        StudyEngine(store, sid, rig, renderer=renderer).run(Scripted([11]))
    assert store.answers(sid) == []


def test_calibration_renderer_uses_the_calibration(calibration_file):
    from vibrofocus.calibration import load_calibration

    cal = load_calibration(calibration_file)
    drives = calibration_renderer(cal, n_samples=N, levels="equal-peak")("inverse", 5)
    H = cal.transfer_for(N)
    expected = render("inverse", H, cal.fs, cal.layout, 5).drives  # render's default: equal peak drive
    np.testing.assert_allclose(drives, expected, rtol=1e-12, atol=0)
    assert drives.shape == (cal.layout.n_actuators, N)


class Hooked(Scripted):
    """A scripted participant that also answers the engine's optional hooks, from scripts."""

    def __init__(self, script, before=(), shown=(), resume=True):
        super().__init__(script, resume)
        self.before, self.shown, self.taken = list(before), list(shown), []

    def respond(self, presentation):
        if isinstance(self.script[0], Again):
            self.seen.append(presentation.trial.trial_index)
            return self.script.pop(0)
        return super().respond(presentation)

    def before_cue(self, trial):
        return self.before.pop(0) if self.before else None

    def cue_shown(self, trial):
        return self.shown.pop(0) if self.shown else None

    def answered(self, presentation, receipt):
        self.taken.append(receipt.trial_index)


def _small(store):
    return store.create_session("p1", 1, seed=5, config={"repetitions": 1, "n_training": 0, "methods": ["inverse"], "locations": [4, 6]})


def test_hooks_cancel_a_cue_restart_a_trial_and_log_why(store, rig, renderer):
    sid = _small(store)
    participant = Hooked(
        [Again("trial_restarted", "page reloaded"), 4, 6],
        before=[Again()],  # e.g. the trial was answered meanwhile: nothing is logged
        shown=[Again("cue_cancelled", "nobody saw the cue")],
    )
    summary = StudyEngine(store, sid, rig, renderer=renderer).run(participant)
    assert summary.status == "completed" and participant.taken == [0, 1]
    kinds = [(e.kind, e.payload.get("trial_index")) for e in store.events(sid)
             if e.kind in ("cue", "stimulus_onset", "cue_cancelled", "trial_restarted", "answer")]
    assert kinds == [
        ("cue", 0), ("cue_cancelled", 0),  # no stimulus for a cancelled cue
        ("cue", 0), ("stimulus_onset", 0), ("trial_restarted", 0),
        ("cue", 0), ("stimulus_onset", 0), ("answer", 0),
        ("cue", 1), ("stimulus_onset", 1), ("answer", 1),
    ]
    assert rig.n_played == 3
    assert store.events(sid, kind="cue_cancelled")[0].payload["reason"] == "nobody saw the cue"


def test_stop_keeps_the_status_and_a_hook_can_pause(store, rig, renderer):
    sid = _small(store)
    stopped = StudyEngine(store, sid, rig, renderer=renderer).run(Hooked([], before=[PAUSE], resume=STOP))
    assert stopped.status == "paused" and rig.n_played == 0, "a stop leaves the session as it was"
    store.set_status(sid, "running")
    stopped = StudyEngine(store, sid, rig, renderer=renderer).run(Hooked([], shown=[STOP]))
    assert stopped.status == "running" and rig.n_played == 0
    with pytest.raises(StudyError, match="expected a Response"):
        StudyEngine(store, sid, rig, renderer=renderer).run(Hooked([], before=["later"]))


def test_every_responder_writes_the_same_payloads_and_a_dry_run_plays_nothing(store, rig, renderer):
    played, dry = _small(store), _small(store)
    StudyEngine(store, played, rig, renderer=renderer).run(Scripted([4, 6]))
    StudyEngine(store, dry, None, dry_run=True, cue_by="page").run(Scripted([4, 6]))
    assert rig.n_played == 2
    for kind in ("cue", "stimulus_onset"):
        a, b = store.events(played, kind=kind), store.events(dry, kind=kind)
        assert [set(e.payload) for e in a] == [set(e.payload) for e in b]
    onset = store.events(played, kind="stimulus_onset")[0].payload
    assert onset["played"] and onset["drive_sha256"] == drive_sha256(renderer(onset["method"], onset["target"]))
    assert store.events(dry, kind="stimulus_onset")[0].payload["played"] is False
    assert store.events(dry, kind="cue")[0].payload["beep"] == "page"
    assert [a.drive_sha256 for a in store.answers(dry)] == [None, None]


def test_a_failing_rig_is_logged_and_the_session_resumes(store, renderer):
    class Broken:
        def play(self, drives):
            raise RuntimeError("interface unplugged")

    sid = _small(store)
    with pytest.raises(RuntimeError, match="unplugged"):
        StudyEngine(store, sid, Broken(), renderer=renderer).run(Scripted([4, 6]))
    (event,) = store.events(sid, kind="error")
    assert "interface unplugged" in event.payload["message"]
    assert store.session(sid).status == "running" and store.answers(sid) == []


def test_device_onsets_reach_the_answers_and_the_trials_export(store, rig, renderer, tmp_path):
    from vibrofocus.studies.export import read_trials_csv

    sid = _small(store)
    StudyEngine(store, sid, rig, renderer=renderer).run(Scripted([4, 6]))
    rows = store.trial_rows()
    # The simulated sample clock: each trial starts after the N samples of every drive before it.
    assert [r["onset_device_s"] for r in rows] == [0.0, N / rig.fs]
    assert [r["onset_clock"] for r in rows] == ["simulated_samples"] * 2
    answers = store.events(sid, kind="answer")
    assert [r["onset_host_s"] for r in rows] == [e.payload["onset_s"] for e in answers]
    assert rows[1]["onset_host_s"] > rows[0]["onset_host_s"]
    assert [e.payload["onset_device_s"] for e in answers] == [0.0, N / rig.fs]
    store.export_trials_csv(tmp_path / "t.csv")
    back = read_trials_csv(tmp_path / "t.csv")
    for key in ("onset_host_s", "onset_device_s", "onset_clock"):
        assert [r[key] for r in back] == [r[key] for r in rows]  # every digit kept


def test_a_dry_run_and_an_older_answer_have_no_onsets(store, tmp_path):
    from vibrofocus.studies.export import read_trials_csv

    dry = _small(store)
    StudyEngine(store, dry, None, dry_run=True).run(Scripted([4, 6]))
    old = _small(store)  # answered as an older vibrofocus did: no onset in the answer event
    store.record_answer(old, 0, 4, 0.7, answer_id="old-0")
    for row in store.trial_rows():
        if row["session_id"] == dry:
            assert row["onset_host_s"] is not None
        assert (row["onset_device_s"], row["onset_clock"]) == (None, None)
    assert [r["onset_host_s"] for r in store.trial_rows() if r["session_id"] == old] == [None]
    store.export_trials_csv(tmp_path / "t.csv")
    line = (tmp_path / "t.csv").read_text().splitlines()[-1]
    # The old answer: three empty onset cells; its session's level rule, and no peaks (nothing was played);
    # the paper's protocol, no point (a location answer), never presented again after an xrun, and its
    # block's level (0 dB re the rule) and allowed answers (the session's locations).
    assert line.endswith(",,,,paper,,,paper-study1,,,0,0.0,4 6")
    assert read_trials_csv(tmp_path / "t.csv")[-1]["onset_clock"] is None


class CommitsItself(Scripted):
    """A responder whose answers are committed before the play's onset is known (the web page's)."""

    def __init__(self, store, script):
        super().__init__(script)
        self.store = store

    def respond(self, presentation):
        reply = super().respond(presentation)
        answer_id = f"page-{presentation.trial.trial_index}"
        self.store.record_answer(presentation.session_id, presentation.trial.trial_index, reply.locations, reply.rt_s,
                                 answer_id=answer_id, require_presented=True)
        return Response(reply.locations, reply.rt_s, answer_id=answer_id)


def test_an_answer_committed_before_the_onset_gets_it_from_an_answer_onset_event(store, rig, renderer):
    sid = _small(store)
    StudyEngine(store, sid, rig, renderer=renderer).run(CommitsItself(store, [4, 6]))
    assert all("onset_device_s" not in e.payload for e in store.events(sid, kind="answer"))
    extra = store.events(sid, kind="answer_onset")
    assert [(e.payload["answer_id"], e.payload["onset_device_s"]) for e in extra] == [("page-0", 0.0),
                                                                                      ("page-1", N / rig.fs)]
    rows = store.trial_rows()
    assert [r["onset_device_s"] for r in rows] == [0.0, N / rig.fs]
    assert [r["onset_host_s"] for r in rows] == [e.payload["onset_s"] for e in extra]


@pytest.mark.parametrize("onsets, words", [
    ({"onset_device_s": 1.0}, "come together"),
    ({"onset_clock": "portaudio_dac"}, "come together"),
    ({"onset_device_s": float("nan"), "onset_clock": "portaudio_dac"}, "finite"),
    ({"onset_s": "soon"}, "finite"),
    ({"onset_device_s": 1.0, "onset_clock": "Wall Clock"}, "unknown device clock 'Wall Clock' for onset_clock"),
    ({"onset_device_s": 1.0, "onset_clock": "wall"}, "unknown device clock 'wall'.*register_clock"),
])
def test_a_bad_onset_stores_nothing(store, onsets, words):
    sid = _small(store)
    with pytest.raises(StudyError, match=words):
        store.record_answer(sid, 0, 5, 0.5, answer_id="a0", **onsets)
    assert store.answers(sid) == [] and store.events(sid, kind="answer") == []


def test_one_participants_trials_carry_their_own_onsets(store):
    # The onsets come from the named participant's events only: each answer keeps its own.
    store.add_participant("p2")
    sids = {pid: store.create_session(pid, 1, seed=5, config={"repetitions": 1, "n_training": 0,
                                                               "methods": ["inverse"], "locations": [4, 6]})
            for pid in ("p1", "p2")}
    for k, (pid, sid) in enumerate(sids.items()):
        for i, loc in enumerate((4, 6)):
            store.record_answer(sid, i, loc, 0.5, answer_id=f"{pid}-{i}", onset_s=100.0 * k + i,
                                onset_device_s=10.0 * k + i, onset_clock="simulated_samples")
    every = store.trial_rows()
    for k, pid in enumerate(sids):
        mine = store.trial_rows(participant_id=pid)
        assert mine == [r for r in every if r["participant"] == pid]
        assert [(r["onset_host_s"], r["onset_device_s"]) for r in mine] == [(100.0 * k, 10.0 * k),
                                                                           (100.0 * k + 1, 10.0 * k + 1)]


def test_a_calibration_at_another_rate_than_the_rig_is_refused_before_any_trial(store, calibration_file):
    from vibrofocus.calibration import load_calibration

    cal = load_calibration(calibration_file)
    sid = _small(store)
    fast = make_rig("simulated", seed=3)
    fast.fs = 2 * cal.fs  # a rig that plays at twice the rate the calibration was made at
    with pytest.raises(StudyError, match=r"made at 10000 Hz but the simulated rig plays at 20000 Hz"):
        StudyEngine(store, sid, fast, cal)
    with pytest.raises(StudyError, match="wrong pitch"):
        StudyEngine(store, sid, fast, renderer=calibration_renderer(cal))  # as the web runner builds it
    assert store.events(sid, kind="stimulus_onset") == []


def test_the_onset_is_when_the_device_took_the_first_sample(store, renderer):
    """A rig whose device starts 60 ms after the call: the answer's onset is the device's, not the call's."""
    from vibrofocus.rigs import DeviceOnset

    class LateRig:
        fs = 10_000.0
        starts: list = []

        def play(self, drives):
            import time

            self.starts.append(time.monotonic() + 0.060)
            return DeviceOnset(self.starts[-1])

    rig = LateRig()
    sid = _small(store)
    StudyEngine(store, sid, rig, renderer=renderer).run(Scripted([4, 6]))
    onsets = [e.payload["onset_s"] for e in store.events(sid, kind="answer")]
    assert onsets == rig.starts  # not the time the play was called, 60 ms earlier
    assert [r["onset_host_s"] for r in store.trial_rows()] == rig.starts


def _tight(rms_v=4.0, sustained_rms_v=4.0):
    from vibrofocus.rigs.safety import SafetyLimits

    rig = make_rig("simulated", seed=3)
    rig.limits = SafetyLimits(rms_v=rms_v, sustained_rms_v=sustained_rms_v)
    return rig


@pytest.mark.parametrize("limits, words", [
    # The plain inverse at location 4 holds 0.55 V RMS over 1 s, 0.45 V made again at
    # Tikhonov 0.1; 0.071 V over 60 s, 0.058 V made again.
    ({"rms_v": 0.3}, r"inverse stimulus at location 4 .*over 1 s, over the limit of 0\.3 V RMS"),
    ({"sustained_rms_v": 0.05}, r"inverse stimulus at location 4 .*over 60 s, over the limit of 0\.05 V RMS.*no wait"),
])
def test_a_stimulus_over_the_rigs_limits_is_refused_when_planned(store, calibration_file, limits, words):
    from vibrofocus.calibration import load_calibration

    cal = load_calibration(calibration_file)
    sid = _small(store)
    rig = _tight(**limits)
    with pytest.raises(StudyError, match=words) as info:
        StudyEngine(store, sid, rig, cal)
    assert "participant p-real" in str(info.value) and "tikhonov regularization 0.1" in str(info.value)
    # Refused at planning, before any trial.
    assert [e.kind for e in store.events(sid)] == ["created"] and rig.n_played == 0


def test_a_stimulus_over_the_rigs_limits_is_made_again_regularized(store, calibration_file):
    from vibrofocus.calibration import load_calibration
    from vibrofocus.rigs.safety import windowed_rms

    cal = load_calibration(calibration_file)
    sid = _small(store)
    rig = _tight(rms_v=0.5)
    renderer = calibration_renderer(cal)
    engine = StudyEngine(store, sid, rig, renderer=renderer)  # as the web runner and simulate-study build it
    assert renderer.redesigned == {("inverse", 4): {"regularization": "tikhonov", "reg_param": 0.1},
                                   ("inverse", 6): {"regularization": "tikhonov", "reg_param": 0.1}}
    stim = engine.stimulus("inverse", 4)
    assert windowed_rms(stim.drives**2, int(rig.fs)).max() <= 0.5
    expected = render("inverse", cal.transfer_for(renderer.n_samples), cal.fs, cal.layout, 4, scale_to_limit=False,
                      regularization="tikhonov", reg_param=0.1).drives
    np.testing.assert_allclose(stim.drives, expected, rtol=1e-9, atol=1e-12)
    summary = engine.run(Scripted([4, 6]), pace_s=1.5)  # back to back, the budget (the runtime's) refuses
    assert (summary.status, summary.n_answered, rig.n_played) == ("completed", 2, 2)
    onsets = store.events(sid, kind="stimulus_onset")
    assert [e.payload["redesign"]["reg_param"] for e in onsets] == [0.1, 0.1]
    # On the default limits the same session plays the design as asked, with no redesign.
    plain = calibration_renderer(cal)
    StudyEngine(store, _small(store), make_rig("simulated", seed=3), renderer=plain)
    assert plain.redesigned == {}


def test_a_trial_presented_again_says_replay_in_its_onset_marker(store, rig, renderer):
    # Issue 54, item 6: a pause (and, below, a run killed mid-trial) presents a trial again;
    # its second onset marker says so, so a recording keeps one onset per answer.
    from vibrofocus.studies.markers import sending_markers

    sid = store.create_session("p1", 1, seed=6, config={"repetitions": 1, "n_training": 0})
    onsets = []

    def sink(marker, host_time_s):
        if marker["event"] == "stimulus_onset":
            onsets.append((marker["trial_index"], marker["replay"]))

    with sending_markers(sink):
        StudyEngine(store, sid, rig, renderer=renderer).run(Scripted([3, PAUSE, 4, ABORT]))
        # Aborted at trial 2's answer; then a run killed after trial 2's stimulus, before
        # its answer (presented here without one); the resumed run plays it a third time.
        StudyEngine(store, sid, rig, renderer=renderer).present(store.planned_trials(sid)[2])
        StudyEngine(store, sid, rig, renderer=renderer).run(Scripted([5, ABORT]))
    assert onsets == [(0, False), (1, False), (1, True), (2, False), (2, True), (2, True), (3, False)]


def test_a_limit_over_time_pauses_the_trial_for_its_wait_instead_of_ending_the_run(store, renderer, monkeypatch):
    import types

    from vibrofocus.rigs import safety
    from vibrofocus.rigs.safety import SafetyLimits, windowed_rms
    from vibrofocus.rigs.simulated import SimulatedForearm

    class Clocked(SimulatedForearm):
        now = 0.0

        def _clock(self):
            return self.now

    rig = Clocked(seed=3)
    alone = max(windowed_rms(renderer("inverse", k) ** 2, int(10 * rig.fs)).max() for k in (4, 6))
    # Each stimulus fits alone; two back to back break the sustained limit.
    rig.limits = SafetyLimits(sustained_rms_v=1.2 * alone, sustained_window_s=10.0)
    monkeypatch.setattr(safety, "time", types.SimpleNamespace(sleep=lambda s: setattr(rig, "now", rig.now + s)))
    sid = _small(store)
    summary = StudyEngine(store, sid, rig, renderer=renderer).run(Scripted([4, 6]))
    assert (summary.status, summary.n_answered, rig.n_played) == ("completed", 2, 2)
    (cooling,) = store.events(sid, kind="cooling")
    assert cooling.payload["trial_index"] == 1 and cooling.payload["wait_s"] > 0
    assert rig.now >= cooling.payload["wait_s"] - 0.06


def _xrun_on(rig, monkeypatch, plays):
    """Make the rig's plays number ``plays`` (1-based) report lost samples, as an audio
    stream's underflow does: the drive played, then the play raises XrunError with its onset."""
    from vibrofocus.rigs import XrunError

    real, calls = rig._play, []

    def play(drive):
        onset = real(drive)
        calls.append(onset)
        if len(calls) in plays:
            raise XrunError(onset, "the audio stream reported output underflow while playing (injected)")
        return onset

    monkeypatch.setattr(rig, "_play", play)
    return calls


def test_an_xrun_presents_the_trial_again_and_every_answer_is_stored_once(store, rig, renderer, monkeypatch,
                                                                          tmp_path):
    from vibrofocus.studies.export import read_trials_csv
    from vibrofocus.studies.markers import sending_markers

    _xrun_on(rig, monkeypatch, {2})  # trial 1's stimulus loses samples
    sid = _small(store)
    markers = []
    with sending_markers(lambda m, t: markers.append(m) if m["event"] == "stimulus_onset" else None):
        summary = StudyEngine(store, sid, rig, renderer=renderer).run(Scripted([4, 6]))
    assert (summary.status, summary.n_answered, rig.n_played) == ("completed", 2, 3)
    assert [(a.trial_index, a.response) for a in store.answers(sid)] == [(0, (4,)), (1, (6,))]
    (xrun,) = store.events(sid, kind="xrun")
    assert xrun.payload["trial_index"] == 1 and xrun.payload["represented"] is True
    assert "underflow" in xrun.payload["message"]
    # The lost stimulus is marked (as lost), its presentation again says replay.
    assert [(m["trial_index"], m.get("xrun", False), m["replay"]) for m in markers] == [
        (0, False, False), (1, True, False), (1, False, True)]
    store.export_trials_csv(tmp_path / "t.csv")
    assert [r["xrun_represented"] for r in read_trials_csv(tmp_path / "t.csv")] == [0, 1]
    from vibrofocus.studies.bids import export_bids

    export_bids(store.path, tmp_path / "bids")
    (events,) = (tmp_path / "bids").rglob("*_events.tsv")
    lines = [line.split("\t") for line in events.read_text().splitlines()]
    assert [row[lines[0].index("xrun_represented")] for row in lines[1:]] == ["0", "1"]


def test_xruns_past_the_sessions_count_end_the_run_which_resumes(store, rig, renderer, monkeypatch):
    from vibrofocus.rigs import XrunError

    _xrun_on(rig, monkeypatch, {1, 2, 3})  # trial 0 loses samples three times running
    sid = store.create_session("p1", 1, seed=5, config={"repetitions": 1, "n_training": 0, "methods": ["inverse"],
                                                        "locations": [4, 6], "represent_after_xrun": 2})
    with pytest.raises(XrunError, match="underflow"):
        StudyEngine(store, sid, rig, renderer=renderer).run(Scripted([4, 6]))
    assert [e.payload["represented"] for e in store.events(sid, kind="xrun")] == [True, True, False]
    assert store.answers(sid) == [] and store.events(sid, kind="error")
    # The count is per trial over every run: the resumed run plays it, it keeps its two.
    summary = StudyEngine(store, sid, rig, renderer=renderer).run(Scripted([4, 6]))
    assert (summary.status, summary.n_answered) == ("completed", 2)


def test_a_bad_represent_after_xrun_is_refused(store):
    for value in (-1, 11, 1.5, True, "1"):
        sid = store.create_session("p1", 1, seed=5, config={"repetitions": 1, "represent_after_xrun": value})
        with pytest.raises(StudyError, match="represent_after_xrun must be an integer from 0 to 10"):
            StudyEngine(store, sid, None, dry_run=True)
