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
