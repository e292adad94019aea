"""The marker stream as a LabRecorder-style recorder sees it: a crash, a resume, and the markers' shape.

Runs ``vibrofocus simulate-study --lsl`` for one simulated participant in a child process,
with a pylsl inlet opened as LabRecorder opens it (``recover=True``) on this machine only
(``ResolveScope = machine``). After ``--kill-after`` answers the child is killed with
SIGKILL; the same command then resumes the database. Prints:

- the stream's source id in the two processes;
- the trials the resumed run answered (from the database) and the markers of the resumed
  run the inlet received;
- the distinct marker strings (what MNE / EEGLAB make event types of);
- the answers stamped after the next cue, and the largest backwards step of the stamps.

Usage: python benchmarks/check_lsl_markers.py [--kill-after 20] [--wait-s 10]
(``--wait-s`` is passed as ``--lsl-wait`` where the command has it.)
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import signal
import sqlite3
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path


def _event(sample: str) -> str:
    """'cue', 'onset' or 'answer', from a JSON marker or from a short code."""
    try:
        event = json.loads(sample)["event"]
    except (ValueError, KeyError, TypeError):
        event = sample.split("/")[0]
    return {"stimulus_onset": "onset", "tap": "onset", "dry": "onset"}.get(event, event)


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--kill-after", type=int, default=20)
    parser.add_argument("--wait-s", type=float, default=10.0)
    parser.add_argument("--seed", type=int, default=4)
    args = parser.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="lsl-check-"))
    cfg = tmp / "lsl_api.cfg"
    cfg.write_text("[multicast]\nResolveScope = machine\n[log]\nlevel = -3\n", encoding="utf-8")
    os.environ["LSLAPICFG"] = str(cfg)  # before liblsl's first use, here and in the children
    import pylsl

    db = tmp / "study.db"
    help_text = subprocess.run([sys.executable, "-m", "vibrofocus", "simulate-study", "--help"],
                               capture_output=True, text=True, env={**os.environ, "COLUMNS": "200"}).stdout
    cmd = [sys.executable, "-m", "vibrofocus", "simulate-study", "-n", "1", "--seed", str(args.seed),
           "--db", str(db), "--quiet", "--lsl"]
    if "--lsl-wait" in help_text:
        cmd += ["--lsl-wait", str(args.wait_s)]
    received: list[tuple[str, float, int]] = []  # sample, stamp, run (1 before the kill, 2 after)
    run = [1]
    stop = threading.Event()
    ready = threading.Event()
    ids: dict[int, str] = {}

    def pull() -> None:
        streams = pylsl.resolve_bypred("name='vibrofocus-markers' and type='Markers'", 1, 60.0)
        inlet = pylsl.StreamInlet(streams[0], max_buflen=3600, recover=True)
        inlet.open_stream(timeout=60.0)
        ids[1] = inlet.info().source_id()
        ready.set()
        while not stop.is_set():
            sample, stamp = inlet.pull_sample(timeout=0.5)
            if sample is not None:
                received.append((sample[0], stamp, run[0]))

    def answers() -> int:
        with sqlite3.connect(db) as conn:
            return conn.execute("SELECT COUNT(*) FROM answers").fetchone()[0]

    reader = threading.Thread(target=pull, daemon=True)
    reader.start()
    first = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    ready.wait(120.0)
    while sum(_event(s) == "answer" for s, _, _ in received) < args.kill_after and first.poll() is None:
        time.sleep(0.001)
    first.send_signal(signal.SIGKILL)
    first.wait()
    killed_at = answers()
    time.sleep(1.0)
    run[0] = 2
    second = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    found = pylsl.resolve_bypred("name='vibrofocus-markers' and type='Markers'", 1, 60.0)
    ids[2] = found[0].source_id() if found else None
    second.wait()
    total = answers()
    time.sleep(3.0)  # the last markers in flight
    stop.set()
    reader.join(5.0)
    resumed = [r for r in received if r[2] == 2]
    samples = [s for s, _, _ in received]
    ordered = [(_event(s), t) for s, t, _ in received]
    after_next_cue, back = 0, 0.0
    for i, (event, stamp) in enumerate(ordered):
        if event == "answer":
            later_cues = [t for e, t in ordered[i + 1:] if e == "cue"]
            after_next_cue += bool(later_cues) and stamp > later_cues[0]
        if i:
            back = max(back, ordered[i - 1][1] - stamp)
    print(f"command: {' '.join(cmd[3:])}")
    print(f"second run exit code: {second.returncode}")
    print(f"source id: first run {ids.get(1)}, resumed run {ids.get(2)}")
    print(f"answers at the kill: {killed_at}; answers after the resume: {total} ({total - killed_at} in the resumed run)")
    print(f"markers received: before the kill {len(received) - len(resumed)}, of the resumed run {len(resumed)} "
          f"(expected {3 * (total - killed_at)}: cue, onset, answer per trial)")
    print(f"distinct marker strings: {len(set(samples))}")
    print(f"answers stamped after the next cue: {after_next_cue} of {sum(e == 'answer' for e, _ in ordered)}")
    print(f"largest backwards step of the stamps: {back:.3f} s")
    shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
