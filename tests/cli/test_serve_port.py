"""``vibrofocus serve`` on a port that is already in use: one error line, exit 2, nothing printed first."""

from __future__ import annotations

import socket
import subprocess
import sys


def test_a_busy_port_is_one_error_line(tmp_path):
    with socket.socket() as other:
        other.bind(("127.0.0.1", 0))
        other.listen()
        port = other.getsockname()[1]
        done = subprocess.run([sys.executable, "-m", "vibrofocus", "serve", "--port", str(port), "--no-browser",
                               "--db", str(tmp_path / "s.sqlite")], capture_output=True, text=True, timeout=120)
    assert done.returncode == 2
    assert done.stderr.count("error:") == 1 and f"{port} is already in use" in done.stderr
    assert "Traceback" not in done.stderr and "login" not in done.stdout  # no link to a server that never ran


def _serve_until(sig: int, tmp_path) -> subprocess.CompletedProcess:
    """Start `vibrofocus serve`, wait until it listens, send ``sig``; the finished process."""
    import time

    proc = subprocess.Popen([sys.executable, "-m", "vibrofocus", "serve", "--port", "0", "--no-browser",
                             "--db", str(tmp_path / f"s{sig}.sqlite")], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        lines = []
        deadline = time.monotonic() + 120
        while not any("emergency stop" in line for line in lines):  # the last line before it serves
            line = proc.stdout.readline()
            assert line and time.monotonic() < deadline, "".join(lines) + proc.stderr.read()
            lines.append(line)
        time.sleep(1.0)  # uvicorn's own handlers are in place
        proc.send_signal(sig)
        out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    return subprocess.CompletedProcess(proc.args, proc.returncode, "".join(lines) + out, err)


def test_sigterm_ends_serve_with_143_and_ctrl_c_with_130(tmp_path):
    import signal

    # 128 + the signal's number: what supervisors (systemd, docker, shells) expect.
    assert _serve_until(signal.SIGTERM, tmp_path).returncode == 143
    assert _serve_until(signal.SIGINT, tmp_path).returncode == 130
