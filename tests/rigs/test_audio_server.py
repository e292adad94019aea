"""The audio rig when its JACK server hangs (SIGSTOP) or restarts under it.

Each case runs in a process of its own with a JACK server of its own: PortAudio cannot
leave a hung or restarted server within the process that used it. What is checked is
docs/hardware.md, "A hung or restarted audio server": the play under way ends with
DeviceError, a later play is refused at once with what to do, the stop and the close
return, and the process exits by itself with status 0 (it neither hangs nor aborts).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time

import pytest

from .conftest import end_private_jackd, start_private_jackd
from .test_audio import JACK_PERIOD, JACK_RATE, jack_config

pytestmark = [pytest.mark.jack, pytest.mark.slow]

_SCRIPT = """
import json, os, signal, sys, threading, time
import numpy as np
from vibrofocus.rigs import DeviceError, make_rig
config, server_pid, how = json.loads(sys.argv[1]), int(sys.argv[2]), sys.argv[3]
fs = config["fs"]
n = int(3.0 * fs)
drive = np.tile(2.0 * np.sin(2 * np.pi * 200 * np.arange(n) / fs), (4, 1))
out = {}
rig = make_rig("audio", config=config)
rig.play(drive[:, :2000])
if how == "sigstop":
    threading.Timer(0.5, os.kill, args=(server_pid, signal.SIGSTOP)).start()
    t0 = time.monotonic()
    try:
        rig.play(drive)
        out["first"] = "played"
    except DeviceError as exc:
        out["first"] = str(exc)
    out["first_s"] = time.monotonic() - t0
elif how == "pause":  # the server stops for 0.4 s between plays: its dummy driver drops the time
    os.kill(server_pid, signal.SIGSTOP)
    time.sleep(0.4)
    os.kill(server_pid, signal.SIGCONT)
    time.sleep(0.3)
    admitted, real = [], rig.budget.admit
    rig.budget.admit = lambda d, start_s: (admitted.append(start_s), real(d, start_s))[1]
    onset = rig.play(drive[:, :2000])
    out["placed_s"] = onset.output_host_s - admitted[0]
    out["xruns"] = rig._stream.xruns
else:  # the test restarts the server, then says so on stdin
    print("ready", flush=True)
    sys.stdin.readline()
t0 = time.monotonic()
try:
    rig.play(drive[:, :2000])
    out["second"] = "played"
except DeviceError as exc:
    out["second"] = str(exc)
out["second_s"] = time.monotonic() - t0
t0 = time.monotonic()
rig.stop()
rig.close()
out["close_s"] = time.monotonic() - t0
print(json.dumps(out), flush=True)
"""


def _child(name: str, server_pid: int, how: str) -> subprocess.Popen:
    env = {**os.environ, "JACK_DEFAULT_SERVER": name, "JACK_NO_START_SERVER": "1"}
    return subprocess.Popen([sys.executable, "-c", _SCRIPT, json.dumps(jack_config()), str(server_pid), how],
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)


def _result(child: subprocess.Popen, timeout: float) -> dict:
    try:
        out, err = child.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        child.kill()
        out, err = child.communicate()
        pytest.fail(f"the process hung (killed after {timeout:g} s): {out[-500:]} {err[-1500:]}")
    assert child.returncode == 0, f"the process ended with {child.returncode}: {err[-1500:]}"
    return json.loads(out.strip().splitlines()[-1])


def _on_a_private_server(how: str) -> dict:
    """What the child process reports for ``how``, run on a private JACK server (stopped after)."""
    name = f"vibrofocus-{how}-{os.getpid()}"
    server = start_private_jackd(name)
    try:
        result = _result(_child(name, server.pid, how), timeout=40)
    finally:
        end_private_jackd(server, name)
    print(result)
    return result


def test_a_stopped_jack_server_ends_the_play_refuses_the_next_and_the_process_exits(jack_server):
    result = _on_a_private_server("sigstop")
    assert result["first"].startswith("the audio") and "restart vibrofocus" in result["first"]
    assert result["first_s"] < 0.5 + 2.0 + 1.5  # SIGSTOP, no callback for STALL_S, slack
    assert "restart vibrofocus" in result["second"] and result["second_s"] < 0.5
    assert result["close_s"] < 1.0


def test_a_paused_jack_server_moves_the_budget_axis_on_to_its_late_frames(jack_server):
    # JACK's dummy driver, late by the pause, starts its frame count again from the late cycle
    # (an xrun): the frames fall 0.4 s behind the host's clock for good. A play after it is
    # still admitted at its time at the outputs, within a period or two (the host's time of a
    # callback jitters), not 0.4 s before it.
    result = _on_a_private_server("pause")
    period = JACK_PERIOD / JACK_RATE
    assert result["xruns"] >= 1
    assert -0.01 <= result["placed_s"] <= 2 * period + 0.01


def test_a_restarted_jack_server_refuses_plays_with_what_to_do_and_the_process_exits(jack_server):
    name = f"vibrofocus-restart-{os.getpid()}"
    server = start_private_jackd(name)
    try:
        child = _child(name, server.pid, "restart")
        assert child.stdout.readline().strip() == "ready"
        server.terminate()
        server.wait(10)
        time.sleep(0.5)  # a new server with the old one's name may not start at once
        server = start_private_jackd(name)
        time.sleep(2.5)  # no callback for STALL_S
        child.stdin.write("\n")
        child.stdin.flush()
        result = _result(child, timeout=40)
    finally:
        end_private_jackd(server, name)
    print(result)
    assert "restart vibrofocus" in result["second"] and result["second_s"] < 0.5
    assert result["close_s"] < 1.0
