"""The peak-contrast (minimax) design of SPEC §2: :func:`minimax_filter`.

The drives minimize the largest ``|displacement|`` at the quiet points over the whole window,
subject to the target's fidelity (zero-lag correlation with the band-limited desired
waveform) being at least ``min_fidelity`` and, when asked, the drive's peak being at most
``max_drive``: a second-order cone program.

Structure used for speed:

* **Reduced basis.** Each drive is a sum of band-limited pulses (the band taper's impulse
  response) on a grid of every ``decimation``-th sample inside a support around the tap:
  every drive is band-limited by construction, and the program has a few hundred
  coefficients per actuator instead of ``n`` samples.
* **Exact target norm.** The target's energy is a quadratic form whose Gram matrix is
  Toeplitz in the pulse delays: it comes from one cross-correlation (FFT) per actuator
  pair, so the fidelity constraint holds over the whole window without listing its samples.
* **Constraint generation.** The peak constraints start at the samples where the
  pseudo-inverse's quiet response peaks (the warm start) and on a coarse grid; after each
  solve, the full response (FFT) adds the samples that exceed the current peak, until
  none does.

Notation: ``g_pa`` is the band-limited impulse response from actuator ``a`` to point ``p``
(``irfft(T H_pa)``, the whole circular window of ``n`` taps: no truncation inside the
window); the response to the pulse at delay ``t_k`` is ``g_pa`` shifted by ``t_k``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .._validation import as_array, check_in_range, check_positive
from ..defaults import BAND_HZ
from ..errors import ValidationError
from ._checks import as_indices, as_transfer, check_grid
from .inverse import _prepare_design, predict_response

__all__ = ["minimax_filter", "MinimaxReport", "MINIMAX_EXTRA"]

#: The pip extra that installs the convex solver (cvxpy with Clarabel).
MINIMAX_EXTRA = "vibrofocus[minimax]"
_VERBOSE = False


@dataclass(frozen=True)
class MinimaxReport:
    """What :func:`minimax_filter` did, returned with ``full_output=True``.

    Attributes
    ----------
    predicted : ndarray, shape (n_points, n)
        Response at every point of ``H`` to the returned drives (through the whole ``H``,
        circular; the drives sit mid-window so that it equals linear playback when the
        responses end inside the window), unit of ``targets``.
    desired : ndarray, shape (n,)
        The band-limited target waveform the fidelity compares with.
    target_index : int
    quiet : ndarray of int
        Points whose peak was minimized.
    fidelity : float
        Zero-lag correlation of ``predicted[target_index]`` with ``desired``.
    peak_contrast_db : float
        ``20 log10`` of the target's peak over the largest quiet peak, dB.
    quiet_peak : float
        Largest ``|predicted|`` at the quiet points.
    model_quiet_peak : float
        The same in the program's own model (its optimum, rescaled); differs from
        ``quiet_peak`` by at most the constraint-generation tolerance.
    peak_drive : float
        Peak ``|drives|``.
    status : str
        The solver's status of the last solve (``"optimal"`` when solved).
    solver : str
    iterations : int
        Constraint-generation rounds.
    n_constraints : int
        Peak constraints in the last program.
    n_variables : int
        Drive coefficients.
    ir_taps : int
        Taps of the band-limited impulse responses over which the first peak constraints
        are listed (after the drives' support).
    ir_energy_left_out : float
        Share of those responses' energy past ``ir_taps`` (checked afterwards: any sample
        found over the peak there joins the program).
    ir_tail_energy : float
        Share of the impulse responses' energy in the window's last eighth.
    support : (int, int)
        First and last sample the drive pulses are centred on.
    decimation : int
        Spacing of the pulses, samples.
    """

    predicted: np.ndarray
    desired: np.ndarray
    target_index: int
    quiet: np.ndarray
    fidelity: float
    peak_contrast_db: float
    quiet_peak: float
    model_quiet_peak: float
    peak_drive: float
    status: str
    solver: str
    iterations: int
    n_constraints: int
    n_variables: int
    ir_taps: int
    ir_energy_left_out: float
    ir_tail_energy: float
    support: tuple[int, int]
    decimation: int


def _cvxpy():
    try:
        import cvxpy as cp
    except ImportError:  # pragma: no cover - exercised only without the extra
        raise ImportError(f"minimax_filter needs cvxpy and Clarabel: pip install '{MINIMAX_EXTRA}'") from None
    return cp


def _local_peaks(y: np.ndarray, floor: float, limit: int) -> np.ndarray:
    """Indices of the local maxima of ``|y|`` (1-D) above ``floor``, largest first, at most ``limit``."""
    a = np.abs(y)
    left = np.roll(a, 1)
    right = np.roll(a, -1)
    idx = np.flatnonzero((a >= left) & (a >= right) & (a > floor))
    return idx[np.argsort(a[idx])[::-1][:limit]]


def minimax_filter(
    H: Any,
    targets: Any,
    fs: float,
    *,
    band: tuple[float, float] = BAND_HZ,
    min_fidelity: float = 0.95,
    max_drive: float | None = None,
    quiet: Any = None,
    full_output: bool = False,
    taper_octaves: float = 0.5,
    support_s: tuple[float, float] = (0.01, 0.005),
    stride: int = 8,
    ir_energy_tol: float = 1e-4,
    decimation: int | None = None,
    tol: float = 1e-3,
    fidelity_margin: float = 1e-3,
    max_iter: int = 30,
    solver: str = "CLARABEL",
) -> np.ndarray | tuple[np.ndarray, MinimaxReport]:
    """Peak-contrast (minimax) drives: the least largest quiet-point ``|displacement|`` at
    a given target fidelity (SPEC §2, §8).

    Parameters
    ----------
    H : ndarray, complex, shape (n // 2 + 1, n_points, n_actuators)
        Transfer matrix on ``numpy.fft.rfftfreq(n, 1 / fs)`` (m/V, or any unit pair).
    targets : ndarray, real, shape (n_points, n)
        One non-zero row: the target's desired displacement (unit of ``H``'s output, m);
        it is band-limited with the design's taper before use. The tap should sit far
        enough from the window's ends for ``support_s``.
    fs : float
        Sample rate, Hz.
    band : (float, float)
        Design band, Hz; every drive is band-limited to it (raised-cosine taper of
        ``taper_octaves``).
    min_fidelity : float
        Least zero-lag correlation of the target's response with the band-limited
        waveform, in (0, 1). The target's response is held at the waveform's amplitude
        (its projection on the waveform equals the waveform).
    max_drive : float, optional
        Drive limit, unit of the drives (V): a constraint of the program (the design may
        then be infeasible: :class:`~vibrofocus.errors.ValidationError`). ``None``: none.
    quiet : sequence of int, optional
        Rows of ``H`` whose peak is minimized; default every row but the target.
    full_output : bool
        Also return a :class:`MinimaxReport` (predicted field, metrics, solver status,
        the truncation used).
    taper_octaves : float
        Taper roll-off outside each band edge, octaves.
    support_s : (float, float)
        The drives' support before and after the tap's peak, s: causal drives played once
        from silence, starting at most ``support_s[0]`` before the tap.
    decimation : int, optional
        Spacing of the drive pulses, samples; default the largest that keeps the taper's
        upper edge below the pulses' Nyquist frequency.
    stride : int
        Spacing of the first peak constraints, samples (later rounds add the samples found
        over the peak).
    ir_energy_tol : float
        The first peak constraints cover the samples where the pulses' responses hold all
        but this share of their energy (the truncation, reported as ``ir_taps`` and
        ``ir_energy_left_out``); samples past it join when found over the peak.
    tol : float
        Constraint-generation tolerance: the returned quiet peak exceeds the program's
        by at most this share.
    fidelity_margin : float
        The program asks ``min_fidelity + fidelity_margin`` (at most ``(1 + min_fidelity) / 2``):
        room for what the drive pulses' band-limited tails, cut at the window, take off the
        played response.
    max_iter : int
        Most constraint-generation rounds.
    solver : str
        cvxpy solver name (default Clarabel).

    Returns
    -------
    drives : ndarray, real, shape (n_actuators, n)
        Unit of ``H``'s input (V).
    report : MinimaxReport
        Only with ``full_output=True``.

    Notes
    -----
    The program's rows use the band-limited impulse responses over the whole circular
    window; its first peak constraints stop ``ir_taps`` after the drives' support (energy
    left out: ``ir_energy_left_out``), and every later round checks the full response
    through the whole ``H``, which is also what ``predicted`` is: the truncation's error is
    in the prediction, and bounded by ``tol`` in the peak.
    Needs the optional extra ``vibrofocus[minimax]`` (cvxpy, Clarabel).
    """
    cp = _cvxpy()
    H = as_transfer(H)
    targets = as_array(targets, "targets", ndim=2)
    n = targets.shape[1]
    check_grid(H.shape[0], n, "targets (n_points, n)")
    if targets.shape[0] != H.shape[1]:
        raise ValidationError(f"targets has {targets.shape[0]} rows but H has {H.shape[1]} points")
    rows = np.flatnonzero(np.any(targets != 0, axis=1))
    if rows.size != 1:
        raise ValidationError(f"targets must have exactly one non-zero row (the target), got {rows.size}")
    ti = int(rows[0])
    min_fidelity = check_in_range(min_fidelity, "min_fidelity", 0.0, 1.0, inclusive=False)
    if max_drive is not None:
        max_drive = check_positive(max_drive, "max_drive")
    tol = check_positive(tol, "tol")
    n_pts, n_act = H.shape[1], H.shape[2]
    quiet_idx = np.delete(np.arange(n_pts), ti) if quiet is None else as_indices(quiet, "quiet", n_pts)
    quiet_idx = quiet_idx[quiet_idx != ti]
    if quiet_idx.size == 0:
        raise ValidationError("minimax_filter needs at least one quiet point besides the target")
    H, fs, n, band, taper, freqs, active = _prepare_design(H, fs, n, band, taper_octaves)
    top = freqs[active][-1]
    if decimation is None:
        decimation = max(1, int(np.floor(fs / (2 * top) * 0.999)))
    elif int(decimation) < 1 or fs / (2 * int(decimation)) < top:
        raise ValidationError(f"decimation={decimation} puts the pulses' Nyquist below the taper's edge {top:g} Hz")
    r = int(decimation)

    desired = np.fft.irfft(np.fft.rfft(targets[ti]) * taper, n)
    d_norm = float(np.linalg.norm(desired))
    if d_norm == 0:
        raise ValidationError("the target's waveform has no energy inside the band")
    t_peak = int(np.argmax(np.abs(desired)))
    pre, post = (int(round(float(s) * fs)) for s in support_s)
    first, last = max(0, t_peak - pre), min(n - 1, t_peak + post)
    delays = np.arange(first, last + 1, r)
    K = delays.size

    # Band-limited impulse responses g[p, a, t] (pulse at t = 0), scaled to O(1).
    G = H * taper[:, None, None]
    g = np.fft.irfft(G, n, axis=0).transpose(1, 2, 0)  # (n_points, n_act, n)
    gscale = float(np.max(np.abs(g[ti]))) or 1.0
    g = g / gscale
    energy = np.sum(g**2, axis=-1)
    tail = float(np.sum(g[..., -n // 8:] ** 2) / np.sum(energy)) if np.sum(energy) > 0 else 0.0
    # The peak constraints list the samples where the pulses' responses carry all but
    # ir_energy_tol of their energy (the truncation), then add any sample found over.
    cum = np.cumsum(np.sum(g[:, :, : n // 2] ** 2, axis=(0, 1)))
    ir_taps = int(np.searchsorted(cum, (1 - ir_energy_tol) * np.sum(energy))) + 1
    ir_taps = min(ir_taps, n // 2)
    left_out = float(1 - cum[ir_taps - 1] / np.sum(energy))

    # Target: <y, d~> = b^T u and |y|^2 = u^T Q u (Q Toeplitz in the delays).
    dn = desired / d_norm
    Gt = np.fft.rfft(g[ti], axis=-1)  # (n_act, F)
    xc = np.fft.irfft(np.conj(Gt) * np.fft.rfft(dn)[None], n, axis=-1)  # sum_t g_a(t) d(t + tau)
    b = xc[:, delays % n].reshape(-1)
    C = np.fft.irfft(np.conj(Gt)[:, None] * Gt[None, :], n, axis=-1)  # C_ab(tau)
    lag = (delays[:, None] - delays[None, :]) % n  # t_k - t_l
    # Q[(a,k),(b,l)] = C_ab(t_k - t_l).
    Q = np.empty((n_act * K, n_act * K))
    for a in range(n_act):
        for bb in range(n_act):
            Q[a * K:(a + 1) * K, bb * K:(bb + 1) * K] = C[a, bb][lag]

    # Unit pulse train -> drive (the taper's impulse response at each delay).
    pulse = np.fft.irfft(taper, n)
    # Reduced basis: the pulses' Gram (Toeplitz, from the taper's autocorrelation) has about
    # 2 x bandwidth x support well-conditioned directions (the discrete prolate sequences
    # of the band); the drives are combinations of those, with unit energy each.
    acorr = np.fft.irfft(taper**2, n)
    wp, Vp = np.linalg.eigh(acorr[lag])
    kept = wp > wp[-1] * 1e-12
    basis = Vp[:, kept] / np.sqrt(wp[kept])  # (K, m)
    m = basis.shape[1]
    b = np.einsum("ak,km->am", b.reshape(n_act, K), basis).reshape(-1)
    Q = np.einsum("akbl,km,ln->ambn", Q.reshape(n_act, K, n_act, K), basis, basis).reshape(n_act * m, n_act * m)
    w, V = np.linalg.eigh(0.5 * (Q + Q.T))
    keep = w > w[-1] * 1e-12
    R = (np.sqrt(w[keep])[:, None] * V[:, keep].T)

    def drives_of(u: np.ndarray) -> np.ndarray:
        train = np.zeros((n_act, n))
        train[:, delays] = u.reshape(n_act, m) @ basis.T
        return np.fft.irfft(np.fft.rfft(train, axis=-1) * taper, n, axis=-1)

    def quiet_response(u: np.ndarray) -> np.ndarray:
        x = drives_of(u)
        return np.fft.irfft(np.einsum("fpa,af->pf", H[:, quiet_idx], np.fft.rfft(x, axis=-1)), n, axis=-1) / gscale

    def rows_of(pairs: np.ndarray) -> np.ndarray:
        """Rows of the peak constraints at (quiet j, sample t): the response there per coefficient."""
        p, t = quiet_idx[pairs[:, 0]], pairs[:, 1]
        lags = (t[:, None] - delays[None, :]) % n  # (N, K)
        rows = g[p[:, None, None], np.arange(n_act)[None, :, None], lags[:, None, :]]  # (N, n_act, K)
        return (rows @ basis).reshape(len(p), -1)

    # Warm start: the active set where the pseudo-inverse's quiet response peaks, and a coarse grid.
    from .inverse import inverse_filter

    pinv = inverse_filter(H, targets, fs, band=band, taper_octaves=taper_octaves, check_wraparound=False)
    spectra = np.fft.rfft(pinv, axis=-1)
    y0 = np.fft.irfft(np.einsum("fpa,af->pf", H[:, quiet_idx], spectra), n, axis=-1)
    pairs = set()
    grid = np.arange(max(0, first), min(n, last + ir_taps), int(stride))
    for j in range(len(quiet_idx)):
        for t in _local_peaks(y0[j], 0.3 * np.max(np.abs(y0[j])), 10):
            pairs.add((j, int(t)))
        for t in grid:
            pairs.add((j, int(t)))
    drive_rows: set[int] = set()
    if max_drive is not None:
        drive_rows.update(int(t) for t in np.arange(first, last + 1, 32))
    u_scale = d_norm / gscale  # drives = (u * u_scale) pulses

    asked = min(min_fidelity + check_positive(fidelity_margin, "fidelity_margin", allow_zero=True),
                (1 + min_fidelity) / 2)
    u = cp.Variable(n_act * m)
    s = cp.Variable()
    status, it, value = "not solved", 0, np.nan
    A_rows = np.zeros((0, n_act * m))
    listed = np.zeros((0, 2), int)
    for it in range(1, max_iter + 1):
        new = np.array(sorted(pairs - {tuple(x) for x in listed}), int).reshape(-1, 2)
        if new.size:
            A_rows = np.vstack([A_rows, rows_of(new)])
            listed = np.vstack([listed, new])
        cons = [b @ u == 1.0, cp.SOC(cp.Constant(1.0 / asked), R @ u), A_rows @ u <= s, -(A_rows @ u) <= s]
        if max_drive is not None and drive_rows:
            tr = np.array(sorted(drive_rows))
            P = np.stack([pulse[(t - delays) % n] for t in tr]) @ basis  # (n_rows, m)
            Pfull = np.kron(np.eye(n_act), P)
            cons += [Pfull @ u <= max_drive / u_scale, -(Pfull @ u) <= max_drive / u_scale]
        prob = cp.Problem(cp.Minimize(s), cons)
        for attempt in (solver, "SCS") if solver == "CLARABEL" else (solver,):
            opts = (dict(tol_gap_rel=1e-7, tol_gap_abs=1e-9, tol_feas=1e-7) if attempt == "CLARABEL" else
                    dict(eps_abs=1e-9, eps_rel=1e-9, max_iters=200_000) if attempt == "SCS" else {})
            try:  # a degenerate optimum (a quiet peak of 0) can stall Clarabel: SCS then
                prob.solve(solver=attempt, verbose=_VERBOSE, **opts)
                break
            except cp.error.SolverError as exc:
                error = exc
        else:
            raise ValidationError(f"the minimax program failed in {solver}: {error}") from None
        status = prob.status
        if status not in ("optimal", "optimal_inaccurate"):
            raise ValidationError(f"the minimax program is {status} (min_fidelity={min_fidelity:g}, "
                                  f"max_drive={max_drive}): relax the fidelity or the drive limit")
        value = float(s.value)
        uu = np.asarray(u.value, float)
        yq = quiet_response(uu)
        over = np.abs(yq) > value * (1 + tol)
        added = 0
        if over.any():
            for j in np.flatnonzero(over.any(axis=1)):
                for t in _local_peaks(yq[j], value * (1 + tol), 20):
                    pairs.add((int(j), int(t)))
                    added += 1
        if max_drive is not None:
            x = drives_of(uu) * u_scale
            bad = np.abs(x) > max_drive * (1 + tol)
            for a in np.flatnonzero(bad.any(axis=1)):
                for t in _local_peaks(x[a], max_drive * (1 + tol), 20):
                    if int(t) not in drive_rows:
                        drive_rows.add(int(t))
                        added += 1
        if added == 0:
            break
    drives = drives_of(uu) * u_scale
    predicted = predict_response(H, drives)
    if max_drive is not None:
        peak = float(np.max(np.abs(drives)))
        if peak > max_drive:  # within tol: trim to the limit exactly
            drives = drives * (max_drive / peak)
            predicted = predicted * (max_drive / peak)
    if not full_output:
        return drives
    yt = predicted[ti]
    fid = float(np.dot(yt, desired) / (np.linalg.norm(yt) * d_norm))
    qpeak = float(np.max(np.abs(predicted[quiet_idx])))
    tpeak = float(np.max(np.abs(yt)))
    report = MinimaxReport(
        predicted=predicted, desired=desired, target_index=ti, quiet=quiet_idx, fidelity=fid,
        peak_contrast_db=float(20 * np.log10(tpeak / qpeak)) if qpeak > 0 else float("inf"),
        quiet_peak=qpeak, model_quiet_peak=value * d_norm, peak_drive=float(np.max(np.abs(drives))),
        status=str(status), solver=solver, iterations=it, n_constraints=len(listed), n_variables=n_act * m,
        ir_taps=ir_taps, ir_energy_left_out=left_out, ir_tail_energy=tail, support=(int(delays[0]), int(delays[-1])),
        decimation=r)
    return drives, report
