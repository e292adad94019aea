"""``vibrofocus serve-osc`` as a process: it plays a tap from a python-osc client, and ``/stop``,
SIGINT or SIGTERM end it with one line and every output at zero."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys

import pytest

pytest.importorskip("pythonosc")
from pythonosc.osc_message import OscMessage  # noqa: E402
from pythonosc.udp_client import SimpleUDPClient  # noqa: E402

from .serve_osc_lines import problems  # noqa: E402

pytestmark = pytest.mark.slow


def _start(tmp_path, *extra):
    env = dict(os.environ, PYTHONDONTWRITEBYTECODE="1", MPLBACKEND="Agg")
    proc = subprocess.Popen([sys.executable, "-m", "vibrofocus", "serve-osc", "--port", "0", *extra], cwd=tmp_path,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    line = proc.stdout.readline()
    found = re.search(r"osc\.udp://127\.0\.0\.1:(\d+)", line)
    if found is None:
        proc.kill()
        raise AssertionError(f"no listening line: {line!r} {proc.stderr.read()!r}")
    proc.stdout.readline()  # the addresses
    return proc, SimpleUDPClient("127.0.0.1", int(found.group(1)))


def _ask(client, address, args):
    client.send_message(address, args)
    data = client.receive(60)
    assert data, f"no reply to {address}"
    return OscMessage(data)


def test_stop_message_ends_it_with_one_line(tmp_path):
    proc, client = _start(tmp_path)
    try:
        assert _ask(client, "/tap", 5).address == "/played"
        assert _ask(client, "/tap_xy", ["x", 1]).address == "/error"
        assert _ask(client, "/tap_xy", [-2.0, 7.5]).address == "/played"
        assert _ask(client, "/stop", []).address == "/stopped"
        out, err = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert proc.returncode == 0, err
    assert out.strip().splitlines() == [re.search(r"serve-osc stopped by /stop from 127\.0\.0\.1:\d+; all outputs at "
                                                  r"zero", out).group(0)]
    assert problems(err) == []
    # Issue 54, item 9: the start (a minute here) was silent when not at a terminal. Each
    # stage is said as it begins, the first before the imports, the grid with its rows.
    said = err.strip().splitlines()
    assert said[0].startswith("serve-osc: starting on the simulated rig"), said
    assert any(line.startswith("serve-osc: evaluating the skin model") for line in said), said
    assert re.fullmatch(r"(\d+)/\1 rows of the /tap_xy grid \(.*elapsed\)", said[-1]), said


def test_taps_from_a_calibration_without_a_skin_model(tmp_path):
    from vibrofocus.calibration import calibrate, save_calibration
    from vibrofocus.rigs import make_rig

    cal = tmp_path / "P01.nc"
    save_calibration(calibrate(make_rig("simulated", seed=5), participant_id="P01"), cal)
    proc, client = _start(tmp_path, "--calibration", str(cal), "--method", "funneling")
    try:
        assert _ask(client, "/tap", 4).params[:1] == [4]
        reply = _ask(client, "/tap_xy", [1.0, 1.0])
        assert reply.address == "/error" and "need a model of the skin" in reply.params[0]
        assert _ask(client, "/tap", 6).address == "/played"
        assert _ask(client, "/stop", []).address == "/stopped"
        out, err = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert proc.returncode == 0 and problems(err) == []


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_signal_ends_it_with_one_line(tmp_path, sig):
    proc, client = _start(tmp_path)
    try:
        assert _ask(client, "/tap", 1).address == "/played"
        proc.send_signal(sig)
        out, err = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert proc.returncode == 130
    assert out == ""
    assert problems(err) == ["interrupted: serve-osc stopped; all outputs at zero"]


@pytest.mark.parametrize("args, needle", [
    (["--method", "nope"], "unknown method 'nope'"),
    (["--rig", "audio"], "the audio rig needs --calibration"),
    (["--skin", "rubber"], "skin"),
    (["--port", "BUSY"], "cannot listen on UDP 127.0.0.1"),
])
def test_bad_options_are_one_error_line(tmp_path, args, needle):
    import socket

    busy = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    busy.bind(("127.0.0.1", 0))
    try:
        args = [str(busy.getsockname()[1]) if a == "BUSY" else a for a in args]
        done = subprocess.run([sys.executable, "-m", "vibrofocus", "serve-osc", *args], cwd=tmp_path,
                              capture_output=True, text=True, timeout=300,
                              env=dict(os.environ, PYTHONDONTWRITEBYTECODE="1"))
    finally:
        busy.close()
    assert done.returncode == 2, done.stderr
    lines = problems(done.stderr)
    assert len(lines) == 1 and lines[0].startswith("error:") and needle in lines[0], lines


def test_an_ipv6_address_is_shown_in_brackets(tmp_path):
    # Issue 38: "--host ::1" printed osc.udp://::1:9124, which no OSC client can parse.
    env = dict(os.environ, PYTHONDONTWRITEBYTECODE="1", MPLBACKEND="Agg")
    proc = subprocess.Popen([sys.executable, "-m", "vibrofocus", "serve-osc", "--host", "::1", "--port", "0"],
                            cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    try:
        line = proc.stdout.readline()
    finally:
        proc.kill()
        proc.communicate(timeout=60)
    assert re.search(r"osc\.udp://\[::1\]:\d+ ", line), line


def test_the_default_inverse_method_starts_on_a_calibration_that_needs_a_longer_window(tmp_path):
    """The window follows the calibration as in the studies: this arm's inverse designs ring past 4096 samples."""
    from vibrofocus.calibration import calibrate, save_calibration
    from vibrofocus.rendering import TransferMatrix
    from vibrofocus.rigs import make_rig
    from vibrofocus.simulation.simulate import STUDY_SKIN, participant_seeds

    # simulate-study --seed 977's second participant, whose inverse designs need 8192 samples.
    calibration = calibrate(make_rig("simulated", seed=participant_seeds(977, 2)[0], skin=STUDY_SKIN),
                            participant_id="P02")
    assert TransferMatrix.from_calibration(calibration).n_samples == 4096
    cal = tmp_path / "P02.nc"
    save_calibration(calibration, cal)
    proc, client = _start(tmp_path, "--calibration", str(cal))  # "too short ... location 2" before
    try:
        # Location 1: this arm's plain inverse at 2, 5 and 8 rings over the 1 s RMS limit
        # (the studies make those again regularized; serve-osc refuses them at the tap).
        reply = _ask(client, "/tap", 1)
        assert reply.address == "/played", reply.params
        assert _ask(client, "/stop", []).address == "/stopped"
        out, err = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert proc.returncode == 0, err
