"""The peak-contrast (minimax) design (docs/method.md, "Rendering methods"): :func:`minimax_filter`.

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
  solve, the full response (FFT) adds the samples that exceed the current peak (and, in a
  round with any, those within 30 % of it), until none does; rows far below the peak leave
  whenever the optimum sets a record. The first grid has at most 64 samples per point: the
  first program does not grow with the window.
* **Drive limit in one solve.** With ``max_drive``, a small program on the drive samples
  alone first finds the least peak drive that reaches the fidelity; a limit below it is
  refused naming that drive (or, ``on_max_drive="least"``, the design runs at twice it).
  Every drive sample the pulses reach is listed from the first round (a limit that binds
  does so over most of them), and a KKT solver that uses the rows' structure (a drive row
  touches one actuator's coefficients) solves those programs.
* **A cone solver called directly.** A few hundred coefficients and rows: CVXOPT's
  primal-dual cone solver takes the dense rows as they are (BLAS on one thread), about 20
  iterations per round, with no modelling layer to compile each round.

Notation: ``g_pa`` is the band-limited impulse response from actuator ``a`` to point ``p``
(``irfft(T H_pa)``, the whole circular window of ``n`` taps: no truncation inside the
window); the response to the pulse at delay ``t_k`` is ``g_pa`` shifted by ``t_k``.
"""

from __future__ import annotations

import inspect
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.interpolate import interp1d
from scipy.linalg import block_diag

from .._validation import as_array, check_in_range, check_positive
from ..defaults import BAND_HZ
from ..errors import InfeasibleDesignError, ValidationError
from ._checks import as_indices, as_transfer, check_grid
from ._pinv import _single_threaded_blas
from .inverse import _prepare_design, predict_response, scale_to_peak
from .metrics import zero_lag_fidelity
from .timing import DEFAULT_SUPPORT_S, response_timing

__all__ = ["minimax_filter", "minimax_frontier", "coherence_radius", "MinimaxReport", "MinimaxFrontier", "MINIMAX_EXTRA"]

#: The pip extra with cvxpy and Clarabel, for the reference formulation (tests, benchmark);
#: the design itself needs neither.
MINIMAX_EXTRA = "vibrofocus[minimax]"
#: Peak rows below this share of the optimum leave the program (when it sets a record).
_DROP = 0.5
#: How far below ``min_fidelity`` a design's fidelity may come out before it counts as a
#: failed solve. The window cuts the pulses' band-limited tails, and the demo's designs
#: (seed 2, at the pseudo-inverse's fidelity) come out up to 0.012 below what they asked;
#: their report says the fidelity reached. A miss beyond this is not a design.
_FIDELITY_SLACK = 0.05
#: Largest robust row radius accepted, relative to the target's peak response per unit
#: drive: beyond it the quiet points' uncertainty alone exceeds the tap 100 dB over (a
#: coherence radius at the coherence floor, 1e-6, gives about 2e4), and the cone solver
#: fails numerically after minutes.
_MAX_ROW_RADIUS = 1e5
#: Fewest constraint-generation rounds accepted: the first rounds only list the peaks the
#: warm start missed (the reference designs converge in about 10; 0 or 1 round returned
#: the unconstrained best-fidelity drives, 35 kV for a 1 um tap).
MIN_ITER = 5
#: Most design variables (drive pulses x actuators): the cone program is dense, so time
#: and memory grow with their cube and square. The default support uses about 200;
#: a support over the whole window (support_s=(100, 100)) asked for 5,000 and ran
#: 151 s at 4.3 GB.
MAX_VARIABLES = 1024
#: A norm bound, this many times the best-fidelity drives' norm, that lets the Cholesky
#: solver take a rank-deficient round (few rows); a round where it binds is solved again
#: without it.
_NORM_CAP = 1e6
#: Each round with a sample over the peak adds, at every quiet point, the local peaks above
#: this share of it (the rows about to bind, not only those over): fewer rounds.
_ADD_MARGIN = 0.7
#: Most steps of the cone solver with the structured KKT solver (a drive limit listed over
#: the support). Where the limit binds over many samples (the 32-actuator layout), the
#: steps stall at the optimum from about 30 on (objective within 1e-5 of the last, dual
#: residual stuck near 1e-3) until the KKT system turns singular, up to 69 steps later;
#: CVXOPT's own Cholesky stops "singular" at about 30 on the same programs. Either way the
#: round ends "unknown" at its last point (the design's status says so); the well-posed
#: rounds take 20-25 steps. At 36: 263 steps in all instead of 390 on the 32-actuator
#: layout, its peak contrast within 0.001 dB.
_STRUCTURED_MAXITERS = 36
#: Each round's cone program is solved to a relative duality gap of this share of ``tol``
#: (the rounds' own tolerance on the quiet peak), not to CVXOPT's default 1e-6: the last
#: steps to 1e-6 bought nothing the rounds use, and there the structured solver broke down
#: ("domain error": CVXOPT's own Cholesky then solved the round again) in 7 of 27 designs
#: on the reference, 60 mm and sleeve layouts, every location; with this and the
#: neighbouring rows of each round, in 1 of the 27 (2026-12-04). Its primal and dual
#: residuals too (not CVXOPT's 1e-7): the dual residual lagged the gap, so 11 of the 12
#: designs of ``bench_minimax.py --layouts`` ran on until the KKT system turned singular
#: and reported "inaccurate (unknown)" at their optimum; now they stop "optimal", as fast
#: or faster, the quiet peak within 2e-5 of the program's and the peak contrast within
#: 0.001 dB of before.
_ROUND_ACCURACY = 0.1
#: Most samples per quiet point on the first rounds' coarse grid (``stride`` apart, or wider).
_GRID_ROWS = 64
#: The first drive-limit rows cover the support widened by this many times the pulse's 1 %
#: half-width on each side (where the 2x3 sleeve's and the outside-hull designs' binding
#: samples lay: up to 2.3 times it), so that a limit binding over most of the support is
#: listed whole in the first round instead of some 20 samples a round.
_DRIVE_REACH = 3
#: Most design variables of a program with per-actuator supports (a default support that
#: one common support from the latest arrival would not fit in :data:`MAX_VARIABLES`): the
#: weak actuators (:data:`_WEAK_SHARE`) place their pulses further apart to stay within it.
SPREAD_VARIABLES = 384
#: An actuator whose band-limited energy at the target is under this share of the
#: strongest's is weak: with per-actuator supports, its pulses may be spaced further apart.
_WEAK_SHARE = 0.1
#: With ``on_max_drive="least"``, the design's drive limit over the least drive that reaches
#: the fidelity: at the least drive itself the drives are pinned by the fidelity and the
#: quiet peak cannot fall (1.3 dB against 5.3 dB at 1.02x on the reference medium).
_LEAST_DRIVE_ROOM = 2.0


#: minimax_filter's keywords that shape the program's set-up, and those of each solve
#: (the frontier takes both; their defaults are minimax_filter's own).
_SETUP_KEYS = ("taper_octaves", "support_s", "stride", "ir_energy_tol", "decimation", "h_radius")
_SOLVE_KEYS = ("tol", "fidelity_margin", "max_iter")


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
        ``quiet_peak`` by at most the constraint-generation tolerance. With ``h_radius``:
        the robust bound, the largest quiet ``|displacement|`` through any ``H`` within the
        radius (at least ``quiet_peak``).
    peak_drive : float
        Peak ``|drives|``.
    status : str
        ``"optimal"`` when constraint generation converged (no sample over the program's
        peak), ``"inaccurate (unknown)"`` when the cone solver's last round stopped short
        of its tolerances (its last point is used; it still meets ``min_fidelity``). A
        design that did not converge in ``max_iter`` rounds, whose solver ended
        infeasible or whose drives miss ``min_fidelity`` raises
        :class:`~vibrofocus.errors.InfeasibleDesignError` instead.
    solver : str
        ``"cvxopt.conelp"``: CVXOPT's primal-dual cone solver, called on each round's rows.
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
    least_drive : float or None
        With ``max_drive``: the least peak drive (unit of the drives) any drives on this
        support need to reach ``min_fidelity`` at the target's amplitude (one small cone
        program on the drive samples alone); ``None`` without ``max_drive``.
    drive_limited : bool
        ``on_max_drive="least"`` raised the drive limit to twice ``least_drive``:
        ``max_drive`` could not reach the fidelity at this tap amplitude.
    size_limit : str or None
        A size limit that changed the program, in words (the default support shortened
        to :data:`MAX_VARIABLES` design variables, or the weak actuators' pulses spaced
        further apart to stay within :data:`SPREAD_VARIABLES`); ``None`` when none did.
    support_shift : ndarray of int, shape (n_actuators,)
        How many samples earlier than ``support`` each actuator's pulses sit: all zero with
        one common support; with per-actuator supports (a default support from the latest
        arrival that would not fit :data:`MAX_VARIABLES`), each actuator's arrival at the
        target less the earliest one's.
    pulse_spacing : ndarray of int, shape (n_actuators,)
        Spacing of each actuator's pulses, samples (``decimation``, or a multiple of it for
        the weak actuators of a program with per-actuator supports).
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
    least_drive: float | None = None
    drive_limited: bool = False
    size_limit: str | None = None
    support_shift: np.ndarray | None = None
    pulse_spacing: np.ndarray | None = None


@dataclass(frozen=True)
class MinimaxFrontier:
    """The peak-contrast frontier of one tap (:func:`minimax_frontier`): for each asked
    fidelity, the minimax design's achieved fidelity and peak contrast.

    Attributes
    ----------
    min_fidelity : ndarray, shape (k,)
        The asked least fidelities.
    fidelity : ndarray, shape (k,)
        Achieved zero-lag fidelity (NaN where the fidelity cannot be reached).
    peak_contrast_db : ndarray, shape (k,)
        Target peak over the largest quiet peak, dB (NaN where infeasible).
    quiet_peak : ndarray, shape (k,)
        Largest quiet ``|displacement|``, unit of the targets.
    seconds : float
        Wall time of the whole frontier, s.
    """

    min_fidelity: np.ndarray
    fidelity: np.ndarray
    peak_contrast_db: np.ndarray
    quiet_peak: np.ndarray
    seconds: float


def _weak_actuators(h: np.ndarray, K: int) -> tuple[np.ndarray, int | None, float]:
    """Which actuators space their pulses wider, by how many pulses, and the largest share of
    the strongest's energy among them. ``h`` (n_freqs, n_act): ``T H`` at the target; ``K``:
    pulses per actuator. The weak are those under :data:`_WEAK_SHARE` of the strongest's
    band-limited energy at the target; where the others' supports alone do not fit
    :data:`SPREAD_VARIABLES`, the next weakest join them until they do. ``None``: not even
    one pulse each fits."""
    energy = np.sum(np.abs(h) ** 2, axis=0)
    order = np.argsort(energy)[::-1]
    for n_strong in range(int(np.sum(energy >= _WEAK_SHARE * np.max(energy))), -1, -1):
        k = _spacing_for(K, n_strong, energy.size - n_strong)
        if k is not None:
            weak = np.ones(energy.size, bool)
            weak[order[:n_strong]] = False
            return weak, k, float(np.max(energy[weak], initial=0.0) / np.max(energy))
    return np.zeros(energy.size, bool), None, 0.0


def _spacing_for(K: int, n_strong: int, n_weak: int) -> int | None:
    """The least spacing ``k`` (in pulses) of the weak actuators' pulses that keeps ``n_strong``
    actuators of ``K`` pulses and ``n_weak`` of ``ceil(K / k)`` within :data:`SPREAD_VARIABLES` (and
    :data:`MAX_VARIABLES`; 1: every pulse); ``None`` when not even one pulse each fits."""
    for k in range(1, K + 1):
        if n_strong * K + n_weak * -(-K // k) <= min(SPREAD_VARIABLES, MAX_VARIABLES):
            return k
    return None


def _local_peaks(y: np.ndarray, floor: float, limit: int) -> np.ndarray:
    """Indices of the local maxima of ``|y|`` (1-D) above ``floor``, largest first, at most ``limit``."""
    a = np.abs(y)
    idx = np.flatnonzero((a >= np.roll(a, 1)) & (a >= np.roll(a, -1)) & (a > floor))
    return idx[np.argsort(a[idx])[::-1][:limit]]


def coherence_radius(H: Any, coherence: Any, *, averages: int = 1) -> np.ndarray:
    """Uncertainty radius of a measured transfer matrix from its coherence: the rms size of
    an H1 estimate's complex error, ``|H| sqrt((1 - gamma2) / (averages gamma2))``
    (Bendat & Piersol: ``sqrt((1 - gamma2) / (2 averages gamma2))`` per component).

    Parameters
    ----------
    H : ndarray, complex, shape (n // 2 + 1, n_points, n_actuators)
        Measured transfer matrix (m/V).
    coherence : ndarray, real, shape (n_freqs', n_points, n_actuators)
        Magnitude-squared coherence ``gamma2`` in [0, 1] on ``n_freqs'`` bins from 0 Hz to
        Nyquist (the calibration's grid); linearly interpolated onto ``H``'s bins. NaN (not
        assessable) counts as 1: no radius there.
    averages : int
        Independent averages behind the estimate: the repeats, less the other inputs for a
        partial coherence (``repeats - n_actuators + 1`` for ``mimo``).

    Returns
    -------
    ndarray, real, shape of ``H``
        Radius, unit of ``H``.
    """
    H = as_transfer(H)
    gam = as_array(coherence, "coherence", ndim=3, finite=False)
    if gam.shape[1:] != H.shape[1:]:
        raise ValidationError(f"coherence has {gam.shape[1:]} (points, actuators), H has {H.shape[1:]}")
    averages = int(check_positive(averages, "averages"))
    if gam.shape[0] != H.shape[0]:  # both grids run from 0 Hz to Nyquist
        gam = interp1d(np.linspace(0, 1, gam.shape[0]), gam, axis=0)(np.linspace(0, 1, H.shape[0]))
    gam = np.clip(np.where(np.isfinite(gam), gam, 1.0), 1e-6, 1.0)
    return np.abs(H) * np.sqrt((1 - gam) / (averages * gam))


def _row_radius(h_radius: Any, shape: tuple[int, ...], taper: np.ndarray) -> np.ndarray:
    """Per quiet-candidate point, the bound ``r_p`` on ``|y_p(t) - y_p,nominal(t)|`` per unit
    drive norm: ``sqrt(sum_{f,a} c_f rho[f, p, a]**2 / n)`` over the taper's bins (``c_f`` = 2,
    1 at 0 Hz and Nyquist). Shape (n_points,); unit of ``h_radius``."""
    rho = as_array(h_radius, "h_radius", ndim=3)
    if rho.shape != tuple(shape):
        raise ValidationError(f"h_radius must have H's shape {tuple(shape)}, got {rho.shape}")
    if np.any(rho < 0):
        raise ValidationError("h_radius must be non-negative")
    n = 2 * (shape[0] - 1)
    c = np.full(shape[0], 2.0)
    c[0] = c[-1] = 1.0
    c = c * (taper > 0)
    return np.sqrt(np.einsum("f,fpa->p", c, rho**2) / n)


class _PerActuator:
    """The drive rows of every actuator, block-diagonal: actuator ``a``'s rows are ``D B_a``
    (``D`` the listed samples' pulse amplitudes, samples x pulses; ``B_a`` its pulses'
    basis), so each row touches one actuator's coefficients. Actuators with one pulse
    spacing share one block: ``groups`` lists (actuators, ``B``, each one's first
    coefficient)."""

    def __init__(self, D: np.ndarray, groups: list, nv: int) -> None:
        self.rows = D.shape[0]
        self.blocks = [(acts, D @ B, starts) for acts, B, starts in groups]
        self.n_act = sum(len(acts) for acts, _, _ in groups)
        self.shape = (self.n_act * self.rows, nv)

    def toarray(self) -> np.ndarray:
        out = np.zeros(self.shape)
        for acts, Dg, starts in self.blocks:
            for a, st in zip(acts, starts):
                out[a * self.rows:(a + 1) * self.rows, st:st + Dg.shape[1]] = Dg
        return out

    def __matmul__(self, u: np.ndarray) -> np.ndarray:
        out = np.zeros((self.n_act, self.rows))
        for acts, Dg, starts in self.blocks:
            out[acts] = u[starts[:, None] + np.arange(Dg.shape[1])] @ Dg.T
        return out.reshape(-1)

    def rmatvec(self, w: np.ndarray) -> np.ndarray:
        """``M' w``, without the dense ``M``."""
        W, res = w.reshape(self.n_act, self.rows), np.zeros(self.shape[1])
        for acts, Dg, starts in self.blocks:
            res[starts[:, None] + np.arange(Dg.shape[1])] = W[acts] @ Dg
        return res


class _RowOperator:
    """The cone program's ``G`` (as in ``h - G x``) as products that use its structure, for
    CVXOPT (``G(x, y, trans, alpha, beta)``) and the KKT solver: each pair ``(M, E)`` gives
    the rows ``[+M, E]`` then ``[-M, E]``, and the cones' dense blocks follow. Its products
    cost the pairs' rows once (not twice) and a drive row one actuator's coefficients (the
    dense ``G`` of a 2x3 sleeve's design, 2 x 2718 drive rows by 492 coefficients, made
    half of each design's time)."""

    def __init__(self, pairs: list, cones: list, nv: int) -> None:
        self.pairs, self.cones, self.nv = pairs, cones, nv
        self.nx = cones[0].shape[1]

    def dot(self, x: np.ndarray) -> np.ndarray:
        """``G x``."""
        xu, xe = x[:self.nv], x[self.nv:]
        out = []
        for M, E in self.pairs:
            mu, e = M @ xu, E @ xe
            out += [e + mu, e - mu]
        return np.concatenate(out + [q @ x for q in self.cones])

    def tdot(self, z: np.ndarray) -> np.ndarray:
        """``G' z``."""
        res, o = np.zeros(self.nx), 0
        for M, E in self.pairs:
            k = M.shape[0]
            zp, zm = z[o:o + k], z[o + k:o + 2 * k]
            res[:self.nv] += M.rmatvec(zp - zm) if isinstance(M, _PerActuator) else (zp - zm) @ M
            res[self.nv:] += (zp + zm) @ E
            o += 2 * k
        for q in self.cones:
            res += z[o:o + len(q)] @ q
            o += len(q)
        return res

    def __call__(self, x: Any, y: Any, trans: str = "N", alpha: float = 1.0, beta: float = 0.0) -> None:
        from cvxopt import matrix

        xv = np.asarray(x).ravel()
        r = alpha * (self.dot(xv) if trans == "N" else self.tdot(xv))
        if beta != 0.0:
            r += beta * np.asarray(y).ravel()
        y[:] = matrix(r)


def _structured_kkt(G: "_RowOperator", pairs: list, cones: list, eq: np.ndarray) -> Any:
    """A KKT solver for CVXOPT's ``conelp`` that uses the program's structure: each peak
    or drive row comes as a pair ``[+m, e]``, ``[-m, e]`` (one Gram term per pair, and a
    drive row touches one actuator's coefficients: a sparse ``m``), and each cone's Gram
    ``G_q' G_q`` is formed once, so each step adds only a rank-two term per cone.

    ``G``: the whole ``G`` as a :class:`_RowOperator` (rows in the order of ``pairs``, then ``cones``);
    ``pairs``: ``(M, E)`` with ``M`` (n, nv) dense or sparse and ``E`` (n, nx - nv) dense;
    ``cones``: dense ``G_q`` blocks (as in ``h - G x``); ``eq``: the one equality row (nx,).
    It solves ``[0 A' G'; A 0 0; G 0 -W'W] [ux; uy; uz] = [bx; by; bz]`` and returns ``ux``,
    ``uy`` and ``W uz``, as CVXOPT's own solvers do (``misc.kkt_chol``)."""
    import scipy.linalg as sla
    from cvxopt import matrix
    from cvxopt.misc import scale
    from scipy.linalg import blas

    nv = pairs[0][0].shape[1]
    nx = eq.size
    offsets = np.cumsum([0] + [2 * len(E) for _, E in pairs])
    grams = [q.T @ q for q in cones]
    # Householder reflection of the equality row: P = I - beta_h hh hh', P eq = a_e1 e1.
    a_e1 = -np.copysign(np.linalg.norm(eq), eq[0])
    hh = eq.copy()
    hh[0] -= a_e1
    beta_h = 2.0 / float(hh @ hh)

    def factor(W: dict) -> Any:
        # S is built in its lower triangle only, in Fortran order, by BLAS's symmetric
        # updates in place: the peak rows' Gram by syrk, and the cones' and the equality's
        # rank-two terms by syr/syr2 with no n x n temporaries (a 2x3 sleeve's design, 492
        # coefficients: 3.0 s against 2.2 s; syrk itself took as long as gemm there).
        w = 1.0 / np.asarray(W["d"]).ravel() ** 2
        S = np.zeros((nx, nx), order="F")
        for P, beta in zip(grams, W["beta"]):
            S += P.T / beta**2  # P is symmetric: its transpose is the Fortran-ordered view
        cross = np.zeros((nv, nx - nv))
        for (M, E), o in zip(pairs, offsets):
            wp, wm = w[o:o + len(E)], w[o + len(E):o + 2 * len(E)]
            ws, wd = wp + wm, wp - wm
            if isinstance(M, _PerActuator):  # block-diagonal: one (m_a, m_a) block per actuator
                wsr, ew = ws.reshape(M.n_act, 1, -1), (wd[:, None] * E).reshape(M.n_act, -1, E.shape[1])
                for acts, Dg, starts in M.blocks:
                    m = Dg.shape[1]
                    blocks = (Dg.T[None] * wsr[acts]) @ Dg
                    cross_a = Dg.T[None] @ ew[acts]
                    for i, st in enumerate(starts):
                        S[st:st + m, st:st + m] += blocks[i]
                        cross[st:st + m] += cross_a[i]
            else:
                weighted = M * np.sqrt(ws)[:, None]  # (k, nv), C order: its transpose is Fortran's
                S[:nv, :nv] += blas.dsyrk(1.0, weighted.T, lower=1)
                cross += M.T @ (wd[:, None] * E)
            S[nv:, nv:] += (E.T * ws) @ E
        S[nv:, :nv] += cross.T
        for q, v, beta in zip(cones, W["v"], W["beta"]):
            v = np.asarray(v).ravel()
            jv = v.copy()
            jv[1:] *= -1
            pq, pv = q.T @ jv, q.T @ v
            # (4 (v'v) pq pq' - 2 pq pv' - 2 pv pq') / beta^2
            S = blas.dsyr(4 * (v @ v) / beta**2, pq, lower=1, a=S, overwrite_a=1)
            S = blas.dsyr2(-2 / beta**2, pq, pv, lower=1, a=S, overwrite_a=1)
        # The equality row eliminated as CVXOPT's own Cholesky solver does (a Householder
        # reflection P with P a = sigma |a| e1; Cholesky of the rest of P S P): S's
        # inverse is never applied to the equality's direction, along which a limit binding
        # over most samples leaves S ill-conditioned (the Schur complement ended short of
        # its tolerances on those programs, "unknown" after 25-30 steps).
        # P S P = S - beta (hh g' + g hh') - beta^2 (hh' g) hh hh' with g = S hh:
        # one rank-two update with g - beta (hh' g) / 2 hh.
        g = blas.dsymv(1.0, S, hh, lower=1)
        g -= 0.5 * beta_h * float(hh @ g) * hh
        ps = blas.dsyr2(-beta_h, hh, g, lower=1, a=S, overwrite_a=1)
        try:
            chol = sla.cho_factor(ps[1:, 1:], lower=True, check_finite=False)
        except np.linalg.LinAlgError:
            raise ArithmeticError("singular KKT system") from None
        col0 = ps[:, 0].copy()  # P S P's first row and column (its lower triangle's column)

        def solve(x: Any, y: Any, z: Any) -> None:
            g = matrix(z)
            scale(g, W, trans="T", inverse="I")
            scale(g, W, inverse="I")
            r = np.asarray(x).ravel() + G.tdot(np.asarray(g).ravel())
            pr = r - beta_h * hh * (hh @ r)
            xt = np.empty(nx)
            xt[0] = float(y[0]) / a_e1
            xt[1:] = sla.cho_solve(chol, pr[1:] - col0[1:] * xt[0], check_finite=False)
            ux = xt - beta_h * hh * (hh @ xt)
            x[:] = matrix(ux)
            y[0] = (pr[0] - col0 @ xt) / a_e1
            z[:] = matrix(G.dot(ux) - np.asarray(z).ravel())
            scale(z, W, trans="T", inverse="I")

        return solve

    return factor


def _solve_cone(A: Any, b: np.ndarray, Lt: np.ndarray, cap: float, D: Any,
                dcap: float | None, *, r: np.ndarray | None = None,
                norm_cap: float | None = None, accuracy: float | None = None
                ) -> tuple[np.ndarray | None, float, str, int]:
    """min t s.t. ``|A u| + r s <= t``, ``||u|| <= s``, ``b.u = 1``, ``||Lt u|| <= cap``,
    ``|D u| <= dcap``, by CVXOPT's primal-dual cone solver with a KKT solver that uses the
    program's structure (:func:`_structured_kkt`; no modelling layer: this program is
    rebuilt every round).

    ``A`` (n_rows, n_var) dense or sparse, ``b`` (n_var,), ``Lt`` (rank, n_var) with
    ``Lt' Lt`` the target's Gram, ``D`` (n_drive_rows, n_var) dense or sparse (each drive
    row touches one actuator) or ``None``; ``r`` (n_rows,) non-negative per-row radii, or
    ``None``: no ``s`` and no norm term. ``norm_cap``: with ``r`` ``None``, a system the
    Cholesky step cannot factor (few rows, a target norm of less than full rank) is tried
    again with ``||u|| <= norm_cap`` added (inactive when the cap is far above the
    optimum's norm; it gives the system full rank) before CVXOPT's regularized LDL.
    ``accuracy``: the solver stops when its relative duality gap and its primal and dual
    residuals are below it (``None``: CVXOPT's own defaults, 1e-6 and 1e-7).
    Returns ``u`` (``None`` if the solver gave no point), ``t``, the solver's status and
    its iterations.
    """
    from cvxopt import matrix, solvers

    nv = A.shape[1]
    robust = r is not None
    nx = nv + (2 if robust else 1)  # u, [s], t
    E = np.zeros((A.shape[0], nx - nv))
    E[:, -1] = -1.0
    if robust:
        E[:, 0] = r
    pairs, h_lin = [(A, E)], [np.zeros(2 * A.shape[0])]
    if D is not None and D.shape[0]:
        pairs.append((D, np.zeros((D.shape[0], nx - nv))))
        h_lin.append(np.full(2 * D.shape[0], float(dcap)))
    # Second-order cones as h - G x: (cap, Lt u), and (s, u) when robust.
    cone = np.zeros((1 + len(Lt), nx))
    cone[1:, :nv] = -Lt
    cones, h_cone = [cone], [np.concatenate([[cap], np.zeros(len(Lt))])]
    if robust:
        norm = np.zeros((1 + nv, nx))
        norm[0, nv], norm[1:, :nv] = -1.0, -np.eye(nv)
        cones.append(norm)
        h_cone.append(np.zeros(1 + nv))
    c = np.zeros(nx)
    c[-1] = 1.0
    eq = np.zeros(nx)
    eq[:nv] = b
    options = {"show_progress": False, "maxiters": 100,
               **({} if accuracy is None else {"reltol": float(accuracy), "feastol": float(accuracy)})}

    def steps(factor: Any) -> dict:
        """The options for a KKT solver: the structured one's steps end at its stalls."""
        return options if isinstance(factor, str) else {**options, "maxiters": _STRUCTURED_MAXITERS}

    def program(cones: list, h_cone: list, dense: bool = False) -> tuple:
        h = np.concatenate(h_lin + h_cone)
        dims = {"l": sum(len(x) for x in h_lin), "q": [len(x) for x in h_cone], "s": []}
        # The structured solver pays off where the per-actuator drive rows outnumber the
        # peak rows (a drive limit listed over the support, or the least-drive program:
        # 37 s against 24 s for the 2x3 sleeve's location 1 with the dense G, less with its
        # products); elsewhere CVXOPT's own Cholesky is faster.
        drive_rows = sum(M.shape[0] for M, _ in pairs if isinstance(M, _PerActuator))
        peak_rows = sum(M.shape[0] for M, _ in pairs if not isinstance(M, _PerActuator))
        if drive_rows > peak_rows and not dense:
            G = _RowOperator(pairs, cones, nv)
            return (matrix(c), G, matrix(h), dims, matrix(eq[None, :]), matrix([1.0])), \
                _structured_kkt(G, pairs, cones, eq)
        G = np.vstack([np.hstack([(M.toarray() if hasattr(M, "toarray") else M) * sign, Ep])
                       for M, Ep in pairs for sign in (1.0, -1.0)] + cones)
        return (matrix(c), matrix(G), matrix(h), dims, matrix(eq[None, :]), matrix([1.0])), "chol"

    args, factor = program(cones, h_cone)
    try:  # Cholesky on the reduced system: fast, but it needs [G; A] of full column rank
        if factor == "chol" and args[2].size[0] + 1 < nx:
            raise ArithmeticError("fewer rows than coefficients")
        sol = solvers.conelp(*args, kktsolver=factor, options=steps(factor))
    except (ArithmeticError, ValueError):  # rank-deficient (few rows), or a numerical breakdown
        sol = None
        # The fallbacks below need the dense G: built once, here, if the first try had not.
        dense = args if factor == "chol" else program(cones, h_cone, dense=True)[0]
        if factor != "chol":
            # The structured solver's normal equations broke down ("domain error"):
            # CVXOPT's own Cholesky (QR on the equality first) usually does not, at a
            # fraction of the regularized LDL's cost (0.15 s against 5-11 s a solve on the
            # OSC tests' arm, whose drive limit binds).
            if dense[1].size[0] + 1 >= nx:
                try:
                    sol = solvers.conelp(*dense, kktsolver="chol", options=options)
                except (ArithmeticError, ValueError):
                    sol = None
        if sol is None and not robust and norm_cap is not None:  # an inactive norm bound gives it full rank
            norm = np.zeros((1 + nv, nx))
            norm[1:, :nv] = -np.eye(nv)
            try:
                args2, factor2 = program(cones + [norm], h_cone + [np.concatenate([[norm_cap], np.zeros(nv)])])
                sol = solvers.conelp(*args2, kktsolver=factor2, options=steps(factor2))
                if sol["x"] is not None and np.linalg.norm(np.asarray(sol["x"])[:nv]) > 0.5 * norm_cap:
                    sol = None  # the bound binds: not the program asked; solve without it
            except (ArithmeticError, ValueError):
                sol = None
        if sol is None:  # a regularized LDL, on the dense G
            sol = solvers.conelp(*dense, kktsolver="ldl", options={**options, "kktreg": 1e-9})
    x = None if sol["x"] is None else np.asarray(sol["x"]).ravel()
    return (None if x is None else x[:nv]), (np.nan if x is None else float(x[-1])), sol["status"], sol["iterations"]


def _solve_in_span(A: np.ndarray, b: np.ndarray, Lt: np.ndarray, Linv: np.ndarray, N0: np.ndarray, cap: float,
                   D: np.ndarray | None, dcap: float | None, *, norm_cap: float | None = None,
                   accuracy: float | None = None) -> tuple[np.ndarray | None, float, str, int]:
    """:func:`_solve_cone` (nominal: no row radii) on the span of the listed rows: the same
    optimum in fewer variables when the rows are fewer than the coefficients.

    In the target's coordinates ``v = Lt u`` (``u = Linv v + N0 z``) the fidelity cone is
    ``||v|| <= cap`` and every row is a linear functional of ``v`` and ``z``. Projecting
    ``v`` on a subspace that holds ``b``'s and every row's ``v``-part keeps each functional's
    value and does not lengthen ``v``: any feasible point has a feasible projection with the
    same objective, so the program restricted to that subspace (orthonormal basis ``Vs``,
    at most one column per row) has the full program's optimum; ``z``, which no norm
    bounds, goes on the span of the rows' ``z``-parts the same way. The program's size then
    follows the rows that can bind, not the window or the actuators.
    """
    n_rows = A.shape[0] + (0 if D is None else D.shape[0])
    rank, n0 = Linv.shape[1], N0.shape[1]
    if min(rank, n_rows + 1) + min(n0, n_rows + 1) >= 0.8 * Linv.shape[0]:  # no smaller: as it is
        return _solve_cone(A, b, Lt, cap, D, dcap, norm_cap=norm_cap, accuracy=accuracy)
    dense = np.vstack([M.toarray() if hasattr(M, "toarray") else M for M in (A, D) if M is not None])
    Av, Az = dense @ Linv, dense @ N0  # (n_rows, rank), (n_rows, n0)
    c, cz = Linv.T @ b, N0.T @ b
    # v on the span of the rows' and b's v-parts; z (no norm on it) on that of their z-parts.
    Vs = np.linalg.qr(np.column_stack([c, Av.T]))[0] if n_rows + 1 < rank else np.eye(rank)
    Zs = np.linalg.qr(np.column_stack([cz, Az.T]))[0] if n_rows + 1 < n0 else np.eye(n0)
    k = Vs.shape[1]
    reduced = np.hstack([Av @ Vs, Az @ Zs])
    Lt_k = np.hstack([np.eye(k), np.zeros((k, Zs.shape[1]))])
    b_k = np.concatenate([Vs.T @ c, Zs.T @ cz])
    D_k = None if D is None or not D.shape[0] else reduced[A.shape[0]:]
    y, value, status, iterations = _solve_cone(reduced[:A.shape[0]], b_k, Lt_k, cap, D_k, dcap, norm_cap=norm_cap,
                                               accuracy=accuracy)
    u = None if y is None else Linv @ (Vs @ y[:k]) + N0 @ (Zs @ y[k:])
    return u, value, status, iterations


def _support_span(t_peak: int, support_s: tuple[float, float], fs: float, n: int) -> tuple[int, int]:
    """The first and last sample of ``support_s`` (s before, after the tap at ``t_peak``), within the window."""
    pre, post = (int(round(s * fs)) for s in support_s)
    return max(0, t_peak - pre), min(n - 1, t_peak + post)


def _pulse_basis(taper: np.ndarray, delays: np.ndarray, n: int, every: int = 1) -> np.ndarray:
    """The basis (K, m) of the drives made of the pulses at every ``every``-th of ``delays``
    (K): the pulses' Gram (Toeplitz, from the taper's autocorrelation) has about
    2 x bandwidth x support well-conditioned directions (the discrete prolate sequences of
    the band); the drives are combinations of those, with unit energy each. Rows of the
    pulses left out are zero."""
    sub = np.arange(0, delays.size, int(every))
    lag = (delays[sub, None] - delays[None, sub]) % n
    wp, Vp = np.linalg.eigh(np.fft.irfft(taper**2, n)[lag])
    kept = wp > wp[-1] * 1e-12
    basis = np.zeros((delays.size, int(np.sum(kept))))
    basis[sub] = Vp[:, kept] / np.sqrt(wp[kept])
    return basis


def _target_norm(xc: np.ndarray, C: np.ndarray, taper: np.ndarray, delays: np.ndarray,
                 n: int, shifts: np.ndarray | None = None, every: np.ndarray | None = None
                 ) -> tuple[list, np.ndarray, np.ndarray, np.ndarray, float, np.ndarray, np.ndarray]:
    """The target's part of the program on pulses at ``delays``: each actuator's basis
    (K, m_a), ``b`` (projection on the waveform), ``Lt`` (``||Lt u||`` = the target's norm),
    the best fidelity's coefficients and that fidelity (what the support can reach), and
    the target's coordinates ``Linv``, ``N0`` (``u = Linv v + N0 z``).

    ``xc`` (n_act, n): cross-correlations of the target's responses with the waveform;
    ``C`` (n_act, n_act, n): their auto- and cross-correlations; ``shifts`` (n_act,): actuator
    ``a``'s pulses sit at ``delays - shifts[a]`` (default none: one support for all); ``every``
    (n_act,): actuator ``a`` uses every ``every[a]``-th pulse (default all). The pulses' Gram
    depends only on the lags inside one actuator's support, so actuators with one spacing
    share one basis."""
    n_act, K = xc.shape[0], delays.size
    s = np.zeros(n_act, int) if shifts is None else np.asarray(shifts, int)
    e = np.ones(n_act, int) if every is None else np.asarray(every, int)
    lag = (delays[:, None] - delays[None, :]) % n  # t_k - t_l
    by_spacing = {int(k): _pulse_basis(taper, delays, n, int(k)) for k in np.unique(e)}
    bases = [by_spacing[int(k)] for k in e]
    # Q[(a,k),(b,l)] = C_ab(t_k - s_a - t_l + s_b), in the bases.
    lags = (lag[None, None] - (s[:, None] - s[None, :])[:, :, None, None]) % n  # (n_act, n_act, K, K)
    Cl = np.take_along_axis(C, lags.reshape(n_act, n_act, -1), axis=-1).reshape(lags.shape)
    xk = xc[np.arange(n_act)[:, None], (delays[None, :] - s[:, None]) % n]  # (n_act, K)
    if len(by_spacing) == 1:  # one basis for all
        basis = bases[0]
        m = basis.shape[1]
        b = (xk @ basis).reshape(-1)
        Q = np.einsum("km,abkl,ln->ambn", basis, Cl, basis, optimize=True).reshape(n_act * m, n_act * m)
    else:
        big = block_diag(*bases)  # (n_act K, nv)
        b = big.T @ xk.reshape(-1)
        Q = big.T @ (Cl.transpose(0, 2, 1, 3).reshape(n_act * K, n_act * K) @ big)
    w, V = np.linalg.eigh(0.5 * (Q + Q.T))
    keep = w > w[-1] * 1e-12
    Lt = np.sqrt(w[keep])[:, None] * V[:, keep].T  # |y_target|^2 = ||Lt u||^2
    # The best fidelity's coefficients (least ||y|| at b.u = 1): the start of every solve.
    qb = V[:, keep] @ ((V[:, keep].T @ b) / w[keep])
    u_best = qb / (b @ qb)
    # u = Linv v + N0 z: v the target's coordinates (||v|| = ||Lt u||), z the directions the
    # target does not see (none unless its Gram is rank-deficient).
    Linv = V[:, keep] / np.sqrt(w[keep])
    return bases, b, Lt, u_best, 1 / float(np.linalg.norm(Lt @ u_best)), Linv, V[:, ~keep]


def _check_support(support_s: Any) -> tuple[float, float]:
    """``support_s`` as two finite non-negative seconds, not both zero (ValidationError naming it)."""
    from .._validation import shorten

    try:
        pre, post = support_s
    except (TypeError, ValueError):
        raise ValidationError(f"support_s must be (before_s, after_s), got {shorten(support_s)}") from None
    pre = check_positive(pre, "support_s[0] (before the tap, s)", allow_zero=True)
    post = check_positive(post, "support_s[1] (after the tap, s)", allow_zero=True)
    if pre + post == 0:
        raise ValidationError("support_s must not be (0, 0): the drives need some support")
    return pre, post


def _check_max_iter(max_iter: Any) -> int:
    """``max_iter`` as an int >= :data:`MIN_ITER` (ValidationError naming it)."""
    if isinstance(max_iter, bool) or not isinstance(max_iter, (int, np.integer)) or max_iter < MIN_ITER:
        raise ValidationError(f"max_iter must be an integer >= {MIN_ITER} (constraint-generation rounds; fewer "
                              f"return drives the peak constraints never saw), got {max_iter!r}")
    return int(max_iter)


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
    support_s: tuple[float, float] | None = None,
    stride: int = 32,
    ir_energy_tol: float = 1e-4,
    decimation: int | None = None,
    tol: float = 1e-3,
    fidelity_margin: float = 1e-3,
    max_iter: int = 30,
    h_radius: Any = None,
    on_max_drive: str = "refuse",
) -> np.ndarray | tuple[np.ndarray, MinimaxReport]:
    """Peak-contrast (minimax) drives: the least largest quiet-point ``|displacement|`` at
    a given target fidelity (docs/method.md, "Rendering methods").

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
    support_s : (float, float), optional
        The drives' support before and after the tap's peak, s (each >= 0, not both 0):
        causal drives played once from silence, starting at most ``support_s[0]`` before
        the tap. At most :data:`MAX_VARIABLES` drive pulses over all actuators (the
        support over ``decimation / fs`` times the actuators), or ValidationError.
        Default: from ``H`` (:meth:`ResponseTiming.support_s
        <vibrofocus.rendering.ResponseTiming.support_s>`): twice the latest arrival of an
        actuator's wave at the target before the tap, 5 ms after it, and at least the
        reference setup's (10 ms, 5 ms). Where that one support over every actuator would
        exceed :data:`MAX_VARIABLES` pulses and the arrivals differ: per-actuator supports
        (the earliest arrival's support, each actuator's pulses its arrival less the earliest
        one's earlier; the weakest actuators' pulses spaced wider within
        :data:`SPREAD_VARIABLES`: ``size_limit``, ``support_shift``, ``pulse_spacing`` of the
        report); else shortened to :data:`MAX_VARIABLES` pulses. A support too short for
        ``min_fidelity`` is refused naming ``support_s`` and a support that reaches it.
    decimation : int, optional
        Spacing of the drive pulses, samples; default the largest that keeps the taper's
        upper edge below the pulses' Nyquist frequency.
    stride : int
        Least spacing of the first peak constraints' coarse grid, samples (widened to at
        most 64 samples per quiet point, so that the first program does not grow with the
        window; later rounds add the samples found over the peak).
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
        Most constraint-generation rounds, at least :data:`MIN_ITER`. A design that has
        not converged by then raises :class:`~vibrofocus.errors.InfeasibleDesignError`
        (it used to return the last round's drives, far over the quiet peak).
    h_radius : ndarray, real, shape (n // 2 + 1, n_points, n_actuators), optional
        Uncertainty of ``H``: ``|H_true - H| <= h_radius`` at each frequency, point and
        actuator (unit of ``H``; see :func:`coherence_radius`). Given, the design minimizes a
        **robust** quiet peak, ``|y_q(t)| + r_q ||x||`` with ``r_q = sqrt(sum_{f,a} c_f
        h_radius[f, q, a]**2 / n)`` (``c_f`` = 2, 1 at 0 Hz and Nyquist; over the band's
        bins) and ``||x||`` the drives' Euclidean norm: the largest quiet ``|displacement|``
        through any ``H`` within the radius (Cauchy-Schwarz over frequency and actuator).
        ``None``: the nominal program (no norm term).
    on_max_drive : {"refuse", "least"}
        What to do when no drive within ``max_drive`` reaches ``min_fidelity`` at the
        target's amplitude (found by one small program before the design, and reported
        as ``least_drive``): ``"refuse"`` raises
        :class:`~vibrofocus.errors.InfeasibleDesignError` naming the drive needed;
        ``"least"`` designs at twice that least drive instead (room for the quiet peak
        to fall; :data:`_LEAST_DRIVE_ROOM`) and sets the report's
        ``drive_limited``: the caller scales the drives to its limit, and the tap falls.

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
    Each round's program goes to CVXOPT's cone solver as dense matrices (one BLAS thread;
    no cvxpy needed).
    """
    with _single_threaded_blas():  # small dense algebra: BLAS threads only cost hand-offs
        program = _Program(H, targets, fs, band=band, quiet=quiet, taper_octaves=taper_octaves,
                           support_s=support_s, stride=stride, ir_energy_tol=ir_energy_tol, decimation=decimation,
                           h_radius=h_radius)
        return program.design(min_fidelity, max_drive=max_drive, full_output=full_output, tol=tol,
                              fidelity_margin=fidelity_margin, max_iter=max_iter, on_max_drive=on_max_drive)


class _Program:
    """The parts of the minimax program that do not depend on the fidelity or the drive
    limit (basis, target norm, impulse responses) and the peak constraints found so far:
    one set-up serves several designs (the frontier), each warm-started from the last."""

    def __init__(self, H: Any, targets: Any, fs: float, *, band: tuple[float, float], quiet: Any,
                 taper_octaves: float, support_s: tuple[float, float], stride: int, ir_energy_tol: float,
                 decimation: int | None, h_radius: Any = None) -> None:
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
        n_pts, n_act = H.shape[1], H.shape[2]
        quiet_idx = np.delete(np.arange(n_pts), ti) if quiet is None else as_indices(quiet, "quiet", n_pts)
        quiet_idx = quiet_idx[quiet_idx != ti]
        if quiet_idx.size == 0:
            raise ValidationError("minimax_filter needs at least one quiet point besides the target")
        stride = int(check_positive(stride, "stride"))
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
        # The support H asks for: the waves' arrival at the target sets how early drives start.
        self.timing = response_timing(H, fs, band=band, taper_octaves=taper_octaves)
        wanted = tuple(float(x) for x in self.timing.support_s(ti))
        self.suggested = self._fit_support(wanted, n_act, r, fs)
        self.given = support_s is not None
        # Per-actuator supports: where one common support from the latest arrival would not
        # fit the program (many actuators, far ones), each actuator's pulses sit its own
        # arrival earlier than the nearest's, on a support from the earliest arrival: every
        # wave reaches the target around the tap, and the program grows with the actuators
        # times one such support, not the latest arrival. Elsewhere: one support, as before.
        arrival = self.timing.arrival_s[ti]
        self.shifts, self.every, thinned, spread = np.zeros(n_act, int), np.ones(n_act, int), "", False
        common = wanted
        if not self.given and self.suggested[0] < wanted[0] - 1e-12:
            self.shifts = np.round((arrival - np.min(arrival)) * fs).astype(int)
            # The rule of ResponseTiming.support_s, from the earliest arrival.
            own = (max(DEFAULT_SUPPORT_S[0], float(np.round(2.0 * np.min(arrival), 3))), DEFAULT_SUPPORT_S[1])
            lo, hi = _support_span(t_peak, own, fs, n)
            K = np.arange(lo, hi + 1, r).size  # pulses per actuator
            weak, k, share = _weak_actuators(H[:, ti] * taper[:, None], K)
            if k is None or own[0] >= wanted[0]:  # no fit, or no shorter than one support: one, shortened
                self.suggested = self._fit_support(own, n_act, r, fs)
            else:
                self.every[weak], spread = k, True
                self.suggested = own
                if k > 1:
                    thinned = (f"; the {int(np.sum(weak))} actuators weakest at the target (energy at most "
                               f"{share:.0%} of the strongest's) place a drive pulse every {k * r} samples instead "
                               f"of {r} (SPREAD_VARIABLES={SPREAD_VARIABLES} design variables)")
            wanted = own
        # No silent cap: a default support cut to the program's size is named in the
        # report and in every refusal.
        self.size_limit = None
        if not self.given and self.suggested[0] < wanted[0] - 1e-12:
            self.size_limit = (
                f"the default support_s=({wanted[0]:.4g}, {wanted[1]:.4g}) s (from H's arrival times"
                f"{', per actuator' if self.shifts.any() else ''}) was shortened "
                f"to ({self.suggested[0]:g}, {self.suggested[1]:g}) s by MAX_VARIABLES={MAX_VARIABLES} design "
                f"variables over {n_act} actuators")
        elif spread:
            self.size_limit = (
                f"one default support_s=({common[0]:.4g}, {common[1]:.4g}) s for all {n_act} actuators would exceed "
                f"MAX_VARIABLES={MAX_VARIABLES} design variables: per-actuator supports of ({own[0]:g}, {own[1]:g}) s "
                f"instead, each actuator's pulses its arrival at the target earlier than the nearest's (up to "
                f"{np.max(self.shifts) / fs * 1e3:.3g} ms){thinned}")
        asked_support = support_s
        support_s = self.suggested if support_s is None else _check_support(support_s)
        first, last = _support_span(t_peak, support_s, fs, n)
        delays = np.arange(first, last + 1, r)
        K = delays.size
        if not spread and K * n_act > MAX_VARIABLES:
            longest = MAX_VARIABLES // n_act * r / fs
            shown = tuple(support_s if asked_support is None else asked_support)
            raise ValidationError(
                f"support_s={shown!r} s gives {K} drive pulses per actuator ({last - first + 1} samples at "
                f"fs={fs:g} Hz, decimation {r}) for {n_act} actuators: {K * n_act} design variables, more than the "
                f"{MAX_VARIABLES} the dense cone program handles (time and memory grow with their cube and square); "
                f"give a support of at most {longest:.4g} s in all")

        # Band-limited impulse responses g[p, a, t] (pulse at t = 0), scaled to O(1).
        g = np.fft.irfft(H * taper[:, None, None], n, axis=0).transpose(1, 2, 0)  # (n_points, n_act, n)
        gscale = float(np.max(np.abs(g[ti]))) or 1.0
        g = g / gscale
        energy = np.sum(g**2, axis=-1)
        self.tail = float(np.sum(g[..., -n // 8:] ** 2) / np.sum(energy)) if np.sum(energy) > 0 else 0.0
        # The first peak constraints list the samples where the pulses' responses carry all
        # but ir_energy_tol of their energy (the truncation); any sample found over joins.
        cum = np.cumsum(np.sum(g[:, :, : n // 2] ** 2, axis=(0, 1)))
        ir_taps = min(int(np.searchsorted(cum, (1 - ir_energy_tol) * np.sum(energy))) + 1, n // 2)
        self.left_out = float(1 - cum[ir_taps - 1] / np.sum(energy))

        # Target: <y, d~> = b^T u and |y|^2 = u^T Q u (Q Toeplitz in the delays).
        dn = desired / d_norm
        Gt = np.fft.rfft(g[ti], axis=-1)  # (n_act, F)
        xc = np.fft.irfft(np.conj(Gt) * np.fft.rfft(dn)[None], n, axis=-1)  # sum_t g_a(t) d(t + tau)
        C = np.fft.irfft(np.conj(Gt)[:, None] * Gt[None, :], n, axis=-1)  # C_ab(tau)
        self._xc, self._C, self._t_peak = xc, C, t_peak
        bases, self.b, self.Lt, self.u_best, self.best_fidelity, self.Linv, self.N0 = _target_norm(
            xc, C, taper, delays, n, self.shifts, self.every)
        sizes = np.array([B.shape[1] for B in bases])
        starts = np.concatenate([[0], np.cumsum(sizes)[:-1]])
        # Actuators with one pulse spacing share one basis (and one block of drive rows).
        self.groups = [(np.flatnonzero(self.every == k), bases[int(np.flatnonzero(self.every == k)[0])],
                        starts[self.every == k]) for k in np.unique(self.every)]
        self.uniform = len(self.groups) == 1
        basis, m = bases[0], int(sizes[0])
        self.big = None if self.uniform else block_diag(*bases)
        nv = int(np.sum(sizes))
        self.support_s = (float(support_s[0]), float(support_s[1]))
        self.H, self.n, self.fs, self.taper, self.g, self.gscale = H, n, fs, taper, g, gscale
        self.ti, self.quiet, self.n_act, self.m, self.basis, self.delays = ti, quiet_idx, n_act, m, basis, delays
        self.desired, self.d_norm, self.ir_taps, self.decimation = desired, d_norm, ir_taps, r
        self.pulse = np.fft.irfft(taper, n)  # unit pulse -> drive
        # Robust rows: |A u| + rq ||u|| (||x|| = u_scale ||u||: the basis has unit energy per
        # coefficient, so ||y - y_nominal|| / d_norm <= r_q u_scale ||u|| / d_norm = r_q / gscale ||u||).
        self.rq = None if h_radius is None else _row_radius(h_radius, H.shape, taper)[quiet_idx] / gscale
        self.rho_max = None if h_radius is None else float(np.max(h_radius))
        self.h_max = float(np.max(np.abs(H)))
        if self.rq is not None and np.max(self.rq) > _MAX_ROW_RADIUS:
            q = int(np.argmax(self.rq))
            raise ValidationError(
                f"h_radius is too large to design under (up to {self.rho_max:.3g}, against |H| up to {self.h_max:.3g}): "
                f"at quiet point {int(quiet_idx[q])} the uncertainty bound is {self.rq[q]:.3g} times the target's "
                f"peak response per unit drive, more than {_MAX_ROW_RADIUS:.0e}, so no drive focuses within it; "
                "give the radius in the unit of H (m/V), e.g. coherence_radius(H, coherence)")
        self.u_scale = d_norm / gscale  # drives = (u * u_scale) pulses

        # Warm start: the samples where the pseudo-inverse's quiet response peaks, and a coarse grid
        # (with per-actuator supports, a many-actuator program, not the pseudo-inverse: its
        # factorization over every bin cost as much as the design).
        from .inverse import inverse_filter

        warm = [] if self.shifts.any() else [predict_response(
            H[:, quiet_idx], inverse_filter(H, targets, fs, band=band, taper_octaves=taper_octaves,
                                            check_wraparound=False))]
        # The coarse grid has at most _GRID_ROWS samples per point, whatever the window (the
        # rounds add what it misses), and the best-fidelity drives' quiet peaks join it.
        start = first - int(np.max(self.shifts))
        span = min(n, last + ir_taps) - start
        grid = np.arange(start, start + span, max(stride, -(-span // _GRID_ROWS))) % n
        y1 = predict_response(H[:, quiet_idx], self.drives_of(self.u_best))
        pairs = [(j, int(t)) for y in (*warm, y1) for j in range(len(quiet_idx))
                 for t in _local_peaks(y[j], 0.3 * np.max(np.abs(y[j])), 10)]
        pairs += [(j, int(t)) for j in range(len(quiet_idx)) for t in grid]
        self.listed = np.zeros((0, 2), int)
        self.A = np.zeros((0, nv))
        self._add_pairs(pairs)
        self.drive_rows = np.zeros(0, int)
        self.D = np.zeros((0, K))
        # Every drive sample the pulses reach (their sum, not one pulse: three times the
        # pulse's 1 % half-width past the support): a drive limit that binds does so over
        # most of them, and the per-actuator rows cost the structured KKT solver little.
        pulse = np.abs(self.pulse[: n // 2])
        reach = _DRIVE_REACH * int(np.flatnonzero(pulse >= 0.01 * pulse[0])[-1])
        self._add_drive_rows(np.arange(max(0, first - reach), min(n, last + reach + 1)))

    @staticmethod
    def _fit_support(support: tuple[float, float], n_act: int, r: int, fs: float) -> tuple[float, float]:
        """``support`` (s before, after the tap), its before-part shortened to the most
        pulses the program takes (:data:`MAX_VARIABLES`) over ``n_act`` actuators."""
        pre, post = support
        most = (MAX_VARIABLES // n_act - 1) * r / fs  # the longest support in all, s
        if pre + post > most:
            pre = max(np.floor((most - post) * 1e3) / 1e3, 0.0)
        return (float(pre), float(post))

    def best_fidelity_for(self, support_s: tuple[float, float]) -> float:
        """The best fidelity drives on another support reach (same taper, pulses and target)."""
        first, last = _support_span(self._t_peak, support_s, self.fs, self.n)
        delays = np.arange(first, last + 1, self.decimation)
        return _target_norm(self._xc, self._C, self.taper, delays, self.n, self.shifts, self.every)[4]

    def _support_advice(self, min_fidelity: float, asked: float) -> str:
        """Why the asked fidelity is out of reach, naming the parameter to change and a
        value that works: ``support_s`` when a longer support reaches it, else the fidelity."""
        arrival = float(np.max(self.timing.arrival_s[self.ti]))
        pre, post = self.support_s
        # Longer supports to try, shortest first: H's own, then twice and four times it,
        # each within the program's size.
        tries = [self.suggested] + [self._fit_support((k * self.suggested[0], self.suggested[1]), self.n_act,
                                                      self.decimation, self.fs) for k in (2, 4)]
        for cand in tries:
            if cand[0] + cand[1] <= pre + post + 1e-9:
                continue
            if self.best_fidelity_for(cand) > asked * (1 + 1e-6):
                why = (f"shorter than the waves' arrival at the target (~{arrival:.3g} s)" if pre < arrival
                       else f"too short for min_fidelity={min_fidelity:.10g}")
                given = "support_s" if self.given else "the default support_s"
                capped = f" [size limit: {self.size_limit}]" if self.size_limit else ""
                return (f"{given}=({pre:g}, {post:g}) is {why}: it reaches fidelity {self.best_fidelity:.4g} at best; "
                        f"use support_s=({cand[0]:g}, {cand[1]:g}){capped}")
        longest = max(tries, key=sum)
        longer = (f"; longer ones, up to support_s=({longest[0]:g}, {longest[1]:g}), reach no more"
                  if sum(longest) > pre + post + 1e-9 else "")
        capped = f" [size limit: {self.size_limit}]" if self.size_limit else ""
        return (f"min_fidelity={min_fidelity:.10g} is above the model's best fidelity {self.best_fidelity:.6g} "
                f"over this support (support_s=({pre:g}, {post:g}){longer}): relax the fidelity{capped}")

    def _add_pairs(self, pairs: Any) -> int:
        """Add the peak constraints at (quiet j, sample t) not listed yet; how many."""
        new = np.array(sorted(set(map(tuple, pairs)) - set(map(tuple, self.listed.tolist()))), int).reshape(-1, 2)
        if new.size:
            p, t = self.quiet[new[:, 0]], new[:, 1]
            # Actuator a's pulses sit at delays - shifts[a].
            lags = (t[:, None, None] - self.delays[None, None, :] + self.shifts[None, :, None]) % self.n  # N, n_act, K
            rows = self.g[p[:, None, None], np.arange(self.n_act)[None, :, None], lags]  # (N, n_act, K)
            rows = (rows @ self.basis).reshape(len(p), -1) if self.uniform else rows.reshape(len(p), -1) @ self.big
            self.A = np.vstack([self.A, rows])
            self.listed = np.vstack([self.listed, new])
        return len(new)

    def _drive_samples(self, x: np.ndarray, floor: float, limit: int) -> list:
        """The local peaks of each actuator's drive ``x`` (n_act, n) above ``floor`` (at most
        ``limit`` each), as the samples of the common support the drive rows list (actuator
        ``a``'s sample ``t`` is the common ``t + shifts[a]``)."""
        return [(int(t) + int(self.shifts[a])) % self.n for a in range(self.n_act)
                for t in _local_peaks(x[a], floor, limit)]

    def _add_drive_rows(self, samples: Any) -> int:
        """Add the drive-limit constraints at these samples (of the common support: actuator
        ``a``'s drive ``shifts[a]`` earlier) not listed yet; how many."""
        new = np.setdiff1d(np.asarray(samples, int), self.drive_rows)
        if new.size:
            self.D = np.vstack([self.D, self.pulse[(new[:, None] - self.delays[None, :]) % self.n]])
            self.drive_rows = np.concatenate([self.drive_rows, new])
        return len(new)

    def _per_actuator(self, D: np.ndarray) -> "_PerActuator":
        """Drive rows (samples x pulses) for every actuator, in each one's basis, kept as blocks."""
        return _PerActuator(D, self.groups, self.A.shape[1])

    def drives_of(self, u: np.ndarray) -> np.ndarray:
        train = np.zeros((self.n_act, self.n))
        amplitudes = u.reshape(self.n_act, self.m) @ self.basis.T if self.uniform else \
            (self.big @ u).reshape(self.n_act, -1)
        train[np.arange(self.n_act)[:, None], (self.delays[None, :] - self.shifts[:, None]) % self.n] = amplitudes
        return np.fft.irfft(np.fft.rfft(train, axis=-1) * self.taper, self.n, axis=-1) * self.u_scale

    def least_drive(self, min_fidelity: float, *, tol: float, fidelity_margin: float, max_iter: int) -> float:
        """The least peak drive (unit of the drives) that reaches ``min_fidelity`` at the
        target's amplitude: ``min max|x|`` s.t. ``b.u = 1``, ``||Lt u|| <= cap``, by the same
        constraint generation on the drive samples (no peak rows: a small program)."""
        asked = min(min_fidelity + fidelity_margin, (1 + min_fidelity) / 2)
        cap = 1.0 / asked
        if self.best_fidelity**-2 >= cap**2 * (1 - 1e-9):
            raise InfeasibleDesignError("the minimax program is infeasible: "
                                        + self._support_advice(min_fidelity, asked))
        saved = self.D, self.drive_rows  # its rows stay out of the design's program
        try:
            return self._least_drive(cap, min_fidelity, tol=tol, max_iter=max_iter)
        finally:
            self.D, self.drive_rows = saved

    def _least_drive(self, cap: float, min_fidelity: float, *, tol: float, max_iter: int) -> float:
        x0 = self.drives_of(self.u_best) / self.u_scale
        self._add_drive_rows(self._drive_samples(x0, 0.3 * np.max(np.abs(x0)), 10))
        value = np.nan
        for _ in range(max_iter):
            found, value, status, _ = _solve_in_span(self._per_actuator(self.D), self.b, self.Lt, self.Linv,
                                                     self.N0, cap, None, None, accuracy=_ROUND_ACCURACY * tol,
                                                     norm_cap=_NORM_CAP * float(np.linalg.norm(self.u_best)))
            if found is None or not np.isfinite(value) or "infeasible" in status:
                raise InfeasibleDesignError(f"the least-drive program failed ({status}): "
                                            f"{self._asked(min_fidelity, None)}")
            x = self.drives_of(found) / self.u_scale
            floor = value * (1 + tol)
            if self._add_drive_rows(self._drive_samples(x, floor, 20)) == 0:
                break
        return float(value * self.u_scale)

    def solve(self, min_fidelity: float, *, max_drive: float | None, tol: float, fidelity_margin: float,
              max_iter: int) -> tuple[np.ndarray, float, str, int]:
        """Drives (n_act, n), the program's quiet peak (unit of the targets), the status and
        the rounds, by constraint generation from the constraints listed so far."""
        asked = min(min_fidelity + fidelity_margin, (1 + min_fidelity) / 2)
        cap = 1.0 / asked
        if self.best_fidelity**-2 >= cap**2 * (1 - 1e-9):
            raise InfeasibleDesignError("the minimax program is infeasible: "
                                        + self._support_advice(min_fidelity, asked))
        dcap = None if max_drive is None else max_drive / self.u_scale
        u, value, it, inside, best_value, status = self.u_best.copy(), np.nan, 0, True, 0.0, "optimal"
        accuracy, norm_cap = _ROUND_ACCURACY * tol, _NORM_CAP * float(np.linalg.norm(self.u_best))
        for it in range(1, max_iter + 1):
            D = None if dcap is None else self._per_actuator(self.D)
            r = None if self.rq is None else self.rq[self.listed[:, 0]]
            try:
                if r is None:
                    found, value, status, _ = _solve_in_span(self.A, self.b, self.Lt, self.Linv, self.N0, cap, D, dcap,
                                                             norm_cap=norm_cap, accuracy=accuracy)
                else:
                    found, value, status, _ = _solve_cone(self.A, self.b, self.Lt, cap, D, dcap, r=r,
                                                          norm_cap=norm_cap, accuracy=accuracy)
            except (ValueError, ArithmeticError) as exc:  # cvxopt: "domain error", "Rank(A) < p", singular KKT
                raise InfeasibleDesignError(f"the minimax solver failed numerically at round {it} ({exc}): "
                                            f"{self._asked(min_fidelity, max_drive)}") from None
            if status == "primal infeasible":
                raise InfeasibleDesignError(f"the minimax program is infeasible (min_fidelity={min_fidelity:g}, "
                                      f"max_drive={max_drive}): relax the fidelity or the drive limit")
            if found is None or not np.isfinite(value):
                raise InfeasibleDesignError(f"the minimax solver failed ({status}) at round {it}: "
                                            f"{self._asked(min_fidelity, max_drive)}")
            u = found
            x = self.drives_of(u)
            # The listed rows' (robust) level at this optimum: which rows bind, which are slack.
            level = np.abs(self.A @ u) + (0.0 if r is None else r * np.linalg.norm(u))
            yq = predict_response(self.H[:, self.quiet], x) / self.d_norm
            floor = max(value, 0.0) * (1 + tol) + 1e-9 * np.max(np.abs(self.desired)) / self.d_norm
            # Per quiet point, the nominal level over which a sample breaks the (robust) bound.
            floors = floor - (0.0 if self.rq is None else self.rq * np.linalg.norm(u))
            floors = np.broadcast_to(floors, len(self.quiet))
            peaks = np.max(np.abs(yq), axis=1)
            violated = bool(np.any(peaks > floors))
            # With any sample over, the rows about to bind join too (margin _ADD_MARGIN).
            near = _ADD_MARGIN * floors if violated else floors
            rows = [(int(j), int(t)) for j in np.flatnonzero(peaks > near) for t in _local_peaks(yq[j], near[j], 50)]
            if violated and value > 0:
                # Each new peak's neighbouring samples, and each binding row's, join too: the
                # next optimum slides a peak to the sample beside a bound one (most rows added
                # after the second round lay within a sample of a listed one), and each slide
                # cost a round.
                rows += [(int(j), int(t)) for j, t in self.listed[level >= (1 - tol) * value]]
                rows = [(j, (t + step) % self.n) for j, t in rows for step in (-1, 0, 1)]
            added = new_rows = self._add_pairs(rows)
            if dcap is not None:
                over = np.abs(x) > max_drive * (1 + tol)
                violated = violated or bool(over.any())
                added += self._add_drive_rows(self._drive_samples(np.where(over.any(axis=1)[:, None], x, 0.0),
                                                                  max_drive * (1 + tol), 20))
            if added == 0 or not violated:
                break
            # Rows far below the peak leave the program only when its optimum sets a record
            # (by more than tol: finitely often, so no set of rows comes back for ever); the
            # full response is checked every round.
            slack = level < _DROP * max(value, 0.0)  # the rows listed before this round's
            record, best_value = value > best_value * (1 + tol), max(best_value, value)
            if record and slack.any():
                keep = np.concatenate([~slack, np.ones(new_rows, bool)])
                self.A, self.listed = self.A[keep], self.listed[keep]
        else:
            inside = False
        if not inside:
            raise InfeasibleDesignError(
                f"the minimax design did not converge in max_iter={max_iter} rounds (quiet samples still over the "
                f"program's peak; {len(self.listed)} peak constraints listed): raise max_iter or tol, or "
                f"{self._asked(min_fidelity, max_drive)}")
        if "infeasible" in status:  # the last point the solver gave is no solution
            raise InfeasibleDesignError(f"the minimax solver ended {status} at round {it}: "
                                        f"{self._asked(min_fidelity, max_drive)}")
        # "unknown": the cone solver stopped short of its tolerances (its last point is used).
        final = "optimal" if status == "optimal" else f"inaccurate ({status})"
        return self.drives_of(u), value * self.d_norm, final, it

    def _asked(self, min_fidelity: float, max_drive: float | None) -> str:
        """What to relax, naming the parameters that make the program hard."""
        best = f" (the best this support reaches is {self.best_fidelity:.6g})" if self.best_fidelity < 1 else ""
        parts = [f"min_fidelity={min_fidelity:g}{best}"]
        if max_drive is not None:
            parts.append(f"max_drive={max_drive:g}")
        if self.rq is not None:
            parts.append(f"h_radius (up to {self.rho_max:.3g}, against |H| up to {self.h_max:.3g})")
        capped = f" [size limit: {self.size_limit}]" if self.size_limit else ""
        return "relax " + ", or ".join(parts) + capped

    def design(self, min_fidelity: float, *, max_drive: float | None, full_output: bool, tol: float,
               fidelity_margin: float, max_iter: int,
               on_max_drive: str = "refuse") -> np.ndarray | tuple[np.ndarray, MinimaxReport]:
        min_fidelity = check_in_range(min_fidelity, "min_fidelity", 0.0, 1.0, inclusive=False)
        if max_drive is not None:
            max_drive = check_positive(max_drive, "max_drive")
        tol = check_positive(tol, "tol")
        fidelity_margin = check_positive(fidelity_margin, "fidelity_margin", allow_zero=True)
        max_iter = _check_max_iter(max_iter)
        if on_max_drive not in ("refuse", "least"):
            raise ValidationError(f"on_max_drive must be 'refuse' or 'least', got {on_max_drive!r}")
        least, limited = None, False
        if max_drive is not None:
            # One small program says whether the limit can reach the fidelity at all: no
            # re-solves of the whole program at doubled limits.
            least = self.least_drive(min_fidelity, tol=tol, fidelity_margin=fidelity_margin, max_iter=max_iter)
            if least > max_drive:
                if on_max_drive == "refuse":
                    raise InfeasibleDesignError(
                        f"the minimax program is infeasible: min_fidelity={min_fidelity:g} needs a peak drive of at "
                        f"least {least:.4g} at this tap amplitude, over max_drive={max_drive:g} "
                        f"({least / max_drive:.3g}x)"
                        f"; relax the fidelity or the drive limit, or lower the tap amplitude"
                        + (f" [size limit: {self.size_limit}]" if self.size_limit else ""))
                max_drive, limited = least * _LEAST_DRIVE_ROOM, True
        drives, value, status, it = self.solve(min_fidelity, max_drive=max_drive, tol=tol,
                                               fidelity_margin=fidelity_margin, max_iter=max_iter)
        predicted = predict_response(self.H, drives)
        if max_drive is not None:
            peak = float(np.max(np.abs(drives)))
            if peak > max_drive:  # within tol: trim to the limit exactly
                drives = scale_to_peak(drives, max_drive)
                predicted = predicted * (max_drive / peak)
        yt = predicted[self.ti]
        fid = zero_lag_fidelity(yt, self.desired)
        if not fid >= min_fidelity - _FIDELITY_SLACK:  # the solver's last point misses what it was asked
            raise InfeasibleDesignError(f"the minimax solver's drives reach fidelity {fid:.4g}, below the asked "
                                        f"{min_fidelity:g} (solver status {status}): "
                                        f"{self._asked(min_fidelity, max_drive)}")
        if not full_output:
            return drives
        qpeak = float(np.max(np.abs(predicted[self.quiet])))
        tpeak = float(np.max(np.abs(yt)))
        report = MinimaxReport(
            predicted=predicted, desired=self.desired, target_index=self.ti, quiet=self.quiet, fidelity=fid,
            peak_contrast_db=float(20 * np.log10(tpeak / qpeak)) if qpeak > 0 else float("inf"),
            quiet_peak=qpeak, model_quiet_peak=value, peak_drive=float(np.max(np.abs(drives))),
            status=str(status), solver="cvxopt.conelp", iterations=it, n_constraints=len(self.listed),
            n_variables=self.A.shape[1], ir_taps=self.ir_taps, ir_energy_left_out=self.left_out,
            ir_tail_energy=self.tail, support=(int(self.delays[0]), int(self.delays[-1])),
            decimation=self.decimation, least_drive=least, drive_limited=limited, size_limit=self.size_limit,
            support_shift=self.shifts.copy(), pulse_spacing=self.every * self.decimation)
        return drives, report


def minimax_frontier(H: Any, targets: Any, fs: float, fidelities: Any, *, band: tuple[float, float] = BAND_HZ,
                     max_drive: float | None = None, quiet: Any = None, **options: Any) -> MinimaxFrontier:
    """The peak-contrast frontier: :func:`minimax_filter` at each of ``fidelities``.

    One set-up (basis, target norm, impulse responses) serves every fidelity, and each
    design starts from the peak constraints the last one found.

    Parameters
    ----------
    H, targets, fs, band, max_drive, quiet
        As in :func:`minimax_filter`.
    fidelities : sequence of float, shape (k,)
        Least fidelities, each in (0, 1).
    **options
        The other keywords of :func:`minimax_filter` (``support_s``, ``tol``, ...), but
        ``full_output`` and ``min_fidelity``.

    Returns
    -------
    MinimaxFrontier
        NaN where a fidelity is above the best the support reaches (or the drive limit
        rules it out).
    """
    import time

    fids = as_array(fidelities, "fidelities", ndim=1)
    for f in fids:
        check_in_range(float(f), "fidelities", 0.0, 1.0, inclusive=False)
    unknown = set(options) - {*_SETUP_KEYS, *_SOLVE_KEYS}
    if unknown:
        raise ValidationError(f"minimax_frontier got unknown options {sorted(unknown)}")
    defaults = inspect.signature(minimax_filter).parameters
    chosen = {k: options.get(k, defaults[k].default) for k in (*_SETUP_KEYS, *_SOLVE_KEYS)}
    setup = {k: chosen[k] for k in _SETUP_KEYS}
    solve = {k: chosen[k] for k in _SOLVE_KEYS}
    start = time.perf_counter()
    out = np.full((3, fids.size), np.nan)
    with _single_threaded_blas():
        program = _Program(H, targets, fs, band=band, quiet=quiet, **setup)
        for i, f in enumerate(fids):
            try:
                _, rep = program.design(float(f), max_drive=max_drive, full_output=True, **solve)
            except InfeasibleDesignError:
                continue
            out[:, i] = rep.fidelity, rep.peak_contrast_db, rep.quiet_peak
    return MinimaxFrontier(min_fidelity=fids, fidelity=out[0], peak_contrast_db=out[1], quiet_peak=out[2],
                           seconds=time.perf_counter() - start)
