"""Contrast designs (ACC, constrained) and the contrast bound, batched over frequency,
against a per-frequency Python loop (scipy.linalg.eigh per frequency) on the same inputs.

Prints the ratios measured in this run, at the reference size (4096 samples, 13 points x 4
actuators) and for the 32-actuator sleeve (ArrayLayout.sleeve()).
Usage: python benchmarks/bench_contrast.py
"""

from __future__ import annotations

import time

import numpy as np
import scipy.linalg

from vibrofocus import ArrayLayout
from vibrofocus.rendering import constrained_drives, contrast_bound, contrast_drives
from vibrofocus.rendering.taper import band_taper
from vibrofocus.signals import ricker

FS = 10_000.0


def medium(layout: ArrayLayout, n: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    r = np.linalg.norm(layout.points_xy[:, None] - layout.actuators_xy[None], axis=-1)
    f = np.fft.rfftfreq(n, 1 / FS)[:, None, None]
    jitter = 1 + 0.2 * rng.standard_normal(r.shape)
    return 1e-6 / (1 + r / 0.01) * jitter * np.exp(-2j * np.pi * f * (2e-3 + r / 10.0))


def loop_acc(H, target, quiet, n, reg):
    """Reference: per frequency, scipy's generalized eigenvector, phase-aligned to the tap."""
    taper = band_taper(np.fft.rfftfreq(n, 1 / FS), (10.0, 1000.0), 0.5)
    U = np.fft.rfft(ricker(FS, 1e-3, n / FS, n / FS / 2)) * taper
    S = np.zeros((H.shape[0], H.shape[2]), complex)
    for f in np.flatnonzero(taper > 0):
        h = H[f, target]
        G = H[f, quiet].conj().T @ H[f, quiet]
        B = G + reg * np.trace(G).real / len(h) * np.eye(len(h))
        w, V = scipy.linalg.eigh(np.outer(h.conj(), h), B)
        v = V[:, -1]
        S[f] = v * U[f] / (h @ v)
    return np.fft.irfft(S, n, axis=0).T


def best_of(fn, repeat=3):
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t)
    return min(times), out


def main() -> None:
    for name, layout, n in (("reference 13 x 4", ArrayLayout.reference(), 4096),
                            ("sleeve %d x %d" % (ArrayLayout.sleeve().n_points, 32), ArrayLayout.sleeve(), 4096)):
        H = medium(layout, n)
        target = 0
        quiet = np.arange(1, layout.n_points)
        t_acc, d_acc = best_of(lambda: contrast_drives(H, target, FS, quiet_indices=quiet))
        t_con, _ = best_of(lambda: constrained_drives(H, target, FS, quiet_indices=quiet, min_contrast_db=-100.0))
        t_bnd, _ = best_of(lambda: contrast_bound(H, target, quiet, fs=FS))
        t_loop, d_loop = best_of(lambda: loop_acc(H, target, quiet, n, 1e-3), repeat=1)
        err = np.abs(d_acc - d_loop).max() / np.abs(d_loop).max()
        print(f"{name}, {n} samples: ACC {t_acc * 1e3:.1f} ms, constrained {t_con * 1e3:.1f} ms, "
              f"bound {t_bnd * 1e3:.1f} ms; per-frequency scipy loop {t_loop * 1e3:.0f} ms -> "
              f"ACC {t_loop / t_acc:.1f}x, constrained {t_loop / t_con:.1f}x faster (max rel. difference {err:.1e})")


if __name__ == "__main__":
    main()
