"""``serve-osc --rig audio``: time from a tap's datagram to its first sample at the outputs.

A private JACK server runs on its dummy driver with loopback ports (``jackd -d dummy -L 6``,
48 kHz, ``--period`` frames). ``serve-osc``'s server (:class:`~vibrofocus.realtime.OscTapServer`)
runs in this process on the audio rig (device ``loopback``); a second JACK client, in a
process of its own, records ``loopback:capture_1..4`` like a scope. The loopback returns
what was written to ``loopback:playback_k`` one period later; the scope subtracts that
period, so a tap's time at the outputs is the JACK frame at which its first non-zero
sample was at the rig's playback ports, on ``time.monotonic()`` (the frame's offset from
the scope's cycle, through JACK's frame clock).

The latency of a tap runs from the kernel's receipt of its datagram (SO_TIMESTAMP, the
server's ``receipt_s``) to that time. Two runs:

- ``--taps`` taps (``/tap``, locations 1..9 in turn) sent at ``--rate`` per second;
  p50, p99 and the maximum, with the period, and how many were played and refused stale;
- 30 taps sent at once: how many were played (the rest answered ``/error stale``).

The taps are designed from the simulated arm at the rig's 10 kHz with a window of
``--window`` samples (800: 80 ms drives, whose 20 ms of silence between taps at 10/s
lets the scope tell one tap's onset from the next).

Tuning (docs/performance.md): ``--realtime`` runs jackd with real-time scheduling (``-R``:
its threads and its clients' process threads, the rig's callback among them, SCHED_FIFO;
needs the right to it: root, or the ``audio`` group's rtprio), ``--switch-interval-ms`` sets
Python's GIL switch interval (default 5 ms, about a 256-frame period: a callback waiting for
the GIL can miss its period), ``--latency`` the rig's ``latency`` (``low``, ``high`` or s).

Usage: python benchmarks/bench_tap_outputs.py [--period 256] [--taps 200] [--rate 10] [--window 800]
       [--realtime] [--switch-interval-ms 0.5] [--latency high]
"""

from __future__ import annotations

import argparse
import atexit
import json
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time

import numpy as np

RATE = 48_000
PORTS = 6
#: Exact zeros for at least this long end a tap at the outputs, s.
QUIET_S = 0.005


def scope(server: str, period: int) -> None:
    """The second JACK client: print, at SIGTERM, the onsets at the outputs (monotonic s) as JSON."""
    import jack

    client = jack.Client("vibrofocus-scope", servername=server, no_start_server=True)
    ports = [client.inports.register(f"in_{k}") for k in range(1, 5)]
    onsets: list[float] = []
    state = {"quiet": True, "zeros": 0}
    quiet_frames = int(QUIET_S * RATE)

    @client.set_process_callback
    def process(frames):
        now = time.monotonic()
        since = client.frames_since_cycle_start
        x = np.max(np.abs(np.stack([p.get_array() for p in ports])), axis=0)
        loud = np.flatnonzero(x > 0)
        if loud.size == 0:
            state["zeros"] += frames
            if state["zeros"] >= quiet_frames:
                state["quiet"] = True
            return
        # Gaps within this buffer of QUIET_S or more also end a tap.
        starts = [loud[0]] + [b for a, b in zip(loud[:-1], loud[1:]) if b - a > quiet_frames]
        if not state["quiet"] and state["zeros"] + loud[0] < quiet_frames:
            starts = starts[1:]
        for k in starts:
            # Sample k of this cycle was at the playback ports one period (the loopback) earlier.
            onsets.append(now - (since + period - int(k)) / RATE)
        state["zeros"] = frames - 1 - int(loud[-1])
        state["quiet"] = state["zeros"] >= quiet_frames

    done = threading.Event()
    signal.signal(signal.SIGTERM, lambda *a: done.set())
    with client:
        for k, port in enumerate(ports, start=1):
            client.connect(f"loopback:capture_{k}", port)
        print("ready", flush=True)
        done.wait()
    print(json.dumps(onsets), flush=True)


def start_jack(name: str, period: int, realtime: bool = False) -> subprocess.Popen:
    rt = ["-R", "-P", "70"] if realtime else ["--no-realtime"]
    proc = subprocess.Popen(["jackd", "-n", name, *rt, "-L", str(PORTS), "-d", "dummy", "-r", str(RATE),
                             "-p", str(period), "-C", "2", "-P", "2"], stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL, start_new_session=True)
    for _ in range(150):
        said = subprocess.run(["jack_wait", "-s", name, "-c"], capture_output=True, text=True).stdout
        if "running" in said and "not" not in said:
            return proc
        time.sleep(0.1)
    proc.kill()
    raise SystemExit("jackd did not start (needs jackd2)")


def send_taps(server, n: int, rate: float | None, sent: list | None = None) -> tuple[int, int, int]:
    """Send n /tap (their send times, monotonic s, to ``sent``); return (played, stale, other errors)."""
    from pythonosc.osc_message import OscMessage
    from pythonosc.udp_client import SimpleUDPClient

    client = SimpleUDPClient(*server.address)
    t0 = time.monotonic()
    for i in range(n):
        if rate:
            time.sleep(max(0.0, t0 + i / rate - time.monotonic()))
        if sent is not None:
            sent.append(time.monotonic())
        client.send_message("/tap", 1 + i % 9)
    counts = {"played": 0, "stale": 0, "other": 0}
    others = []
    for _ in range(n):
        try:
            reply = OscMessage(client.receive(60))
        except Exception as exc:  # noqa: BLE001 - no answer (a timeout), or not OSC
            counts["other"] += 1
            others.append(f"no answer: {exc}")
            continue
        if reply.address == "/played":
            counts["played"] += 1
        elif str(reply.params[0]).startswith("stale"):
            counts["stale"] += 1
        else:
            counts["other"] += 1
            others.append(reply.params[0])
    if others:
        print(f"  other errors, first: {others[0][:160]}")
    return counts["played"], counts["stale"], counts["other"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--period", type=int, default=256, help="JACK period, frames (default 256)")
    parser.add_argument("--taps", type=int, default=200, help="Taps in the timed run (default 200)")
    parser.add_argument("--rate", type=float, default=10.0, help="Taps per second in the timed run (default 10)")
    parser.add_argument("--window", type=int, default=800, help="Design window, samples at 10 kHz (default 800)")
    parser.add_argument("--realtime", action="store_true", help="jackd -R: real-time scheduling (needs the right)")
    parser.add_argument("--switch-interval-ms", type=float, help="Python's GIL switch interval, ms (default 5)")
    parser.add_argument("--latency", default="low", help="The rig's latency: low, high or seconds (default low)")
    parser.add_argument("--scope", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.switch_interval_ms:
        sys.setswitchinterval(args.switch_interval_ms / 1e3)
    if args.scope:
        scope(args.scope, args.period)
        return

    import logging

    logging.basicConfig(level=logging.ERROR)
    name = f"vibrofocus-bench-{os.getpid()}"
    os.environ["JACK_DEFAULT_SERVER"], os.environ["JACK_NO_START_SERVER"] = name, "1"
    # The server is this run's own, so is the device ("loopback" on it): device locks of
    # its own too, beside other programs' rigs on other JACK servers of this machine.
    os.environ["VIBROFOCUS_LOCK_DIR"] = tempfile.mkdtemp(prefix="vibrofocus-bench-locks-")
    jackd = start_jack(name, args.period, args.realtime)

    def stop_jack() -> None:
        jackd.terminate()
        jackd.wait(10)

    # Registered before sounddevice is imported, so it runs after sounddevice's own exit
    # handler: PortAudio leaves the server before the server goes.
    atexit.register(stop_jack)
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))  # `timeout` ends the server too
    from vibrofocus.realtime import OscTapServer, TapDesigner
    from vibrofocus.rendering import TransferMatrix
    from vibrofocus.rigs import make_rig
    from vibrofocus.rigs.simulated import SimulatedForearm

    config = {
        "kind": "audio", "fs": 10_000.0, "amplifier_gain": 10.0, "volts_full_scale": 2.0,
        "input_volts_full_scale": 0.5, "max_latency_s": 0.2,
        "latency": args.latency if args.latency in ("low", "high") else float(args.latency),
        "device": {"name": "loopback", "hostapi": "JACK", "samplerate": float(RATE)},
        "channels": {"actuators": [1, 2, 3, 4], "vibrometer": 1, "loopback_output": 5, "loopback_input": 5},
        "vibrometer": {"decoder": "displacement", "sensitivity": 1e-6, "highpass_hz": None}}
    t = time.monotonic()
    rig = make_rig("audio", config=config)
    print(f"rig opened in {1e3 * (time.monotonic() - t):.0f} ms; JACK dummy, {args.period} frames at {RATE} Hz "
          f"({1e3 * args.period / RATE:.2f} ms), {os.cpu_count()} CPUs, load {os.getloadavg()[0]:.1f}; "
          f"{'real-time' if args.realtime else 'no real-time'} jackd, GIL switch interval "
          f"{1e3 * sys.getswitchinterval():g} ms, rig latency {args.latency} ({1e3 * rig.output_latency_s:.1f} ms)")
    arm = SimulatedForearm(seed=3, fs=rig.fs)
    designer = TapDesigner(TransferMatrix.from_model(arm, rig.layout, rig.fs, n_samples=args.window), None,
                           method="inverse", limit_v=rig.limits.peak_v)
    for location in range(1, 10):
        designer.drives_at(location)  # designed ahead, as serve-osc does
    server = OscTapServer(rig, designer, port=0, clock=time.monotonic)
    thread = threading.Thread(target=server.serve, daemon=True)
    thread.start()
    # One play before anything is timed (the first stream of the process).
    played, _, _ = send_taps(server, 1, None)
    probe = subprocess.Popen([sys.executable, __file__, "--scope", name, "--period", str(args.period)],
                             stdout=subprocess.PIPE, text=True)
    assert probe.stdout.readline().strip() == "ready"
    n_before = len(server.records)
    t = time.monotonic()
    sent: list[float] = []
    played, stale, other = send_taps(server, args.taps, args.rate, sent)
    print(f"{args.taps} taps at {args.rate:g}/s: {played} played, {stale} stale, {other} other errors "
          f"({time.monotonic() - t:.1f} s)")
    time.sleep(0.3)
    probe.send_signal(signal.SIGTERM)
    onsets = np.array(json.loads(probe.communicate(timeout=30)[0].strip().splitlines()[-1]))
    records = server.records[n_before:]
    lat = []
    for r in records:  # the first onset at the outputs after each tap's receipt
        later = onsets[onsets > r.receipt_s]
        if later.size:
            lat.append(later[0] - r.receipt_s)
    lat = 1e3 * np.array(lat)
    # Every tap that reached the outputs, played or not (one the stream lost samples in
    # is answered /error): from its send, just before the kernel's receipt.
    every = 1e3 * np.array([onsets[onsets > t][0] - t for t in sent if (onsets > t).any()
                            and onsets[onsets > t][0] - t < 1.0 / args.rate])
    if every.size:
        print(f"  send -> first non-zero sample at the outputs, every tap that reached them ({every.size}): "
              f"p50 {np.percentile(every, 50):.2f} ms, p99 {np.percentile(every, 99):.2f} ms, "
              f"max {every.max():.2f} ms")
    print(f"  onsets at the outputs: {len(onsets)} for {len(records)} taps played; stream xruns: "
          f"{getattr(getattr(rig, '_stream', None), 'xruns', '?')} buffers since it opened")
    if lat.size:
        print(f"  receipt -> first non-zero sample at the outputs: p50 {np.percentile(lat, 50):.2f} ms, "
              f"p99 {np.percentile(lat, 99):.2f} ms, max {lat.max():.2f} ms, min {lat.min():.2f} ms "
              f"(period {1e3 * args.period / RATE:.2f} ms; target p99 <= {1e3 * args.period / RATE + 10:.2f} ms)")
        handed = 1e3 * np.array([r.played_s - r.receipt_s for r in records])
        print(f"  receipt -> play() returned: p50 {np.percentile(handed, 50):.1f} ms, "
              f"p99 {np.percentile(handed, 99):.1f} ms")
    time.sleep(1.0)
    played, stale, other = send_taps(server, 30, None)
    print(f"30 taps sent at once: {played} played, {stale} stale, {other} other errors")
    server.stop()
    thread.join(10)
    server.close()
    rig.close()


if __name__ == "__main__":
    main()
