"""``serve-osc``: time from a message's receipt to the first sample handed to the rig.

A server runs in a thread on the simulated rig (the default of ``vibrofocus serve-osc``);
a python-osc client on localhost asks for taps at random points of the calibrated area
(``/tap_xy``, seeded) and then at random locations (``/tap``), one after the other, each
after the last one's ``/played``. For every tap the time runs from the moment the server
read its datagram to the moment the rig's backend received the checked drive (after the
design, the safety layer and the energy budget): its first sample handed to the rig.

Prints p50, p99 and the maximum per kind of tap, from this run.
Usage: python benchmarks/bench_osc_latency.py [--taps 500] [--seed 29]
"""

from __future__ import annotations

import argparse
import platform
import threading
import time

import numpy as np
from pythonosc.osc_message import OscMessage
from pythonosc.udp_client import SimpleUDPClient

from vibrofocus.realtime import OscTapServer, TapDesigner
from vibrofocus.rendering import TransferMatrix
from vibrofocus.rigs.simulated import SimulatedForearm


class TimedForearm(SimulatedForearm):
    """The simulated rig, noting when its backend receives each checked drive.

    Its plays are placed one after the other on a clock that advances by each drive's
    length (a real rig plays for that long), so the energy budget sees the taps as a
    participant would feel them back to back, not overlapping at the same instant.
    """

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.handed_s: list[float] = []
        self._t = 0.0

    def _clock(self) -> float:
        return self._t

    def _play(self, drive: np.ndarray) -> None:
        self.handed_s.append(time.perf_counter())
        super()._play(drive)
        self._t += drive.shape[1] / self.fs


def run(n_taps: int, seed: int) -> dict[str, np.ndarray]:
    rig = TimedForearm(seed=0)
    t = time.perf_counter()
    tm = TransferMatrix.from_model(rig, rig.layout, rig.fs)
    designer = TapDesigner(tm, rig, method="inverse", limit_v=rig.limits.peak_v)
    designer.prepare_grid()
    print(f"start-up (transfer, 9 designs, model grid): {time.perf_counter() - t:.1f} s; window {tm.n_samples} "
          f"samples at {tm.fs:g} Hz")
    server = OscTapServer(rig, designer, port=0)
    thread = threading.Thread(target=server.serve, daemon=True)
    thread.start()
    client = SimpleUDPClient(*server.address)
    rng = np.random.default_rng(seed)
    (x0, x1), (y0, y1) = designer.area.x_m, designer.area.y_m
    asks = [("/tap_xy", [float(rng.uniform(x0, x1) * 1e3), float(rng.uniform(y0, y1) * 1e3)]) for _ in range(n_taps)]
    asks += [("/tap", int(rng.integers(1, designer.layout.n_locations + 1))) for _ in range(n_taps)]
    errors = []
    for address, args in asks:
        client.send_message(address, args)
        reply = OscMessage(client.receive(30))
        if reply.address != "/played":
            errors.append((address, args, reply.params))
    server.stop()
    thread.join(10)
    server.close()
    if errors:
        raise SystemExit(f"{len(errors)} taps were refused, first: {errors[0]}")
    lat = (np.array(rig.handed_s) - np.array([r.receipt_s for r in server.records])) * 1e3
    return {"/tap_xy (random point)": lat[:n_taps], "/tap (random location)": lat[n_taps:]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--taps", type=int, default=500, help="Taps of each kind (default 500).")
    parser.add_argument("--seed", type=int, default=29)
    args = parser.parse_args()
    print(f"{platform.processor() or platform.machine()}, Python {platform.python_version()}, numpy {np.__version__}")
    results = run(args.taps, args.seed)
    print(f"{'taps':<26}{'n':>6}{'p50 ms':>9}{'p99 ms':>9}{'max ms':>9}")
    for name, ms in results.items():
        print(f"{name:<26}{len(ms):>6}{np.percentile(ms, 50):>9.2f}{np.percentile(ms, 99):>9.2f}{ms.max():>9.2f}")


if __name__ == "__main__":
    main()
