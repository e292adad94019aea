"""``serve-osc``: time from a message's receipt to the first sample handed to the rig.

A server runs in a thread on the simulated rig (the default of ``vibrofocus serve-osc``);
a python-osc client on localhost asks for taps at random points of the calibrated area
(``/tap_xy``, seeded) and then at random locations (``/tap``), one after the other, each
after the last one's ``/played``. For every tap the time runs from the moment the server
read its datagram to the moment the rig's backend received the checked drive (after the
design, the safety layer and the energy budget): its first sample handed to the rig.

With ``--jack`` the rig is the audio rig on a JACK server of its own with the dummy
driver (``jackd -d dummy``, 48 kHz, as the test suite starts it; needs jackd2 and
libportaudio2), and the taps are designed from the simulated arm's model at the rig's rate.
Its ``play`` lasts as long as the drive, so each tap waits for the last one to end.

Prints p50, p99 and the maximum per kind of tap, from this run.
Usage: python benchmarks/bench_osc_latency.py [--taps 500] [--seed 29] [--jack] [--no-locations]
"""

from __future__ import annotations

import argparse
import contextlib
import os
import platform
import subprocess
import threading
import time

import numpy as np
from pythonosc.osc_message import OscMessage
from pythonosc.udp_client import SimpleUDPClient

from vibrofocus.realtime import OscTapServer, TapDesigner
from vibrofocus.rendering import TransferMatrix
from vibrofocus.rigs import DeviceOnset
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

    def _play(self, drive: np.ndarray) -> DeviceOnset:
        self.handed_s.append(time.perf_counter())
        onset = super()._play(drive)
        self._t += drive.shape[1] / self.fs
        return onset


@contextlib.contextmanager
def jack_rig():
    """The audio rig on a private JACK server with the dummy driver and loopback ports."""
    from vibrofocus.rigs.audio import AudioRig
    from vibrofocus.rigs.config import parse_rig_config

    class TimedAudioRig(AudioRig):
        def __init__(self, *args, **kwargs):
            super().__init__(*args, **kwargs)
            self.handed_s: list[float] = []

        def _play(self, drive: np.ndarray) -> DeviceOnset:
            handed = time.perf_counter()
            onset = super()._play(drive)
            self.handed_s.append(handed)  # a play the stream lost (an xrun) is no tap played
            return onset

    name = f"vibrofocus-bench-{os.getpid()}"
    os.environ["JACK_DEFAULT_SERVER"], os.environ["JACK_NO_START_SERVER"] = name, "1"
    jack = subprocess.Popen(["jackd", "-n", name, "--no-realtime", "-L", "6", "-d", "dummy", "-r", "48000", "-p",
                             "1024", "-C", "2", "-P", "2"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        for _ in range(150):
            said = subprocess.run(["jack_wait", "-s", name, "-c"], capture_output=True, text=True).stdout
            if "running" in said and "not" not in said:
                break
            time.sleep(0.1)
        else:
            raise SystemExit("jackd did not start (needs jackd2)")
        import sounddevice as sd

        sd._terminate()  # PortAudio lists JACK's devices only if initialized after the server started
        sd._initialize()
        config = parse_rig_config({
            "kind": "audio", "fs": 10_000.0, "amplifier_gain": 10.0, "volts_full_scale": 2.0,
            "input_volts_full_scale": 0.5, "max_latency_s": 0.2,
            "device": {"name": "loopback", "hostapi": "JACK", "samplerate": 48_000.0},
            "channels": {"actuators": [1, 2, 3, 4], "vibrometer": 1, "loopback_output": 5, "loopback_input": 5},
            "vibrometer": {"decoder": "displacement", "sensitivity": 1e-6, "highpass_hz": None}})
        rig = TimedAudioRig(config)
        try:
            yield rig
        finally:
            rig.close()
            sd._terminate()  # PortAudio's JACK client goes before the server does
    finally:
        jack.terminate()
        jack.wait(10)


def run(rig, n_taps: int, seed: int, locations: bool = True) -> dict[str, np.ndarray]:
    t = time.perf_counter()
    model = rig if isinstance(rig, SimulatedForearm) else SimulatedForearm(seed=0, fs=rig.fs)
    tm = TransferMatrix.from_model(model, rig.layout, rig.fs)
    designer = TapDesigner(tm, model, method="inverse", limit_v=rig.limits.peak_v)
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
    if locations:
        asks += [("/tap", int(rng.integers(1, designer.layout.n_locations + 1))) for _ in range(n_taps)]
    errors = []
    for address, args in asks:
        client.send_message(address, args)
        reply = OscMessage(client.receive(60))
        if reply.address != "/played":
            errors.append((address, args, reply.params))
    server.stop()
    thread.join(10)
    server.close()
    if errors:
        # Only the audio rig's lost streams (xruns on a loaded machine) are expected here.
        print(f"{len(errors)} of {len(asks)} taps were answered /error, first: {errors[0][2]}")
    lat = (np.array(rig.handed_s) - np.array([r.receipt_s for r in server.records])) * 1e3
    xy = np.array([r.target.startswith("x ") for r in server.records])
    out = {"/tap_xy (random point)": lat[xy]}
    if locations:
        out["/tap (random location)"] = lat[~xy]
    return out


def main() -> None:
    import logging

    # The audio rig logs each resampled drive it clips by a hair to the limit: not news here.
    logging.getLogger("vibrofocus.rigs.audio").setLevel(logging.ERROR)
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--taps", type=int, default=500, help="Taps of each kind (default 500).")
    parser.add_argument("--seed", type=int, default=29)
    parser.add_argument("--jack", action="store_true", help="The audio rig on JACK's dummy driver.")
    parser.add_argument("--no-locations", action="store_true", help="Only /tap_xy taps.")
    args = parser.parse_args()
    print(f"{platform.processor() or platform.machine()}, Python {platform.python_version()}, numpy {np.__version__}")
    with (jack_rig() if args.jack else contextlib.nullcontext(TimedForearm(seed=0))) as rig:
        print(f"rig: {rig.kind}" + (" (JACK dummy driver, 48 kHz, 1024-frame periods)" if args.jack else " (simulated)"))
        results = run(rig, args.taps, args.seed, locations=not args.no_locations)
    print(f"{'taps':<26}{'n':>6}{'p50 ms':>9}{'p99 ms':>9}{'max ms':>9}")
    for name, ms in results.items():
        print(f"{name:<26}{len(ms):>6}{np.percentile(ms, 50):>9.2f}{np.percentile(ms, 99):>9.2f}{ms.max():>9.2f}")


if __name__ == "__main__":
    main()
