#!/usr/bin/env python
"""Print the checks of the simulated arm against the paper's own measurements.

For each skin preset (``--skin``, all presets by default) and participant seeds 0-3:

- the paper's plain pseudo-inverse (target + guards, equal weights, the true H) focused
  at location 5: zero-lag fidelity and whether location 5 peaks above every other;
- 10 V of the base tap on one nominal actuator: peak displacement on the actuator, and
  the drive a 2 µm tap 16 mm away would need;
- the guards' distance from their actuator's centre;
- phase speed and attenuation at 250 Hz.

    .venv/bin/python scripts/paper_checks.py [--skin nominal] [--seeds 0 1 2 3]
"""

from __future__ import annotations

import argparse
import inspect

import numpy as np

from vibrofocus.defaults import FS_HZ, SIGMA_S
from vibrofocus.rendering import render
from vibrofocus.rigs import SimulatedForearm
from vibrofocus.skin import ForearmParameters

N = 4096


def _arm(skin: str | None, **kwargs) -> SimulatedForearm:
    if skin is None:
        return SimulatedForearm(**kwargs)
    return SimulatedForearm(skin=skin, **kwargs)


def _single_actuator_peaks(skin: str | None) -> tuple[float, float]:
    """Peak on the actuator for a 10 V tap, and the drive a 2 µm tap at 16 mm needs."""
    arm = _arm(skin, participant=_nominal_params(skin), noise_m=0.0, dropout_rate=0.0, geometry="plane")
    act = arm.layout.actuators_xy[:1]
    freqs = np.fft.rfftfreq(N, 1 / FS_HZ)
    h = arm.transfer(np.vstack([act, act + [0.0, -16e-3]]), freqs)[:, :, 0]
    t = np.arange(N) / FS_HZ - 0.1
    tap = 10.0 * (1 - t**2 / SIGMA_S**2) * np.exp(-(t**2) / (2 * SIGMA_S**2))
    resp = np.fft.irfft(np.fft.rfft(tap)[:, None] * h, N, axis=0)
    on, far = np.abs(resp).max(axis=0)
    return float(on), float(10.0 * 2e-6 / far)


def _nominal_params(skin: str | None) -> ForearmParameters:
    if skin is None:
        return ForearmParameters.nominal(4)
    return ForearmParameters.nominal(4, skin=skin)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--skin", nargs="*", default=None, help="presets (default: all)")
    parser.add_argument("--seeds", nargs="*", type=int, default=[0, 1, 2, 3])
    args = parser.parse_args()
    has_presets = "skin" in inspect.signature(SimulatedForearm).parameters
    if has_presets:
        from vibrofocus.skin import SKIN_PRESETS

        skins = args.skin or list(SKIN_PRESETS)
    else:
        skins = [None]
    for skin in skins:
        fids, peaks_above = [], []
        for seed in args.seeds:
            arm = _arm(skin, seed=seed, noise_m=0.0, dropout_rate=0.0)
            H = arm.transfer(arm.layout.points_xy, np.fft.rfftfreq(N, 1 / arm.fs))
            r = render("inverse", H, arm.fs, arm.layout, 5, scale_to_limit=False, check_wraparound=False)
            fids.append(r.metrics()["fidelity"])
            peaks = np.abs(r.predicted[: arm.layout.n_locations]).max(axis=1)
            peaks_above.append(bool(np.argmax(peaks) == 4 and np.sum(peaks >= peaks[4]) == 1))
        on, v16 = _single_actuator_peaks(skin)
        lay = arm.layout
        guard_d = np.linalg.norm(lay.guards_xy[:, None] - lay.actuators_xy[None], axis=2).min(axis=1)
        p = arm.participant
        print(f"skin {skin or '(unmodified)'}")
        print(f"  pseudo-inverse fidelity at location 5, seeds {args.seeds}: {np.round(fids, 2).tolist()}"
              f"; location 5 peaks above every other: {peaks_above}")
        print(f"  10 V tap on one actuator: {on * 1e6:.2f} µm on it; 2 µm at 16 mm needs {v16:.0f} V")
        print(f"  guards {np.round(guard_d * 1e3, 1).tolist()} mm from their actuator's centre")
        f = np.array([100.0, 200.0, 250.0, 500.0, 1000.0])
        print(f"  seed {args.seeds[-1]}: c(100, 200, 250, 500, 1000 Hz) = {np.round(p.phase_speed(f), 2).tolist()} m/s, "
              f"alpha = {np.round(p.attenuation(f), 0).tolist()} Np/m")


if __name__ == "__main__":
    main()
