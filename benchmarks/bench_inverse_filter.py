"""Speed of the default inverse-filter design against a naive per-frequency loop (docs/performance.md).

Prints, from one run, for the reference setup and a dense sleeve, every row of issue 18's
table:

- a Python loop of ``numpy.linalg.pinv`` at every active frequency (the naive design);
- ``inverse_filter`` without the wrap-around check (the solve), same result to 1e-9
  relative (asserted);
- the default path, ``inverse_filter`` with its wrap-around check (one shot: the check
  transforms every path's impulse response), same result (asserted);
- ``inverse_filter`` with a kept ``WraparoundCheck`` (``wraparound=``), the path for
  repeated designs through one ``H``, same drives (asserted);
- the check alone: one shot, and through a cached ``WraparoundCheck`` (what an
  ``InverseOperator`` or a ``Calibration`` keeps), with its one-time cost, against the
  former playback check (same fraction, asserted);
- ``InverseOperator`` retargeting against one inverse FFT of the drives;
- the contrast designs (``contrast_drives``, ``constrained_drives``) against a
  per-frequency ``scipy.linalg.eigh`` loop on the same medium, same drives to 1e-9
  (asserted);
- the peak memory of the sleeve design (a fresh subprocess, numpy's buffers traced).

Run: ``python benchmarks/bench_inverse_filter.py [--repeats 5]``. Timings are the best of
``repeats`` runs (of more where those take under half a second in all); every ratio
compares timings of this one run on this one machine.
"""

from __future__ import annotations

import argparse
import resource
import subprocess
import sys
import time
import tracemalloc

import numpy as np
from threadpoolctl import threadpool_limits

from bench_contrast import loop_acc
from vibrofocus import ricker
from vibrofocus.rendering import InverseOperator, inverse_filter
from vibrofocus.rendering import WraparoundCheck, band_taper, constrained_drives, contrast_drives
from vibrofocus.rendering.causality import _playback_wraparound_fraction

FS = 10_000.0
BAND = (10.0, 1000.0)
SIZES = {"reference": (4096, 13, 4), "sleeve": (8192, 256, 32)}


#: Short calls are repeated until they have run this long in all (a few runs of a
#: millisecond call mostly measure the machine's noise).
MIN_TOTAL_S = 0.5


def best_of(repeats: int, fn, *args, **kwargs) -> tuple[float, object]:
    """Best wall time of ``repeats`` runs, or of as many as fill MIN_TOTAL_S."""
    best, result, runs, spent = np.inf, None, 0, 0.0
    while runs < repeats or spent < MIN_TOTAL_S:
        start = time.perf_counter()
        result = fn(*args, **kwargs)
        elapsed = time.perf_counter() - start
        best, runs, spent = min(best, elapsed), runs + 1, spent + elapsed
    return best, result


def naive_design(H: np.ndarray, targets: np.ndarray) -> np.ndarray:
    """The per-frequency loop a first implementation would write (skipping, like the
    batched design, the frequencies where the band taper is zero)."""
    n = targets.shape[1]
    taper = band_taper(np.fft.rfftfreq(n, 1 / FS), BAND)
    spectra_in = np.fft.rfft(targets, axis=-1)
    spectra = np.zeros((H.shape[0], H.shape[2]), complex)
    for k in np.flatnonzero(taper > 0):
        spectra[k] = taper[k] * (np.linalg.pinv(H[k]) @ spectra_in[:, k])
    return np.fft.irfft(spectra, n, axis=0).T


def medium(rng: np.random.Generator, n: int, n_points: int, n_actuators: int) -> np.ndarray:
    """Random, decaying multipath medium: 8 arrivals per path with random delays and gains."""
    freqs = np.fft.rfftfreq(n, 1 / FS)
    H = np.zeros((len(freqs), n_points, n_actuators), complex)
    for _ in range(8):  # a loop over arrivals, not frequencies
        delay = rng.uniform(0.001, 0.02, (n_points, n_actuators))
        gain = rng.standard_normal((n_points, n_actuators)) * 1e-6
        H += gain * np.exp(-2j * np.pi * freqs[:, None, None] * delay)
    return H


def case(n: int, n_points: int, n_actuators: int, seed: int = 9) -> tuple[np.ndarray, np.ndarray]:
    H = medium(np.random.default_rng(seed), n, n_points, n_actuators)
    targets = np.zeros((n_points, n))
    targets[0] = 2e-6 * ricker(FS, duration=n / FS)
    return H, targets


def row(label: str, seconds: float, note: str = "") -> None:
    print(f"  {label:<44} {seconds * 1e3:9.2f} ms   {note}")


def compare(label: str, n: int, n_points: int, n_actuators: int, repeats: int) -> None:
    H, targets = case(n, n_points, n_actuators)
    print(f"{label}: {n} samples, {n_points} points x {n_actuators} actuators")
    t_naive, naive = best_of(max(1, repeats // 2), naive_design, H, targets)
    t_solve, fast = best_of(repeats, inverse_filter, H, targets, FS, check_wraparound=False)
    t_default, default = best_of(repeats, inverse_filter, H, targets, FS)
    error = max(np.max(np.abs(d - naive)) / np.max(np.abs(naive)) for d in (fast, default))
    assert error < 1e-9, f"batched and naive designs differ by {error:.2e} relative"
    t_one_shot, fraction = best_of(repeats, WraparoundCheck(H, keep=False).fraction, fast)
    t_old, old_fraction = best_of(1, _playback_wraparound_fraction, fast, H)
    assert abs(fraction - old_fraction) <= 1e-4 * old_fraction + 1e-9, (fraction, old_fraction)
    cached = WraparoundCheck(H)
    start = time.perf_counter()
    cached.padded_spectra  # built on first use, then kept: timed once
    t_build = time.perf_counter() - start
    t_cached, cached_fraction = best_of(repeats, cached.check, fast)
    assert abs(cached_fraction - old_fraction) <= 1e-4 * old_fraction + 1e-9, (cached_fraction, old_fraction)
    t_kept, kept = best_of(repeats, inverse_filter, H, targets, FS, wraparound=cached)
    assert np.array_equal(kept, default)
    row("naive per-frequency numpy.linalg.pinv loop", t_naive)
    row("inverse_filter solve (check_wraparound=False)", t_solve,
        f"{t_naive / t_solve:5.1f}x naive (max rel. diff {error:.1e})")
    row("default path: inverse_filter + one-shot check", t_default,
        f"{t_naive / t_default:5.1f}x naive, check +{(t_default - t_solve) / t_solve:.0%} of the solve")
    row("inverse_filter(wraparound=WraparoundCheck(H))", t_kept,
        f"{t_naive / t_kept:5.1f}x naive (the check's spectra kept across designs)")
    row("  check one shot (wraparound_fraction)", t_one_shot, f"{t_one_shot / t_solve:.0%} of the solve")
    row("  check, cached spectra (per design)", t_cached, f"{t_cached / t_solve:.0%} of the solve")
    row("  the cache, once per transfer matrix", t_build)
    row("  former playback check", t_old, f"fraction {fraction:.4g} (cached {cached_fraction:.4g}, former {old_fraction:.4g})")

    control = np.arange(min(n_points, n_actuators + 1))
    t_build_op, op = best_of(1, InverseOperator, H, FS, control=control)
    waveform = 2e-6 * ricker(FS, duration=n / FS, t0=0.6 * n / FS)
    t_retarget, drives = best_of(max(repeats, 20), op.drives_for_point, int(control[-1]), waveform)
    spectra = np.fft.rfft(drives, axis=-1)  # (n_actuators, n // 2 + 1)
    t_irfft, _ = best_of(max(repeats, 20), np.fft.irfft, spectra, n, axis=-1)
    op.check_wraparound(drives)  # builds and keeps the operator's check
    t_op_check, _ = best_of(repeats, op.check_wraparound, drives)
    row(f"InverseOperator ({len(control)} control points) build", t_build_op)
    row("  retarget (drives_for_point)", t_retarget,
        f"{t_retarget / t_irfft:.1f}x one irfft of the drives ({t_irfft * 1e3:.3f} ms)")
    row("  operator.check_wraparound (cached)", t_op_check)

    quiet = np.arange(1, n_points)
    t_loop, looped = best_of(1, loop_acc, H, 0, quiet, n, 1e-3)
    t_acc, acc = best_of(repeats, contrast_drives, H, 0, FS, quiet_indices=quiet)
    t_con, con = best_of(repeats, constrained_drives, H, 0, FS, quiet_indices=quiet, contrast_weight=0.0)
    error = max(np.max(np.abs(d - looped)) / np.max(np.abs(looped)) for d in (acc, con))
    assert error < 1e-9, f"batched and looped contrast designs differ by {error:.2e} relative"
    _, goal = constrained_drives(H, 0, FS, quiet_indices=quiet, contrast_weight=1.0, full_output=True)
    t_search, _ = best_of(repeats, constrained_drives, H, 0, FS, quiet_indices=quiet,
                          min_contrast_db=goal["energy_contrast_db"])
    row("naive per-frequency scipy.linalg.eigh ACC loop", t_loop)
    row("  contrast_drives (ACC)", t_acc, f"{t_loop / t_acc:5.1f}x the loop (max rel. diff {error:.1e})")
    row("  constrained_drives (contrast_weight)", t_con, f"{t_loop / t_con:5.1f}x the loop")
    row("  constrained_drives (min_contrast_db search)", t_search, f"{t_loop / t_search:5.1f}x the loop")


def peak_memory(size: str) -> None:
    """Run one default design of ``size`` in this script's --memory mode, in a fresh process."""
    out = subprocess.run([sys.executable, __file__, "--memory", size], capture_output=True, text=True, check=True)
    print(out.stdout.strip())


def measure_memory(size: str) -> None:
    n, n_points, n_actuators = SIZES[size]
    H, targets = case(n, n_points, n_actuators)
    inputs = H.nbytes + targets.nbytes
    tracemalloc.start()  # numpy reports its buffers to tracemalloc
    with threadpool_limits(limits=1, user_api="blas"):
        inverse_filter(H, targets, FS)
        _, design = tracemalloc.get_traced_memory()
        tracemalloc.reset_peak()
        op = InverseOperator(H, FS, control=np.arange(n_actuators + 1))
        drives = op.drives_for_point(0, targets[0])
        op.check_wraparound(drives)
        _, cached = tracemalloc.get_traced_memory()
    print(f"peak memory, {size}: default design (inverse_filter + check) {(inputs + design) / 2**30:.2f} GiB "
          f"(inputs {inputs / 2**30:.2f} GiB + {design / 2**30:.2f} GiB working); InverseOperator + cached check "
          f"{(inputs + cached) / 2**30:.2f} GiB; process peak (ru_maxrss, includes building the medium) "
          f"{resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20:.2f} GiB")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--blas-threads", type=int, default=1,
                        help="BLAS threads for both sides (default 1: compares batching, not threading)")
    parser.add_argument("--memory", choices=sorted(SIZES), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.memory:
        measure_memory(args.memory)
        return
    with threadpool_limits(limits=args.blas_threads, user_api="blas"):
        print(f"BLAS threads: {args.blas_threads} for both the naive loop and the batched design")
        compare("reference setup", *SIZES["reference"], args.repeats)
        compare("dense sleeve", *SIZES["sleeve"], args.repeats)
    peak_memory("sleeve")


if __name__ == "__main__":
    main()
