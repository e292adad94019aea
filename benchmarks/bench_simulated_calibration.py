"""How much faster than real time a calibration runs on the simulated forearm (docs/performance.md).

A real single-spot vibrometer calibration of the reference setup records, for each skin
point the operator aims at, one sweep per actuator (one actuator plays at a time). The
benchmark replays that flow on the simulated forearm with plain sweeps and
``play_and_record`` at one point per recording, estimates ``H`` per recording by spectral
division, and compares the wall-clock time with the real duration of the recordings
(sweep plus tail; the operator's aiming time is not counted, which favours real time).

Flows (recordings = points x actuators x repeats):

- ``paper``: the 9 locations x 4 actuators, one 2 s linear sweep each: 36 recordings;
- ``full``: all 13 points (locations and guards) x 4 actuators, one sweep each: 52;
- ``h1``: 13 x 4 x 8 repeats of a 2 s exponential sweep (the calibration default): 416.

Also times ``vibrofocus.calibration.calibrate`` on the simulated rig when that module is
available (the simulated rig records all points per take, so it needs fewer takes; its
real-time reference is the single-spot flow it stands for).

Run: ``python benchmarks/bench_simulated_calibration.py``. Prints ratios from one run.
"""

from __future__ import annotations

import time

import numpy as np

from vibrofocus import SimulatedForearm, ricker
from vibrofocus.signals import exponential_sweep, linear_sweep

FS = 10_000.0
SWEEP_S = 2.0
TAIL_S = 0.3
AMPLITUDE_V = 5.0


def simulate_flow(
    rig: SimulatedForearm, points: np.ndarray, sweep: np.ndarray, repeats: int
) -> tuple[float, float, int]:
    """Run the single-spot flow; return (wall seconds, real-time seconds, recordings)."""
    n_act = rig.layout.n_actuators
    n_fft = sweep.size + int(round(TAIL_S * FS))
    sweep_spectrum = np.fft.rfft(sweep, n_fft)
    n_rec = 0
    start = time.perf_counter()
    for p in points:
        for q in range(n_act):
            drive = np.zeros((n_act, sweep.size))
            drive[q] = sweep
            for _ in range(repeats):
                rec = rig.play_and_record(drive, p[None], tail_s=TAIL_S)[0]
                h = np.fft.rfft(np.nan_to_num(rec), n_fft) / np.where(sweep_spectrum == 0, 1, sweep_spectrum)
                n_rec += 1
    wall = time.perf_counter() - start
    assert h.shape == sweep_spectrum.shape  # the estimate was computed
    return wall, n_rec * (SWEEP_S + TAIL_S), n_rec


def main() -> None:
    rig = SimulatedForearm(seed=0)
    layout = rig.layout
    lin = AMPLITUDE_V * linear_sweep(FS, 10.0, 1000.0, SWEEP_S)
    exp = AMPLITUDE_V * exponential_sweep(FS, 7.0, 1400.0, SWEEP_S)
    rig.play_and_record(np.zeros((layout.n_actuators, 100)), layout.points_xy[:1])  # warm-up (sensitivity)
    flows = (
        ("paper: 9 locations x 4 actuators x 1", layout.locations_xy, lin, 1),
        ("full: 13 points x 4 actuators x 1", layout.points_xy, lin, 1),
        ("h1: 13 points x 4 actuators x 8", layout.points_xy, exp, 8),
    )
    print(f"simulated calibration of the reference setup, fs = {FS:g} Hz, sweeps {SWEEP_S:g} s + {TAIL_S:g} s tail")
    print(f"{'flow':<40} {'recordings':>10} {'real time s':>12} {'wall s':>8} {'x real time':>12}")
    for name, points, sweep, repeats in flows:
        fresh = SimulatedForearm(seed=0)
        wall, real, n_rec = simulate_flow(fresh, points, sweep, repeats)
        print(f"{name:<40} {n_rec:>10d} {real:>12.1f} {wall:>8.2f} {real / wall:>12.1f}")
    # The field over a dense grid (pictures, simulated participants): 2,025 points, 4 instants.
    axis = np.linspace(-0.04, 0.04, 45)
    grid = np.array(np.meshgrid(axis, axis)).reshape(2, -1).T
    drive = np.zeros((layout.n_actuators, 4096))
    drive[:] = ricker(FS, amplitude=5.0)
    start = time.perf_counter()
    rig.field(drive, grid, times=0.2048 + np.array([-3e-3, 0.0, 3e-3, 6e-3]))
    print(f"field: {len(grid)} points x 4 instants of a Ricker tap in {time.perf_counter() - start:.2f} s")
    try:
        from vibrofocus.calibration import calibrate
    except ImportError:  # the calibration module is optional for this benchmark
        return
    fresh = SimulatedForearm(seed=0)
    start = time.perf_counter()
    cal = calibrate(fresh, participant_id="bench")
    wall = time.perf_counter() - start
    real = layout.n_points * layout.n_actuators * 8 * (SWEEP_S + TAIL_S)
    print(f"{'calibrate() (h1 defaults, all points/take)':<40} {'':>10} {real:>12.1f} {wall:>8.2f} {real / wall:>12.1f}"
          f"   H {tuple(cal.H.shape)}")


if __name__ == "__main__":
    main()
