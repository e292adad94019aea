"""``TapStimulus``: in-process on the simulated rig and through a real ``OscTapServer`` over
UDP; levels scale the played drive by their decibels, onsets reach the data file."""

from __future__ import annotations

import socket
import threading

import numpy as np
import pytest

from vibrofocus.errors import ValidationError
from vibrofocus.psychopy import DATA_FIELDS, TapStimulus
from vibrofocus.rigs import make_rig


class Recorder:
    """The one method of PsychoPy's ExperimentHandler that ``store`` calls."""

    def __init__(self):
        self.rows = [{}]

    def addData(self, name, value):  # noqa: N802 - PsychoPy's name
        self.rows[-1][name] = value

    def nextEntry(self):  # noqa: N802
        self.rows.append({})


def test_in_process_levels_onsets_and_the_data_file():
    rig = make_rig("simulated", seed=4)
    exp = Recorder()
    said = []
    with TapStimulus.in_process(rig, name="vib", grid_pitch_m=5e-3, report=said.append) as tap:
        design = rig.check(tap._backend.designer.drives_at(5))
        for level in (0.0, -6.0, -12.0):
            tap.set(location=5, level_db=level).play()
            result = tap.store(exp)
            exp.nextEntry()
            assert result.played and result.level_db == level
            np.testing.assert_allclose(rig.last_drive, design * 10 ** (level / 20), rtol=1e-12, atol=0)
        tap.set(x_mm=2.0, y_mm=-1.0, level_db=-3.0).play()
        point = tap.result()
        refused = tap.set(location=5, level_db=6.0)
        refused.play()
        over = tap.result()
    rows = exp.rows[:3]
    assert [r["vib.tap_id"] for r in rows] == [1, 2, 3]
    assert [r["vib.level_db"] for r in rows] == [0.0, -6.0, -12.0]
    assert set(rows[0]) == {f"vib.{f}" for f in DATA_FIELDS}
    n = design.shape[1]
    assert [r["vib.onset_device_s"] for r in rows] == [k * n / rig.fs for k in range(3)]
    assert all(r["vib.asked_host_s"] <= r["vib.onset_host_s"] for r in rows)
    assert rows[0]["vib.x_mm"] == "" and rows[0]["vib.error"] == ""  # empty cells, not "None"
    assert (point.location, point.x_mm, point.y_mm, point.tap_id) == (None, 2.0, -1.0, 4)
    # Over the limit: the safety layer refuses, nothing plays, the reason is kept.
    assert not over.played and over.tap_id is None and "drive refused" in over.error
    assert rig.n_played == 4
    # Issue 54, item 9: the start (42 s with the default grid) said nothing. It says each
    # stage, the grid's rows with the time left, and when it is ready.
    assert said[0].startswith("vibrofocus: evaluating the skin model on the grid"), said
    grid = [line.split()[2].split("/") for line in said if line.startswith("vibrofocus: grid ")]
    assert grid[0][0] == "0" and grid[-1][0] == grid[-1][1], said
    assert said[-1].startswith("vibrofocus: ready in "), said


def test_through_serve_osc_with_its_tap_ids_and_onsets():
    pytest.importorskip("pythonosc")
    from vibrofocus.realtime import OscTapServer, TapDesigner
    from vibrofocus.rendering import TransferMatrix

    rig = make_rig("simulated", seed=3)
    designer = TapDesigner(TransferMatrix.from_model(rig, rig.layout, rig.fs), rig, limit_v=rig.limits.peak_v,
                           grid_pitch_m=5e-3)
    designer.prepare_grid()  # as serve-osc does at start: the tap at a point is not answered 30 s late
    server = OscTapServer(rig, designer, port=0)
    thread = threading.Thread(target=server.serve, daemon=True)
    thread.start()
    try:
        with TapStimulus.osc(port=server.address[1], timeout_s=30.0) as tap:
            results = []
            for kwargs in ({"location": 2, "level_db": -6.0}, {"x_mm": 1.0, "y_mm": 3.0, "level_db": -1.0},
                           {"location": 4, "level_db": 0.0, "method": "funneling"}, {"location": 4, "level_db": 1.0}):
                tap.set(**kwargs).play()
                results.append(tap.result())
            # Two taps asked before either answer is read: answers are matched in order.
            tap.set(location=1, level_db=-2.0, method="inverse").play()
            tap.set(location=9, level_db=-4.0).play()
            results += [tap.result(), tap.result()]
            # A method the server refuses (minimax was not designed ahead) raises at once and
            # changes nothing: the next tap is recorded under the method it plays with.
            with pytest.raises(ValidationError, match="refused method 'minimax'.*--method minimax"):
                tap.set(method="minimax")
            tap.set(location=3).play()
            after = tap.result()
            assert after.played and after.method == "inverse"
    finally:
        server.stop()
        thread.join(10)
        server.close()
    played = [r for r in results if r.played]
    assert [r.tap_id for r in played] == [1, 2, 3, 4, 5]
    assert [(r.onset_host_s, r.onset_device_s, r.onset_clock) for r in played] == [
        (rec.onset_host_s, rec.onset_device_s, rec.onset_clock) for rec in server.records[:5]]
    assert [rec.method for rec in server.records] == ["inverse", "inverse", "funneling", "inverse", "inverse",
                                                      "inverse"]
    assert [r.method for r in played] == [rec.method for rec in server.records[:5]]
    assert [rec.level_db for rec in server.records] == [-6.0, -1.0, 0.0, -2.0, -4.0, -4.0]
    assert not results[3].played and "drive refused" in results[3].error


def test_no_server_is_one_clear_error_at_the_start_not_a_hang():
    pytest.importorskip("pythonosc")
    import socket

    free = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    free.bind(("127.0.0.1", 0))
    port = free.getsockname()[1]
    free.close()
    with pytest.raises(ValidationError, match=f"serve-osc at 127.0.0.1:{port}"):
        TapStimulus.osc(port=port, timeout_s=0.5)


class _Nothing:
    def set_method(self, name, timeout_s):
        pass


@pytest.mark.parametrize("kwargs, needle", [
    ({"location": 2, "x_mm": 1.0, "y_mm": 1.0}, "not both"),
    ({"x_mm": 1.0}, "both x_mm and y_mm"),
    ({"location": 2.5}, "integer"),
    ({"level_db": float("nan")}, "finite"),
    ({"level_db": "loud"}, "finite"),
    ({"method": ""}, "method"),
])
def test_bad_settings_are_one_clear_error(kwargs, needle):
    tap = TapStimulus(backend=_Nothing())
    with pytest.raises(ValidationError, match=needle):
        tap.set(**kwargs)
    with pytest.raises(ValidationError, match="identifier"):
        TapStimulus(backend=_Nothing(), name="my tap")
    with pytest.raises(ValidationError, match="call play"):
        tap.result()


# -- pairing answers with taps (issue 53, item 11) -----------------------------------------
class ScriptedServer:
    """A UDP socket that answers as a test says: what serve-osc sends, at the moment chosen."""

    def __init__(self):
        from pythonosc.osc_message import OscMessage

        self._parse = OscMessage
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(30)
        self.port = self.sock.getsockname()[1]
        self.client = None
        # TapStimulus asks its method when made: answered by a thread, the rest by the test.
        self._method = threading.Thread(target=self._answer_method, daemon=True)
        self._method.start()

    def _answer_method(self):
        message = self.next()
        self.send("/method", *message.params)

    def next(self):
        data, self.client = self.sock.recvfrom(65536)
        return self._parse(data)

    def send(self, address, *args, to=None):
        from pythonosc.osc_message_builder import OscMessageBuilder

        builder = OscMessageBuilder(address=address)
        for arg in args:
            builder.add_arg(arg)
        self.sock.sendto(builder.build().dgram, to or self.client)

    def played(self, echo, tap_id, level_db=0.0):
        self.send("/played", *echo, tap_id, 100.0 + tap_id, float("nan"), "", float(level_db))

    def close(self):
        self.sock.close()


@pytest.fixture
def scripted():
    pytest.importorskip("pythonosc")
    server = ScriptedServer()
    yield server
    server.close()


def test_an_answer_after_the_timeout_is_discarded_not_given_to_the_next_tap(scripted):
    with TapStimulus.osc(port=scripted.port, timeout_s=30.0) as tap:
        tap.set(location=5, level_db=-6.0).play()
        assert scripted.next().params == [5, -6.0]
        given_up = tap.result(timeout_s=0.2)
        assert not given_up.played and "no answer" in given_up.error
        scripted.played([5], 1, -6.0)  # its answer, late
        tap.set(location=5, level_db=-6.0).play()
        scripted.next()
        scripted.played([5], 2, -6.0)
        after = tap.result()
    assert after.played and after.tap_id == 2 and after.onset_host_s == 102.0


def test_answers_are_matched_by_what_they_echo_and_by_increasing_tap_ids(scripted):
    with TapStimulus.osc(port=scripted.port, timeout_s=30.0) as tap:
        tap.set(location=1).play()
        tap.set(x_mm=1.3, y_mm=-2.0, level_db=-3.0).play()
        tap.set(location=9).play()
        for _ in range(3):
            scripted.next()
        # Out of order, as serve-osc may answer (a refusal at once, a play later), with noise:
        scripted.send("/error", "stopped: /tap location 9 was not played")
        scripted.played([4], 7)  # a location nobody asked
        scripted.played([1], 3, -12.0)  # location 1, but not the level asked
        scripted.played([1], 3)
        scripted.played([1.3, -2.0], 3, -3.0)  # a tap id already used
        scripted.played([1.3, -2.0], 4, -3.0)
        first, point, last = tap.result(), tap.result(), tap.result()
    assert (first.location, first.tap_id, first.onset_host_s) == (1, 3, 103.0)
    assert (point.x_mm, point.tap_id, point.onset_host_s) == (1.3, 4, 104.0)
    assert not last.played and last.location == 9 and last.error == "stopped: /tap location 9 was not played"


def test_the_socket_takes_answers_from_the_server_only(scripted):
    with TapStimulus.osc(port=scripted.port, timeout_s=30.0) as tap:
        tap.set(location=5).play()
        scripted.next()
        # Another local program that found the client's port sends it a /played first.
        intruder = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            intruder.sendto(_played_dgram(5, 1), tap._backend._sock.getsockname())
        finally:
            intruder.close()
        scripted.played([5], 2)
        result = tap.result()
    # The server's answer only (its address and port): the kernel drops the intruder's.
    assert (result.tap_id, result.onset_host_s, result.onset_clock) == (2, 102.0, None)


def _played_dgram(location, tap_id):
    from pythonosc.osc_message_builder import OscMessageBuilder

    builder = OscMessageBuilder(address="/played")
    for arg in (location, tap_id, 999.0, float("nan"), "intruder", 0.0):
        builder.add_arg(arg)
    return builder.build().dgram


def test_a_late_answer_of_a_real_server_is_not_given_to_the_next_tap():
    pytest.importorskip("pythonosc")
    import time

    from vibrofocus.realtime import OscTapServer, TapDesigner
    from vibrofocus.rendering import TransferMatrix
    from vibrofocus.rigs.simulated import SimulatedForearm

    class Slow(SimulatedForearm):
        first = True

        def _play(self, drive):
            if self.first:
                self.first = False
                time.sleep(1.0)
            return super()._play(drive)

    rig = Slow(seed=3)
    designer = TapDesigner(TransferMatrix.from_model(rig, rig.layout, rig.fs), rig, limit_v=rig.limits.peak_v,
                           grid_pitch_m=5e-3)
    server = OscTapServer(rig, designer, port=0, max_wait_s=30.0)
    thread = threading.Thread(target=server.serve, daemon=True)
    thread.start()
    try:
        with TapStimulus.osc(port=server.address[1], timeout_s=30.0) as tap:
            tap.set(location=5).play()
            given_up = tap.result(timeout_s=0.3)  # the server answers about 0.7 s later
            tap.set(location=5).play()
            after = tap.result()
    finally:
        server.stop()
        thread.join(10)
        server.close()
    assert not given_up.played and "no answer" in given_up.error
    assert [r.tap_id for r in server.records] == [1, 2]
    assert after.played and after.tap_id == 2 and after.onset_host_s == server.records[1].onset_host_s


@pytest.mark.parametrize("location, level", [(np.int64(5), np.int64(-6)), (np.int32(5), np.float32(-6.0)),
                                             (np.uint8(5), np.int16(-6)), (5, -6)])
def test_numpy_scalars_from_a_conditions_file_are_numbers(location, level):
    # PsychoPy's importConditions gives numpy integers (issue 54, item 4b).
    tap = TapStimulus(backend=_Nothing()).set(location=location, level_db=level)
    assert (tap.location, tap.level_db) == (5, -6.0)
    assert type(tap.location) is int and type(tap.level_db) is float


@pytest.mark.parametrize("kwargs", [{"location": np.bool_(True)}, {"location": np.float64(2.5)},
                                    {"level_db": np.float64("nan")}, {"level_db": np.bool_(False)},
                                    {"location": np.float64("inf")}])
def test_numpy_scalars_that_are_not_a_location_or_level_are_refused(kwargs):
    with pytest.raises(ValidationError):
        TapStimulus(backend=_Nothing()).set(**kwargs)
