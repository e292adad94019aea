"""minimax_filter (reduced basis, Toeplitz target norm, constraint generation, CVXOPT's cone
solver called on the dense rows; no cvxpy) against a plain cvxpy + Clarabel program on the same
inputs (every drive sample of the support a variable through an orthonormal basis of the
band-limited pulses, every response sample a peak constraint, dense circulant convolutions).

Prints both times from one run, their ratio and the two optima, for the reference setup
(13 points x 4 actuators, 10 kHz) on a synthetic medium, on a short window (default 1024
samples: the plain program's circulant rows grow as n^2 and do not fit the reference window
of 8192 samples in memory and minutes); also the fast path alone at n = 8192.
Usage: python benchmarks/bench_minimax.py [n_samples]   (needs the test extra: cvxpy, Clarabel)
"""

from __future__ import annotations

import sys
import time
import warnings

import numpy as np

from vibrofocus import ArrayLayout
from vibrofocus.rendering import minimax_filter
from vibrofocus.rendering.taper import design_grid
from vibrofocus.signals import ricker

FS = 10_000.0
BAND = (10.0, 1000.0)
SUPPORT = (0.01, 0.005)


def medium(layout: ArrayLayout, n: int, seed: int = 0) -> np.ndarray:
    """Causal synthetic transfer (delay by distance at 10 m/s, 1/r decay, jitter), m/V."""
    rng = np.random.default_rng(seed)
    r = np.linalg.norm(layout.points_xy[:, None] - layout.actuators_xy[None], axis=-1)
    f = np.fft.rfftfreq(n, 1 / FS)[:, None, None]
    jitter = 1 + 0.2 * rng.standard_normal(r.shape)
    return 1e-6 / (1 + r / 0.01) * jitter * np.exp(-2j * np.pi * f * (2e-3 + r / 10.0)) / (1 + 1j * f / 400.0)


def plain(H, targets, n, min_fidelity):
    import cvxpy as cp

    taper = design_grid(n, FS, BAND, 0.5)[1]
    ti = int(np.flatnonzero(np.any(targets != 0, axis=1))[0])
    d = np.fft.irfft(np.fft.rfft(targets[ti]) * taper, n)
    scale = np.linalg.norm(d)
    d = d / scale
    tp = int(np.argmax(np.abs(d)))
    sup = np.arange(tp - int(SUPPORT[0] * FS), tp + int(SUPPORT[1] * FS) + 1)
    pulse = np.fft.irfft(taper, n)
    P = np.stack([np.roll(pulse, k) for k in sup], axis=1)
    U, sv, _ = np.linalg.svd(P, full_matrices=False)
    B = U[:, sv > 1e-6 * sv[0]]
    h = np.fft.irfft(H, n, axis=0)
    h = h / np.max(np.abs(h))
    n_pts, n_act = H.shape[1], H.shape[2]
    circ = lambda x: np.stack([np.roll(x, k) for k in range(n)], axis=1)  # noqa: E731
    z = cp.Variable((n_act, B.shape[1]))
    s = cp.Variable()
    ys = [sum((circ(h[:, p, a]) @ B) @ z[a] for a in range(n_act)) for p in range(n_pts)]
    cons = [d @ ys[ti] == 1, cp.norm(ys[ti]) <= 1 / min_fidelity]
    cons += [cp.abs(ys[p]) <= s for p in range(n_pts) if p != ti]
    cp.Problem(cp.Minimize(s), cons).solve(solver="CLARABEL")
    return float(s.value)


def main() -> None:
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 1024
    layout = ArrayLayout.reference()
    H = medium(layout, n)
    targets = np.zeros((layout.n_points, n))
    ti = layout.location_index(5)
    targets[ti] = 2e-6 * ricker(FS, 1e-3, n / FS, n / FS / 2)
    warnings.simplefilter("ignore", UserWarning)
    t = time.perf_counter()
    _, rep = minimax_filter(H, targets, FS, band=BAND, min_fidelity=0.95, support_s=SUPPORT, full_output=True,
                            fidelity_margin=0.0)
    fast = time.perf_counter() - t
    t = time.perf_counter()
    ref = plain(H, targets, n, 0.95)
    slow = time.perf_counter() - t
    print(f"reference layout 13 x 4, n={n}, fs={FS:g} Hz, fidelity >= 0.95, support {SUPPORT} s")
    print(f"minimax_filter: {fast:.1f} s ({rep.iterations} rounds, {rep.n_constraints} peak constraints, "
          f"{rep.n_variables} variables), peak contrast {rep.peak_contrast_db:.2f} dB")
    print(f"plain cvxpy:    {slow:.1f} s")
    print(f"ratio plain cvxpy / minimax_filter: {slow / fast:.1f}x")
    print("optima (largest quiet peak over the target's projection on the tap): "
          f"minimax_filter {rep.model_quiet_peak / np.linalg.norm(rep.desired):.5g}, plain {ref:.5g}")
    n_ref = 8192
    H = medium(layout, n_ref)
    targets = np.zeros((layout.n_points, n_ref))
    targets[ti] = 2e-6 * ricker(FS, 1e-3, n_ref / FS, n_ref / FS / 2)
    t = time.perf_counter()
    _, rep = minimax_filter(H, targets, FS, band=BAND, min_fidelity=0.95, support_s=SUPPORT, full_output=True)
    print(f"minimax_filter at n={n_ref}: {time.perf_counter() - t:.1f} s ({rep.iterations} rounds, "
          f"{rep.n_constraints} peak constraints)")


if __name__ == "__main__":
    main()
