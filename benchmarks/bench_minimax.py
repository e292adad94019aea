"""minimax_filter (reduced basis, Toeplitz target norm, constraint generation, CVXOPT's cone
solver called on the dense rows; no cvxpy) against a plain cvxpy + Clarabel program on the same
inputs (every drive sample of the support a variable through an orthonormal basis of the
band-limited pulses, every response sample a peak constraint, dense circulant convolutions).

Prints both times from one run, their ratio and the two optima, for the reference setup
(13 points x 4 actuators, 10 kHz) on a synthetic medium, on a short window (default 1024
samples: the plain program's circulant rows grow as n^2 and do not fit the reference window
of 8192 samples in memory and minutes); also the fast path alone at n = 8192.

Then the long-response case beside it: a simulated arm with four exciters 9-15 cm from nine
points at 1.3 kHz (band 10-500 Hz), where the waves take 20-30 ms to arrive. minimax_filter
with its defaults (support from H) against the naive pseudo-inverse: fidelity, peak contrast,
seconds per design, and the ratio of its time to the reference setup's.
Then the synthetic array cases of issue 57 (45 mm pitch, 3 x 3 locations at 10 mm, n = 4096,
min_fidelity 0.95, location 5): 4, 8, 16 and 32 actuators x 9 points, each timed (CPU seconds of
this process) in the same run as the reference setup's design at n = 4096 and printed as a ratio to it, with the variables, the
peak constraints and any size limit the design named (``MinimaxReport.size_limit``).

``--layouts``: issue 57's layouts on the simulated ``nominal`` arm (seed 41; the far layout
seeds 5 and 17 at 1.3 kHz, n = 1024), ``render("minimax", ...)`` and ``render("inverse", ...)``
with their defaults at n = 16384, each minimax time (CPU seconds of this process: the machine
may be shared) printed as a ratio to the reference setup's minimax design in the same run;
32 actuators as a 4 x 8 grid at 45 mm over the 3 x 3 locations (one default support from the
latest arrival would exceed ``MAX_VARIABLES``: per-actuator supports, the weak actuators' pulses
spaced wider within ``SPREAD_VARIABLES``; the notes say so, and when a design is over its drive
budget). Each design is timed ``REPEATS`` times in a row and the least CPU time is kept: on a
shared virtual machine one design's CPU time varied by up to 2x between runs with the same
solver steps, and the least is the one nearest the work done.

Usage: python benchmarks/bench_minimax.py [n_samples]   (needs the test extra: cvxpy, Clarabel)
       python benchmarks/bench_minimax.py --arrays      (the synthetic array cases only)
       python benchmarks/bench_minimax.py --layouts [--write] [NAME ...]   (the simulated arm's layouts only;
                                        --write: the table into docs/performance.md, between its markers)
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


def arrays(n: int = 4096) -> None:
    """The issue's synthetic cases: actuators x 9 points, times as ratios to the reference's."""
    warnings.simplefilter("ignore", UserWarning)

    def one(layout: ArrayLayout) -> tuple[float, object]:
        H = medium(layout, n)
        targets = np.zeros((layout.n_points, n))
        targets[layout.location_index(5)] = 2e-6 * ricker(FS, 1e-3, n / FS, n / FS / 2)
        t = time.process_time()  # CPU seconds of this process: the machine may be shared
        try:
            _, rep = minimax_filter(H, targets, FS, band=BAND, min_fidelity=0.95, full_output=True)
        except Exception as exc:  # noqa: BLE001 - a refusal is a result here
            return time.process_time() - t, exc
        return time.process_time() - t, rep

    ref_s, rep = one(ArrayLayout.reference())
    print(f"reference setup 13 x 4, n={n}, defaults: {ref_s:.1f} s")
    for shape in ((2, 2), (2, 4), (4, 4), (4, 8)):
        layout = ArrayLayout.grid(shape, 0.045, (3, 3), 0.01)
        s, rep = one(layout)
        what = (f"refused: {rep}" if isinstance(rep, Exception) else
                f"{rep.n_variables} variables, {rep.n_constraints} peak constraints, {rep.iterations} rounds, "
                f"{rep.peak_contrast_db:.1f} dB at fidelity {rep.fidelity:.3f}, "
                f"size limit: {getattr(rep, 'size_limit', None) or 'none'}")
        print(f"{layout.n_actuators:>2} x {layout.n_points}: {s:7.1f} s  ratio {s / ref_s:5.2f}x  {what}")


#: Issue 57's layouts: (layout, seed, fs, n, locations).
LAYOUTS = {
    "reference 2x2 at 45 mm": (ArrayLayout.reference(), 41, FS, 16384, (5,)),
    "2x2 at 60 mm": (ArrayLayout.grid((2, 2), 0.06, (3, 3), 0.01, guard_offset_m=9e-3), 41, FS, 16384, (5, 3)),
    "line of 4 at 30 mm": (ArrayLayout.grid((4, 1), 0.03, (3, 3), 0.01), 41, FS, 16384, (4, 1)),
    "2x3 sleeve": (ArrayLayout.grid((2, 3), 0.045, (3, 3), 0.01, guard_offset_m=9e-3), 41, FS, 16384, (5, 1)),
    "2x2 at 45 mm, targets outside the hull": (ArrayLayout.grid((2, 2), 0.045, (3, 3), 0.03, guard_offset_m=9e-3),
                                               41, FS, 16384, (5, 1)),
    "32 actuators, 4x8 at 45 mm": (ArrayLayout.grid((4, 8), 0.045, (3, 3), 0.01), 41, FS, 16384, (5,)),
    "far layout, seed 5": (ArrayLayout.grid((2, 2), (0.14, 0.20), (3, 3), 0.02), 5, 1300.0, 1024, (5,)),
    "far layout, seed 17": (ArrayLayout.grid((2, 2), (0.14, 0.20), (3, 3), 0.02), 17, 1300.0, 1024, (5,)),
}


#: Times each design of ``--layouts`` is timed; the least CPU time is kept.
REPEATS = 3


def _least_cpu_s(job, repeats: int = REPEATS):
    """``job()``'s result and its least CPU time (s of this process) over ``repeats`` runs."""
    best, out = np.inf, None
    for _ in range(repeats):
        t = time.process_time()
        out = job()
        best = min(best, time.process_time() - t)
    return out, best


def layouts(only: list[str] | None = None, write: bool = False) -> None:
    """Issue 57's layouts: minimax and inverse CPU seconds per design, minimax as a ratio to
    the reference setup's in the same run; ``write``: the table also goes between the
    ``minimax-layouts`` markers of docs/performance.md."""
    from vibrofocus.rendering import render
    from vibrofocus.rigs import SimulatedForearm

    warnings.simplefilter("ignore", UserWarning)
    lines = ["| layout, location | minimax s | ratio to reference | inverse s | minimax peak contrast dB | notes |",
             "|---|---|---|---|---|---|"]
    print(*lines, sep="\n")
    ref_s = None
    for name, (layout, seed, fs, n, locations) in LAYOUTS.items():
        if only and name not in only and name != next(iter(LAYOUTS)):
            continue
        extra, band = ({}, {}) if fs >= 2 * BAND[1] else ({"noise_band": (10.0, 500.0)}, {"band": (10.0, 500.0)})
        tm = SimulatedForearm(seed=seed, skin="nominal", layout=layout, fs=fs, **extra).transfer_matrix(n)
        for loc in locations:
            _, inv_s = _least_cpu_s(lambda: render("inverse", tm, fs, layout, loc, **band))
            with warnings.catch_warnings(record=True) as said:
                warnings.simplefilter("always", UserWarning)
                d, mm_s = _least_cpu_s(lambda: render("minimax", tm, fs, layout, loc, **band))
            ref_s = mm_s if ref_s is None else ref_s
            y = d.predicted
            quiet = np.delete(np.arange(y.shape[0]), d.target_index)
            db = 20 * np.log10(np.abs(y[d.target_index]).max() / np.abs(y[quiet]).max())
            text = " ".join(str(w.message) for w in said)
            notes = "; ".join(what for key, what in (("was shortened", "support shortened by MAX_VARIABLES"),
                                                     ("per-actuator supports", "per-actuator supports"),
                                                     ("SPREAD_VARIABLES", "weak actuators' pulses spaced wider"),
                                                     ("drive budget", "over the drive budget"))
                              if key in text) or "—"
            lines.append(f"| {name}, {loc} | {mm_s:.1f} | {mm_s / ref_s:.2f}x | {inv_s:.2f} | {db:.1f} | {notes} |")
            print(lines[-1], flush=True)
    if write:
        from pathlib import Path

        from vibrofocus_tools.markers import write_between_markers

        write_between_markers(Path(__file__).resolve().parents[1] / "docs" / "performance.md", "minimax-layouts",
                              "\n".join("  " + line for line in lines))  # inside the page's list item


def main() -> None:
    if sys.argv[1:] == ["--arrays"]:
        arrays()
        return
    if sys.argv[1:2] == ["--layouts"]:
        names = [a for a in sys.argv[2:] if a != "--write"]
        layouts(names, write="--write" in sys.argv[2:])
        return
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
    ref_s = time.perf_counter() - t
    print(f"minimax_filter at n={n_ref}: {ref_s:.1f} s ({rep.iterations} rounds, "
          f"{rep.n_constraints} peak constraints)")
    long_response(ref_s)


def long_response(ref_s: float) -> None:
    """minimax_filter with its defaults on a simulated arm whose exciters sit 9-15 cm away."""
    from vibrofocus.rendering import inverse_filter, predict_response
    from vibrofocus.rendering.metrics import zero_lag_fidelity
    from vibrofocus.rigs import SimulatedForearm

    fs, n, band = 1300.0, 1024, (10.0, 500.0)
    layout = ArrayLayout.grid((2, 2), (0.14, 0.20), (3, 3), 0.02, name="far exciters")
    H = np.asarray(SimulatedForearm(seed=1, layout=layout, fs=fs, noise_band=band).transfer_matrix(n).H)
    ti = layout.location_index(5)
    targets = np.zeros((layout.n_points, n))
    targets[ti] = 2e-6 * ricker(fs, 1e-3, n / fs, n / fs / 2)
    quiet = np.delete(np.arange(layout.n_points), ti)
    y = predict_response(H, inverse_filter(H, targets, fs, band=band, check_wraparound=False))
    t = time.perf_counter()
    _, rep = minimax_filter(H, targets, fs, band=band, min_fidelity=0.95, full_output=True)
    long_s = time.perf_counter() - t
    pinv_db = 20 * np.log10(np.abs(y[ti]).max() / np.abs(y[quiet]).max())
    before = (int(np.argmax(np.abs(rep.desired))) - rep.support[0]) / fs
    print(f"long responses: {layout.n_points} x 4, exciters 9-15 cm away, n={n}, fs={fs:g} Hz, band {band} Hz, "
          f"default support {before:.3f} s before the tap")
    print(f"pseudo-inverse: fidelity {zero_lag_fidelity(y[ti], rep.desired):.3f}, peak contrast {pinv_db:.2f} dB")
    print(f"minimax_filter: {long_s:.1f} s ({rep.iterations} rounds, {rep.n_variables} variables), fidelity "
          f"{rep.fidelity:.3f}, peak contrast {rep.peak_contrast_db:.2f} dB ({rep.peak_contrast_db - pinv_db:+.2f} dB)")
    print(f"ratio long responses / reference setup (n=8192): {long_s / ref_s:.2f}x")


if __name__ == "__main__":
    main()
