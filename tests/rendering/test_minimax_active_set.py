"""minimax_filter's active set against the full program (every quiet sample a constraint),
named size limits, and the drive limit: kept, or refused naming the drive it needs."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("cvxopt")

from vibrofocus.errors import InfeasibleDesignError  # noqa: E402
from vibrofocus.rendering import minimax, minimax_filter, response_timing  # noqa: E402
from vibrofocus.rendering.minimax import _Program, _solve_cone  # noqa: E402

FS, N, BAND = 2000.0, 256, (20.0, 300.0)
SUPPORT = (0.02, 0.01)
TOL = 1e-3  # minimax_filter's default constraint-generation tolerance


def medium(n_points=4, n_act=2, taps=24, seed=0):
    """A random causal medium: decaying FIR impulse responses, as H (n // 2 + 1, points, actuators)."""
    rng = np.random.default_rng(seed)
    h = rng.standard_normal((n_points, n_act, taps)) * np.exp(-np.arange(taps) / 6.0)
    return np.fft.rfft(h, N, axis=-1).transpose(2, 0, 1)


def tap(n_points=4):
    t = np.arange(N) / FS
    a = ((t - N / FS / 2) / 4e-3) ** 2
    targets = np.zeros((n_points, N))
    targets[0] = (1 - a) * np.exp(-a / 2)
    return targets


def full_program(H, targets, min_fidelity, max_drive=None, margin=1e-3):
    """The same program with every (quiet point, sample) peak constraint and every drive sample
    of the window listed: its optimum (unit of the targets)."""
    p = _Program(H, targets, FS, band=BAND, quiet=None, taper_octaves=0.5, support_s=SUPPORT, stride=32,
                 ir_energy_tol=1e-4, decimation=None)
    p._add_pairs([(j, t) for j in range(len(p.quiet)) for t in range(N)])
    cap = 1 / min(min_fidelity + margin, (1 + min_fidelity) / 2)
    D = dcap = None
    if max_drive is not None:
        p._add_drive_rows(np.arange(N))
        D, dcap = p._per_actuator(p.D).toarray(), max_drive / p.u_scale
    u, value, status, _ = _solve_cone(p.A, p.b, p.Lt, cap, D, dcap)
    assert status == "optimal"
    return value * p.d_norm


@pytest.mark.parametrize("seed, stride, limit", [(0, 32, None), (1, 1000, None), (2, 1000, 0.9)])
def test_active_set_reaches_the_full_programs_optimum(seed, stride, limit):
    """Listing only the constraints that bind gives the full program's optimum, and the design
    meets every constraint of the full program (to the tolerance)."""
    H, targets = medium(seed=seed), tap()
    if limit is not None:  # a drive limit that binds: 0.9 of the free design's peak
        limit *= float(np.max(np.abs(minimax_filter(H, targets, FS, band=BAND, min_fidelity=0.9, support_s=SUPPORT))))
    drives, rep = minimax_filter(H, targets, FS, band=BAND, min_fidelity=0.9, support_s=SUPPORT, stride=stride,
                                 max_drive=limit, full_output=True)
    full = full_program(H, targets, 0.9, max_drive=limit)
    assert rep.n_constraints < 0.5 * 3 * N  # the active set is a fraction of the full program's rows
    assert rep.model_quiet_peak == pytest.approx(full, rel=2 * TOL)
    # Every full constraint holds: the quiet peak over the whole window, the fidelity, the drive.
    assert np.max(np.abs(rep.predicted[1:])) <= full * (1 + 2 * TOL)
    assert rep.fidelity >= 0.9 - 1e-4
    if limit is not None:
        assert np.max(np.abs(drives)) <= limit * (1 + 1e-9)


def test_a_size_limit_that_cuts_the_support_is_named(monkeypatch):
    """The default support cut to MAX_VARIABLES is in the report and in a refusal, not silent."""
    H, targets = medium(), tap()
    _, rep = minimax_filter(H, targets, FS, band=BAND, min_fidelity=0.9, full_output=True)
    assert rep.size_limit is None
    monkeypatch.setattr(minimax, "MAX_VARIABLES", 24)  # 12 pulses per actuator: under the default's 10 ms
    _, rep = minimax_filter(H, targets, FS, band=BAND, min_fidelity=0.9, full_output=True)
    assert rep.n_variables <= 24
    assert "shortened" in rep.size_limit and "MAX_VARIABLES=24" in rep.size_limit
    with pytest.raises(InfeasibleDesignError, match=r"size limit: .*MAX_VARIABLES=24"):
        minimax_filter(H, targets, FS, band=BAND, min_fidelity=0.9999)


def test_a_drive_limit_is_kept_or_refused_naming_the_drive_it_needs():
    H, targets = medium(seed=3), tap()
    free = float(np.max(np.abs(minimax_filter(H, targets, FS, band=BAND, min_fidelity=0.9, support_s=SUPPORT))))
    low = 1e-3 * free
    with pytest.raises(InfeasibleDesignError, match=r"needs a peak drive of at least [0-9.e+-]+ at this tap "
                                                    r"amplitude, over max_drive="):
        minimax_filter(H, targets, FS, band=BAND, min_fidelity=0.9, support_s=SUPPORT, max_drive=low)
    drives, rep = minimax_filter(H, targets, FS, band=BAND, min_fidelity=0.9, support_s=SUPPORT, max_drive=low,
                                 on_max_drive="least", full_output=True)
    assert rep.drive_limited and rep.least_drive > 100 * low
    assert rep.least_drive <= free * (1 + 1e-3)  # no drive reaches the fidelity with less
    assert np.max(np.abs(drives)) <= rep.least_drive * 2 * (1 + 1e-9)
    assert rep.fidelity >= 0.9 - 1e-4
    _, kept = minimax_filter(H, targets, FS, band=BAND, min_fidelity=0.9, support_s=SUPPORT, max_drive=2 * free,
                             on_max_drive="least", full_output=True)
    assert not kept.drive_limited and kept.peak_drive <= 2 * free * (1 + 1e-9)


@pytest.mark.slow
def test_the_method_says_what_a_design_over_its_drive_budget_costs():
    """The reference medium's location 5 needs 1.3x the pseudo-inverse's drive at its fidelity:
    it used to be re-solved at 2x the budget without a word (and dropped past 4x)."""
    from vibrofocus import ArrayLayout, TransferMatrix, render

    from ._media import FS as MFS
    from ._media import layout_medium

    ref = ArrayLayout.reference()
    tm = TransferMatrix(layout_medium(ref, 2048, MFS), MFS, ref)
    with pytest.warns(UserWarning, match=r"needs a peak drive of [0-9.]+ V for the 2 um tap, [0-9.]+x the drive "
                                         r"budget .* at limit_v=10 V its tap peaks at [0-9.]+ um with -?[0-9.]+ dB "
                                         r"peak contrast, the inverse filter's at [0-9.]+ um with -?[0-9.]+ dB"):
        design = render("minimax", tm, MFS, ref, 5)
    assert np.max(np.abs(design.drives)) == pytest.approx(10.0)


def cvxpy_program(A, b, Lt, cap, D, dcap):
    """The same rows as an independent cvxpy + Clarabel program: its optimum."""
    cp = pytest.importorskip("cvxpy")
    u, t = cp.Variable(A.shape[1]), cp.Variable()
    cons = [cp.abs(A @ u) <= t, b @ u == 1, cp.norm(Lt @ u) <= cap]
    if D is not None:
        cons.append(cp.abs(D @ u) <= dcap)
    cp.Problem(cp.Minimize(t), cons).solve(solver="CLARABEL")
    return float(t.value)


@pytest.mark.parametrize("limit", [None, 0.9])
def test_the_program_on_the_rows_span_has_the_full_programs_optimum(limit):
    """Few rows (fewer than the coefficients): the program in the span of the listed rows
    has the optimum of the program over every coefficient, as an independent cvxpy
    program finds it (rel. 1e-5), and its point meets that program's constraints; the
    structured KKT solver (drive rows outnumbering the peak rows) finds it too."""
    from vibrofocus.rendering.minimax import _solve_in_span

    H, targets = medium(n_points=9, n_act=1, seed=4), tap(n_points=9)
    p = _Program(H, targets, FS, band=BAND, quiet=None, taper_octaves=0.5, support_s=SUPPORT, stride=1000,
                 ir_energy_tol=1e-4, decimation=None)
    p._add_pairs([(j, t) for j in range(len(p.quiet)) for t in range(0, N, 2)])
    rows = p.A[np.random.default_rng(0).choice(len(p.A), 10, replace=False)]
    cap = 1 / 0.9
    D = dcap = None
    if limit is not None:  # a drive limit that binds: 0.9 of the free design's peak drive
        u, _, _, _ = _solve_cone(rows, p.b, p.Lt, cap, None, None)
        p.D, p.drive_rows = p.D[:0], p.drive_rows[:0]  # a few drive rows of its own
        p._add_drive_rows(np.arange(0, N, 16))
        D = p._per_actuator(p.D).toarray()
        dcap = limit * float(np.max(np.abs(D @ u)))
    n_rows = len(rows) + (0 if D is None else len(D))
    assert n_rows + 1 < p.Lt.shape[0] and p.N0.shape[1] == 0  # the span is smaller
    reference = cvxpy_program(rows, p.b, p.Lt, cap, D, dcap)
    assert reference > 0.1  # a program whose rows bind
    blocks = None if D is None else p._per_actuator(p.D)
    u, value, status, _ = _solve_in_span(rows, p.b, p.Lt, p.Linv, p.N0, cap, blocks, dcap)
    assert status == "optimal"
    assert value == pytest.approx(reference, rel=1e-5)
    # The point found meets the full program's constraints, in the original coefficients.
    assert np.max(np.abs(rows @ u)) <= value * (1 + 1e-6)
    assert p.b @ u == pytest.approx(1.0, rel=1e-7)
    assert np.linalg.norm(p.Lt @ u) <= cap * (1 + 1e-6)
    if D is not None:
        assert np.max(np.abs(D @ u)) <= dcap * (1 + 1e-6)
        _, whole, status, _ = _solve_cone(rows, p.b, p.Lt, cap, blocks, dcap)  # the structured KKT
        assert status == "optimal" and whole == pytest.approx(reference, rel=1e-5)


def test_a_structured_solve_that_breaks_down_goes_to_cvxopts_cholesky_not_the_ldl(monkeypatch):
    """The structured KKT's normal equations can break down ("domain error": 13 of the OSC
    tests' 140 solves); CVXOPT's own Cholesky then solves the same program in a fraction of
    the regularized LDL's time (0.15 s against 5-11 s a solve there)."""
    from cvxopt import solvers

    H, targets = medium(seed=2), tap()
    p = _Program(H, targets, FS, band=BAND, quiet=None, taper_octaves=0.5, support_s=SUPPORT, stride=32,
                 ir_energy_tol=1e-4, decimation=None)
    p._add_pairs([(j, t) for j in range(len(p.quiet)) for t in range(0, N, 8)])
    p._add_drive_rows(np.arange(N))
    blocks, cap = p._per_actuator(p.D), 1 / 0.9
    assert blocks.shape[0] > p.A.shape[0]  # the structured KKT's case
    free = _solve_cone(p.A, p.b, p.Lt, cap, None, None)[0]
    dcap = 0.9 * float(np.max(np.abs(blocks.toarray() @ free)))
    _, expected, status, _ = _solve_cone(p.A, p.b, p.Lt, cap, blocks, dcap)
    assert status == "optimal"

    def broken(*args):
        def factor(W):
            raise ValueError("domain error")
        return factor

    used, conelp = [], solvers.conelp
    monkeypatch.setattr(minimax, "_structured_kkt", broken)
    monkeypatch.setattr(solvers, "conelp", lambda *a, kktsolver=None, **k: used.append(
        kktsolver if isinstance(kktsolver, str) else "structured") or conelp(*a, kktsolver=kktsolver, **k))
    _, value, status, _ = _solve_cone(p.A, p.b, p.Lt, cap, blocks, dcap)
    assert used == ["structured", "chol"]
    assert status == "optimal" and value == pytest.approx(expected, rel=1e-5)


def test_the_least_drive_program_lists_every_binding_drive_sample_at_once(monkeypatch):
    """The least peak drive binds at most drive samples: the first program lists every sample
    the pulses reach, so it is solved once (it added some 20 samples a round, six to eight
    rounds on the 2x3 sleeve), with the optimum of the program over every sample of the window."""
    H, targets = medium(seed=3), tap()
    p = _Program(H, targets, FS, band=BAND, quiet=None, taper_octaves=0.5, support_s=SUPPORT, stride=32,
                 ir_energy_tol=1e-4, decimation=None)
    whole = p._per_actuator(np.stack([np.roll(p.pulse, k) for k in p.delays], axis=1))  # every sample
    cap = 1 / (0.9 + 1e-3)
    # The reference: the same program over every sample, by another solver (Clarabel through
    # cvxpy; CVXOPT's structured steps can end "unknown" at its optimum on this one).
    cp = pytest.importorskip("cvxpy")
    u = cp.Variable(p.b.size)
    program = cp.Problem(cp.Minimize(cp.norm(whole.toarray() @ u, "inf")),
                         [p.b @ u == 1, cp.norm(p.Lt @ u) <= cap])
    program.solve(solver="CLARABEL")
    assert program.status == "optimal"
    value = program.value
    solves = []
    counted = minimax._solve_cone
    monkeypatch.setattr(minimax, "_solve_cone", lambda *a, **k: solves.append(1) or counted(*a, **k))
    least = p.least_drive(0.9, tol=TOL, fidelity_margin=1e-3, max_iter=30)
    assert len(solves) == 1
    assert least == pytest.approx(value * p.u_scale, rel=TOL)


def test_the_row_operator_is_the_dense_programs_g():
    """The structured solver's G (products by blocks: a drive row touches one actuator, in its
    own basis: actuators 0 and 2 with 4 coefficients, 1 with 2) gives the dense G's products,
    both ways."""
    rng = np.random.default_rng(5)
    K, nv = 6, 10
    peak, E = rng.standard_normal((7, nv)), rng.standard_normal((7, 2))
    groups = [(np.array([0, 2]), rng.standard_normal((K, 4)), np.array([0, 6])),
              (np.array([1]), rng.standard_normal((K, 2)), np.array([4]))]
    drive = minimax._PerActuator(rng.standard_normal((5, K)), groups, nv)
    cones = [rng.standard_normal((6, nv + 2))]
    pairs = [(peak, E), (drive, np.zeros((drive.shape[0], 2)))]
    G = np.vstack([np.hstack([(M.toarray() if hasattr(M, "toarray") else M) * s, Ep])
                   for M, Ep in pairs for s in (1.0, -1.0)] + cones)
    op = minimax._RowOperator(pairs, cones, nv)
    x, z = rng.standard_normal(nv + 2), rng.standard_normal(G.shape[0])
    np.testing.assert_allclose(op.dot(x), G @ x, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(op.tdot(z), G.T @ z, rtol=1e-12, atol=1e-12)


def far_medium(delays_s=(0.001, 0.001, 0.010, 0.014, 0.018, 0.022), n_points=10, seed=6):
    """A medium whose actuators' waves reach the points after their own delay (s, and up to
    1.5 ms more by point): decaying 150 Hz wavelets of random amplitude and phase."""
    rng = np.random.default_rng(seed)
    lag = np.arange(N)[None, None] - np.round((np.asarray(delays_s)[None, :, None]
                                                + rng.uniform(0, 1.5e-3, (n_points, len(delays_s), 1))) * FS)
    amp, phase = rng.uniform(0.5, 1.5, (2, n_points, len(delays_s), 1)) * np.array([1, np.pi])[:, None, None, None]
    h = np.where(lag >= 0, amp * np.exp(-np.clip(lag, 0, None) / 8.0) * np.cos(2 * np.pi * 150 * lag / FS + phase), 0)
    return np.fft.rfft(h, N, axis=-1).transpose(2, 0, 1)


def test_per_actuator_supports_reach_the_far_actuators_that_a_cut_support_leaves_out(monkeypatch):
    """Where one default support from the latest arrival exceeds MAX_VARIABLES, each actuator's
    pulses sit its own arrival earlier (named in the report) instead of one support cut short
    of the far actuators' arrival: the design's peak contrast beats the cut support's."""
    H, targets = far_medium(), tap(n_points=10)
    monkeypatch.setattr(minimax, "MAX_VARIABLES", 120)  # 20 pulses per actuator: a 19 ms common support
    _, rep = minimax_filter(H, targets, FS, band=BAND, min_fidelity=0.9, full_output=True)
    assert "per-actuator supports" in rep.size_limit and "MAX_VARIABLES=120" in rep.size_limit
    arrival = response_timing(H, FS, band=BAND).arrival_s[0]
    np.testing.assert_array_equal(rep.support_shift, np.round((arrival - arrival.min()) * FS))  # its arrival earlier
    assert rep.support_shift[-1] > rep.support_shift[0]
    assert rep.n_variables <= 120 and np.all(rep.pulse_spacing == rep.decimation)
    cut = minimax._Program._fit_support((0.044, 0.005), 6, rep.decimation, FS)  # the old default
    assert cut[0] < 0.014  # shorter than the far actuators' arrival
    _, old = minimax_filter(H, targets, FS, band=BAND, min_fidelity=0.9, support_s=cut, full_output=True)
    assert rep.fidelity >= 0.9 - 1e-3
    assert rep.peak_contrast_db > old.peak_contrast_db + 1.0


def test_weak_actuators_pulses_spaced_wider_are_named(monkeypatch):
    """Over SPREAD_VARIABLES the weak actuators (under 10 % of the strongest's energy at the
    target) space their pulses wider: in the report's size limit and pulse spacing."""
    H, targets = far_medium(), tap(n_points=10)
    H[:, :, 2:] *= 0.1  # the four far actuators weak
    monkeypatch.setattr(minimax, "MAX_VARIABLES", 120)
    monkeypatch.setattr(minimax, "SPREAD_VARIABLES", 64)
    _, rep = minimax_filter(H, targets, FS, band=BAND, min_fidelity=0.9, full_output=True)
    assert rep.n_variables <= 64
    assert np.all(rep.pulse_spacing[:2] == rep.decimation) and np.all(rep.pulse_spacing[2:] > rep.decimation)
    assert "SPREAD_VARIABLES=64" in rep.size_limit and "4 actuators" in rep.size_limit
    assert rep.fidelity >= 0.9 - 1e-3


def test_the_structured_solvers_step_limit_keeps_the_optimum(monkeypatch):
    """A drive limit binding over the support (twice the least drive) goes to the structured
    KKT solver, whose steps end at _STRUCTURED_MAXITERS: the same design as without the limit."""
    H, targets = medium(seed=3), tap()

    def design():
        return minimax_filter(H, targets, FS, band=BAND, support_s=SUPPORT, min_fidelity=0.9, max_drive=1e-9,
                              on_max_drive="least", full_output=True)[1]

    capped = design()
    monkeypatch.setattr(minimax, "_STRUCTURED_MAXITERS", 100)
    free = design()
    assert capped.drive_limited and free.drive_limited
    assert capped.model_quiet_peak == pytest.approx(free.model_quiet_peak, rel=TOL)
    assert capped.peak_contrast_db == pytest.approx(free.peak_contrast_db, abs=0.01)
