"""All actuators at once (``mimo``) against one at a time (``h1``) on the simulated forearm.

For several simulated participants (seeds), each method calibrates the reference setup
with its defaults, on the forearm with its vibrometer noise (1 nm RMS in band) and
dropouts. Reported per seed and method:

- real duration: the seconds of sweeps the rig played and recorded (silence, sweep and
  tail of every take, re-recordings after dropouts included), counted from the rig's
  own number of takes, not from the plan; the simulated forearm records all 13 points
  per take, a single-spot vibrometer multiplies both methods by 13;
- H error: the median relative error of ``H`` against the arm's true transfer
  (``calibration.accuracy.transfer_error``, bins within 40 dB of each pair's peak, in
  the calibrated band);
- the ratios mimo / h1 of both.

Target (issue 17): mimo at most 1/3 of h1's real duration at an equal or lower H error.
Also shown: mimo with h1's 2 s sweeps (a quarter of the time), where the error is only
equal on average, which is why the default spends part of the saving on 2.5 s sweeps.

Run: ``python benchmarks/bench_mimo_calibration.py [n_seeds]`` (default 5; about 10 s a
seed). Prints the table from one run.
"""

from __future__ import annotations

import sys

import numpy as np

from vibrofocus.calibration import calibrate, transfer_error
from vibrofocus.rigs import SimulatedForearm

METHODS = (("h1", {}), ("mimo", {}), ("mimo 2 s", {"sweep_s": 2.0}))


def run(seed: int, method: str, extra: dict) -> tuple[float, float]:
    """Calibrate participant ``seed``; return (real duration s, median relative H error)."""
    rig = SimulatedForearm(seed=seed)
    cal = calibrate(rig, participant_id=f"S{seed:02d}", method=method.split()[0], **extra)
    real_s = rig.n_played * cal.sweep.take_s  # every take plays and records one take_s
    assert np.isclose(real_s, cal.recorded_s)
    truth = rig.transfer(rig.layout.points_xy, cal.freqs)
    band = (cal.freqs >= cal.band[0]) & (cal.freqs <= cal.band[1])
    return real_s, transfer_error(cal.H[band], truth[band])["median_relative_error"]


def main(n_seeds: int = 5) -> None:
    print("calibration of the reference setup (13 points x 4 actuators) on the simulated forearm, "
          "noise 1 nm RMS in band, dropouts on")
    print("defaults: h1 = 4 actuators one at a time x 8 takes of 2 s sweeps; "
          "mimo = all 4 at once x 8 Hadamard-signed takes of 2.5 s sweeps")
    header = f"{'seed':>4} " + " ".join(f"{name + ' s':>10} {name + ' err':>12}" for name, _ in METHODS)
    print(header + f" {'time ratio':>10} {'err ratio':>9} {'2 s: time':>9} {'err':>6}")
    ratios = []
    for seed in range(n_seeds):
        rows = [run(seed, name, extra) for name, extra in METHODS]
        (t_h1, e_h1), (t_m, e_m), (t_m2, e_m2) = rows
        ratios.append((t_m / t_h1, e_m / e_h1, t_m2 / t_h1, e_m2 / e_h1))
        cells = " ".join(f"{t:>10.1f} {e:>12.3%}" for t, e in rows)
        print(f"{seed:>4} {cells} {ratios[-1][0]:>10.3f} {ratios[-1][1]:>9.3f} {ratios[-1][2]:>9.3f} "
              f"{ratios[-1][3]:>6.3f}", flush=True)
    r = np.array(ratios)
    print(f"mimo / h1 over {n_seeds} seeds: real duration {r[:, 0].mean():.3f} (max {r[:, 0].max():.3f}), "
          f"H error {r[:, 1].mean():.3f} (max {r[:, 1].max():.3f}); target duration <= 0.333 at error <= 1")
    print(f"mimo with 2 s sweeps / h1: real duration {r[:, 2].mean():.3f}, H error {r[:, 3].mean():.3f} "
          f"(range {r[:, 3].min():.3f}-{r[:, 3].max():.3f})")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 5)
