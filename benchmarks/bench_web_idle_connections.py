"""``vibrofocus serve`` under idle connections (issue 30).

Prints, from one run against a real server (a subprocess on 127.0.0.1, ``--pace fast``,
a dry-run Study 1 session answered over HTTP as its page would):

- a participant's answer latency (the POST of an answer until its commit is confirmed)
  with no other connection open;
- then, while another program opens ``--idle`` silent TCP connections and keeps opening
  more: how many the server holds (its open sockets), whether a new client still gets a
  page and how long that takes, and the participant's answer latency under that load;
- the size of the server's log at the end.

Run: ``python benchmarks/bench_web_idle_connections.py [--idle 5000] [--max-connections 1000]``.
The client needs about ``--idle`` file descriptors of its own (``ulimit -n``).
"""

from __future__ import annotations

import argparse
import os
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import httpx

TOKEN = "bench-token-" + "x" * 20


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _sockets(pid: int) -> int:
    n = 0
    for fd in os.listdir(f"/proc/{pid}/fd"):
        try:
            n += os.readlink(f"/proc/{pid}/fd/{fd}").startswith("socket:")
        except OSError:
            pass
    return n


def _wait_state(base: str, sid: int, key: str, state: str) -> dict:
    seq = -1
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        try:
            st = httpx.get(f"{base}/api/participant/{sid}/state?after={seq}&wait=1&ready=1",
                           headers={"X-Participant-Key": key}, timeout=10).json()
        except httpx.TransportError:
            continue  # closed under us as the longest-idle connection: ask again
        seq = st["seq"]
        if st["state"] == state:
            return st
    raise RuntimeError(f"session {sid} never reached {state}")


def _answer_latencies(base: str, sid: int, key: str, trials: range) -> list[float]:
    out = []
    for i in trials:
        st = _wait_state(base, sid, key, "respond")
        body = {"session_id": sid, "trial_index": st["trial_index"], "response": [5], "rt_s": 0.5, "answer_id": f"bench-{i:05d}"}
        t0 = time.perf_counter()
        for _ in range(20):
            try:
                r = httpx.post(f"{base}/api/participant/{sid}/answer", json=body, headers={"X-Participant-Key": key}, timeout=10)
                break
            except httpx.TransportError:
                continue
        out.append(time.perf_counter() - t0)
        assert r.status_code == 200, r.text
    return out


def _ms(values: list[float]) -> str:
    return f"median {1e3 * statistics.median(values):.1f} ms, max {1e3 * max(values):.1f} ms (n={len(values)})"


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--idle", type=int, default=5000, help="idle connections opened")
    ap.add_argument("--max-connections", type=int, default=1000)
    ap.add_argument("--trials", type=int, default=10, help="answers timed in each phase")
    args = ap.parse_args()

    tmp = Path(tempfile.mkdtemp(prefix="vf-bench-web-"))
    port = _free_port()
    base = f"http://127.0.0.1:{port}"
    log = tmp / "server.log"
    env = dict(os.environ, VIBROFOCUS_TOKEN=TOKEN)
    with open(log, "wb") as fh:
        proc = subprocess.Popen([sys.executable, "-m", "vibrofocus", "serve", "--db", str(tmp / "s.sqlite"), "--port", str(port),
                                 "--no-browser", "--pace", "fast", "--max-connections", str(args.max_connections)],
                                stdout=fh, stderr=subprocess.STDOUT, env=env)
    held: list[socket.socket] = []
    try:
        headers = {"X-Vibrofocus-Token": TOKEN}
        for _ in range(300):
            try:
                if httpx.get(f"{base}/api/rigs", headers=headers, timeout=1).status_code == 200:
                    break
            except httpx.TransportError:
                time.sleep(0.1)
        httpx.post(f"{base}/api/participants", json={"participant_id": "B01"}, headers=headers)
        s = httpx.post(f"{base}/api/sessions", headers=headers, json={
            "participant_id": "B01", "study": 1, "seed": 1, "n_training": 0, "repetitions": 3}).json()
        sid, key = s["session_id"], s["participant_url"].split("key=")[1]
        httpx.post(f"{base}/api/sessions/{sid}/start", headers=headers)
        quiet = _answer_latencies(base, sid, key, range(args.trials))
        print(f"answer latency, no other connection: {_ms(quiet)}")

        t0 = time.perf_counter()
        for _ in range(args.idle):
            held.append(socket.create_connection(("127.0.0.1", port)))
        print(f"opened {args.idle} idle connections in {time.perf_counter() - t0:.1f} s")
        stop = threading.Event()

        def keep_opening() -> None:
            while not stop.is_set():
                try:
                    held.append(socket.create_connection(("127.0.0.1", port)))
                except OSError:
                    pass
                time.sleep(0.01)

        opener = threading.Thread(target=keep_opening, daemon=True)
        opener.start()
        time.sleep(1.0)
        print(f"sockets the server holds: {_sockets(proc.pid)} (cap {args.max_connections})")
        t0 = time.perf_counter()
        r = httpx.get(f"{base}/api/rigs", headers=headers, timeout=30)
        print(f"a new client under that load: HTTP {r.status_code} in {1e3 * (time.perf_counter() - t0):.1f} ms")
        loaded = _answer_latencies(base, sid, key, range(args.trials, 2 * args.trials))
        print(f"answer latency under that load: {_ms(loaded)}")
        stop.set()
        opener.join(5)
        print(f"sockets the server holds at the end: {_sockets(proc.pid)}; opened in all: {len(held)}")
    finally:
        for sock in held:
            sock.close()
        proc.terminate()
        proc.wait(10)
    print(f"server log: {log.stat().st_size} bytes")


if __name__ == "__main__":
    main()
