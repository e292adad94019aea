"""Speed of the batched inverse-filter design against a naive per-frequency loop (SPEC §9).

Prints, from one run:

- inverse_filter (batched over frequencies) against a Python loop of
  ``numpy.linalg.pinv`` at every active frequency, same inputs, same result to 1e-9
  relative (asserted), for the reference setup and a dense sleeve;
- the retargeting cost of a precomputed InverseOperator (new focus point and waveform)
  against one inverse FFT of the drives.

Run: ``python benchmarks/bench_inverse_filter.py [--repeats 3]``. Timings are the best of
``repeats`` runs; both sides run on the same machine in the same process.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from threadpoolctl import threadpool_limits

from vibrofocus import InverseOperator, inverse_filter, ricker
from vibrofocus.rendering import band_taper

FS = 10_000.0
BAND = (10.0, 1000.0)


def best_of(repeats: int, fn, *args, **kwargs) -> tuple[float, object]:
    best, result = np.inf, None
    for _ in range(repeats):
        start = time.perf_counter()
        result = fn(*args, **kwargs)
        best = min(best, time.perf_counter() - start)
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


def compare(label: str, n: int, n_points: int, n_actuators: int, repeats: int, rng: np.random.Generator) -> None:
    H = medium(rng, n, n_points, n_actuators)
    targets = np.zeros((n_points, n))
    targets[0] = 2e-6 * ricker(FS, duration=n / FS)
    t_fast, fast = best_of(repeats, inverse_filter, H, targets, FS, check_wraparound=False)
    t_check, _ = best_of(1, inverse_filter, H, targets, FS, check_wraparound="warn")
    t_naive, naive = best_of(max(1, repeats - 1), naive_design, H, targets)
    error = np.max(np.abs(fast - naive)) / np.max(np.abs(naive))
    assert error < 1e-9, f"batched and naive designs differ by {error:.2e} relative"
    print(f"{label}: {n} samples, {n_points} points x {n_actuators} actuators")
    print(f"  naive pinv loop   {t_naive * 1e3:9.1f} ms")
    print(f"  inverse_filter    {t_fast * 1e3:9.1f} ms   speed-up {t_naive / t_fast:5.1f}x   (max rel. diff {error:.1e})")
    print(f"  + wrap-around check {t_check * 1e3:7.1f} ms (linear-convolution playback at every point)")

    control = np.arange(min(n_points, n_actuators + 1))
    t_build, op = best_of(1, InverseOperator, H, FS, control=control)
    waveform = 2e-6 * ricker(FS, duration=n / FS, t0=0.6 * n / FS)
    t_retarget, drives = best_of(max(repeats, 20), op.drives_for_point, int(control[-1]), waveform)
    spectra = np.fft.rfft(drives, axis=-1)  # (n_actuators, n // 2 + 1)
    t_irfft, _ = best_of(max(repeats, 20), np.fft.irfft, spectra, n, axis=-1)
    print(f"  InverseOperator ({len(control)} control points): build {t_build * 1e3:.1f} ms, "
          f"retarget {t_retarget * 1e3:.3f} ms = {t_retarget / t_irfft:.1f} x one irfft of the drives "
          f"({t_irfft * 1e3:.3f} ms)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--blas-threads", type=int, default=1,
                        help="BLAS threads for both sides (default 1: compares batching, not threading)")
    args = parser.parse_args()
    rng = np.random.default_rng(9)
    with threadpool_limits(limits=args.blas_threads, user_api="blas"):
        print(f"BLAS threads: {args.blas_threads} for both the naive loop and the batched design")
        compare("reference setup", 4096, 13, 4, args.repeats, rng)
        compare("dense sleeve", 8192, 256, 32, args.repeats, rng)


if __name__ == "__main__":
    main()
