"""How long ``vibrofocus stop`` takes to reach the server's stop, and to return.

Starts a stop listener (vibrofocus.web.emergency.StopListener) on a stand-in server state
whose emergency stop records when it ran, then runs ``python -m vibrofocus stop --db``
(and ``--help``) several times, printing the median and the largest time from the
command's start to the stop (the outputs' zeroing, where the button's 100 ms budget
runs) and to the command's exit. Run: ``python benchmarks/stop_latency.py [N]``.
"""

from __future__ import annotations

import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

from vibrofocus.web.emergency import StopListener


class _Web:
    def __init__(self) -> None:
        self.lock = self.db = threading.RLock()
        self.runners: dict = {}
        self.at: list[float] = []

    def emergency_stop(self) -> list[str]:
        self.at.append(time.monotonic())
        return ["outputs at 0 V"]


def main(n: int = 7) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp) / "studies-files"
        folder.mkdir(mode=0o700)
        web = _Web()
        listener = StopListener(web, folder / "stop.sock")
        assert listener.start()
        try:
            reached, returned, helped = [], [], []
            for _ in range(n):
                t0 = time.monotonic()
                done = subprocess.run([sys.executable, "-m", "vibrofocus", "stop", "--db", str(Path(tmp) / "studies.sqlite")],
                                      capture_output=True, text=True)
                returned.append(time.monotonic() - t0)
                assert done.returncode == 0, done.stderr
                reached.append(web.at[-1] - t0)
                t0 = time.monotonic()
                subprocess.run([sys.executable, "-m", "vibrofocus", "stop", "--help"], capture_output=True)
                helped.append(time.monotonic() - t0)
        finally:
            listener.close()
    t0 = time.monotonic()
    subprocess.run([sys.executable, "-c", "pass"])
    bare = time.monotonic() - t0
    for name, xs in (("start to the stop", reached), ("start to exit", returned), ("stop --help", helped)):
        print(f"{name:18s} median {1e3 * statistics.median(xs):6.0f} ms, max {1e3 * max(xs):6.0f} ms (n={n})")
    print(f"python -c pass     {1e3 * bare:6.0f} ms (the interpreter's own start on this machine)")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 7)
