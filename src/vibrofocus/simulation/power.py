"""Study power by simulation (``vibrofocus power``), on Dask.

For a design (participants N, repetitions, methods, locations) and the perceptual model
(its effect sizes are those of the perceptual model as fitted, see
``docs/simulated-participants.md``), many studies are simulated per N with the fast path
(:func:`~vibrofocus.simulation.bank.simulate_cell_means`) and analysed with the vectorized
statistics (:mod:`vibrofocus.analysis.fast`); the power of each test of docs/method.md (Analysis) is the
share of studies in which it is significant. Simulated participants: a model, not data.

Every study ``j`` of sample size ``N`` draws from its own generator
``numpy.random.default_rng([seed, N, j])``: results do not depend on how studies are
split into tasks, nor on the scheduler (one process, a LocalCluster or a cluster).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import stats

from ..defaults import STUDY_METHODS
from ..errors import ValidationError
from .bank import FeatureBank, StudyArrays, default_bank, simulate_cell_means
from .perception import PerceptualModel

__all__ = ["TESTS", "DIRECTIONAL_TESTS", "REVERSE_TESTS", "CONTRASTS", "ROBUST_POWER", "robust_conclusions",
           "directional_shares", "effect_directions", "direction_sentences", "paper_implied_power",
           "paper_implied_wilcoxon_power", "PowerDesign",
           "study_statistics", "simulate_statistics", "power_table", "run_power", "dask_client"]

#: The tests of docs/method.md (Analysis) whose power is reported: (key, description).
TESTS: tuple[tuple[str, str], ...] = (
    ("s1_location", "Study 1 RM-ANOVA, location (GG)"),
    ("s1_method", "Study 1 RM-ANOVA, method (GG)"),
    ("s1_interaction", "Study 1 RM-ANOVA, location x method (GG)"),
    ("s2_location", "Study 2 Friedman, location"),
    ("s2_method", "Study 2 Friedman, method"),
    ("s2_hit_location", "Study 2 Friedman, location (trials containing the target)"),
    ("s2_hit_method", "Study 2 Friedman, method (trials containing the target)"),
)
#: The paper's directional claims (Sec. III.B-C), reported beside the omnibus tests: an
#: omnibus test is significant whichever method wins, these only in the paper's direction.
#: They need funneling and the inverse filter among the methods.
DIRECTIONAL_TESTS: tuple[tuple[str, str], ...] = (
    ("s1_inverse_below", "Study 1 inverse error below funneling (Bonferroni paired t; the paper's direction)"),
    ("s2_inverse_fewer", "Study 2 fewer points with the inverse filter (Bonferroni Wilcoxon; the paper's direction)"),
)
#: The same tests significant in the reverse direction: a hypothesis can predict the
#: opposite of the paper, and "not significant in the paper's direction" does not say so.
REVERSE_TESTS: tuple[tuple[str, str], ...] = (
    ("s1_inverse_above", "Study 1 funneling error below inverse (Bonferroni paired t; the reverse)"),
    ("s2_inverse_more", "Study 2 fewer points with funneling (Bonferroni Wilcoxon; the reverse)"),
)
#: The paper's two method contrasts, inverse filter vs funneling: per contrast, its label,
#: the tests significant in the paper's direction and in the reverse, the omnibus test whose
#: post hoc direction it is, and how each direction reads.
CONTRASTS: dict[str, dict[str, str]] = {
    "s1_inverse_vs_funneling": {
        "label": "the Study 1 method effect (error)", "paper": "s1_inverse_below", "reverse": "s1_inverse_above",
        "omnibus": "s1_method", "paper_reads": "inverse < funneling",
        "reverse_reads": "funneling < inverse"},
    "s2_inverse_vs_funneling": {
        "label": "the Study 2 method effect (points selected)", "paper": "s2_inverse_fewer", "reverse": "s2_inverse_more",
        "omnibus": "s2_method", "paper_reads": "inverse < funneling",
        "reverse_reads": "funneling < inverse"},
}
#: The paper's Bonferroni-corrected p of funneling vs inverse in Study 1 (Sec. III.B), of
#: 3 method pairs, with 20 participants.
PAPER_S1_PAIR_P = 0.007
PAPER_S1_PAIRS = 3
#: The paper's Bonferroni-corrected p of funneling vs inverse in Study 2 (Sec. III.C:
#: fewer points selected with the inverse filter, Wilcoxon signed-rank), of 3 method pairs.
PAPER_S2_PAIR_P = 0.013
PAPER_S2_PAIRS = 3
PAPER_N = 20


#: Largest sample size N of a power analysis (memory grows with N x studies).
MAX_PARTICIPANTS = 1000
#: Most simulated studies per N.
MAX_STUDIES = 100_000
#: Most trials per condition and study.
MAX_REPETITIONS = 100
#: Seconds to wait for a Dask scheduler given by address.
SCHEDULER_TIMEOUT_S = 5


@dataclass(frozen=True)
class PowerDesign:
    """A study design for power analysis.

    Attributes
    ----------
    n_participants : tuple of int
        Sample sizes N to evaluate.
    n_studies : int
        Simulated studies per N.
    repetitions : int
        Trials per condition and study.
    methods : tuple of str or None
        Registered methods, each in the feature bank (default the bank's; the shipped
        bank has funneling, inverse and combination, and one built with
        ``scripts/build_feature_bank.py --methods`` may have others, such as minimax).
    locations : tuple of int or None
        Location numbers (default 1..9).
    alpha : float
        Significance level.
    seed : int
        Master seed.
    model : PerceptualModel or None
        The perceptual model (its effect sizes); None: the hypothesis' fitted model.
    hypothesis : str or None
        How the simulated participants read the felt field
        (:mod:`vibrofocus.simulation.hypotheses`; None: the default hypothesis).
    level_db : float
        Level of every stimulus, dB re the feature bank's level rule (0: the bank's own;
        :meth:`~vibrofocus.simulation.bank.FeatureBank.at_level`).
    """

    n_participants: tuple[int, ...] = (10, 15, 20, 25, 30)
    n_studies: int = 200
    repetitions: int = 3
    methods: tuple[str, ...] | None = None
    locations: tuple[int, ...] | None = None
    alpha: float = 0.05
    seed: int = 0
    model: PerceptualModel | None = None
    hypothesis: str | None = None
    level_db: float = 0.0

    def __post_init__(self) -> None:
        from .._validation import shorten
        from ..layout import ArrayLayout
        from .bank import check_level_db
        from .hypotheses import hypothesis as find_hypothesis

        object.__setattr__(self, "hypothesis", find_hypothesis(self.hypothesis).name)
        object.__setattr__(self, "level_db", check_level_db(self.level_db, "level_db"))

        ns = tuple(int(n) for n in self.n_participants)
        if not ns or min(ns) < 3 or max(ns) > MAX_PARTICIPANTS:
            raise ValidationError(f"n_participants must be sample sizes from 3 (the RM-ANOVA needs 3) to "
                                  f"{MAX_PARTICIPANTS}, got {shorten(ns)}")
        object.__setattr__(self, "n_participants", ns)
        for name, value, lo, hi in (("n_studies", self.n_studies, 1, MAX_STUDIES),
                                    ("repetitions", self.repetitions, 1, MAX_REPETITIONS)):
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not lo <= value <= hi:
                raise ValidationError(f"{name} must be an integer from {lo} to {hi}, got {shorten(value)}")
        if not 0 < self.alpha < 1:
            raise ValidationError(f"alpha must be in (0, 1), got {self.alpha!r}")
        if self.methods is not None:
            from ..rendering.registry import available_methods

            known = available_methods()
            unknown = [m for m in self.methods if m not in known]
            if unknown:
                raise ValidationError(f"methods: unknown method(s) {shorten(unknown)}; registered: {', '.join(known)}")
            if len(set(self.methods)) != len(self.methods):
                raise ValidationError(f"methods: each method once, got {shorten(self.methods)}")
            if len(self.methods) < 2:
                raise ValidationError("at least 2 methods are needed")
        if self.locations is not None:
            n_loc = ArrayLayout.reference().n_locations
            outside = [x for x in self.locations if not 1 <= x <= n_loc]
            if outside:
                raise ValidationError(f"locations: {shorten(outside)} outside the location numbers 1 to {n_loc}")
            if len(set(self.locations)) != len(self.locations):
                raise ValidationError(f"locations: each location once, got {shorten(self.locations)}")
            if len(self.locations) < 2:
                raise ValidationError("at least 2 locations are needed")


def _paired_t_p(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    from ..analysis.fast import t_sf  # not at import: vibrofocus.analysis draws (matplotlib)

    d = x - y
    n = d.shape[0]
    sd = d.std(axis=0, ddof=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        t = d.mean(axis=0) / (sd / np.sqrt(n))
    p = 2 * t_sf(np.abs(t), n - 1)
    return np.where(sd > 0, p, 1.0)


#: Largest sample that scipy's ``wilcoxon`` tests with ties or zeros by an exact permutation
#: test (its ``method="auto"``: 2**13 sign flips are fewer than its 9999 resamples).
_WILCOXON_PERMUTATION_N = 13


def _wilcoxon_p(x: np.ndarray, y: np.ndarray) -> float:
    """Two-sided Wilcoxon signed-rank p of paired samples (1 when they never differ).

    ``scipy.stats.wilcoxon(x, y).pvalue``, bit for bit. Where scipy runs its exact
    permutation test (at most 13 pairs, with ties or zeros) it evaluates the statistic one
    sign flip at a time (about 1 ms each, 2**n of them); here the same
    ``scipy.stats.permutation_test`` gets the statistic vectorized: the ranks of ``|x - y|``
    are the same under every sign flip, so R+ is a sum of fixed ranks (half-integers: exact
    in any order), and the p value is scipy's own count of the same null distribution.
    """
    d = np.asarray(x, dtype=float) - np.asarray(y, dtype=float)
    nonzero = d != 0
    n_nonzero = int(np.count_nonzero(nonzero))
    if n_nonzero < 2:
        return 1.0
    ties = np.unique(np.abs(d[nonzero])).size < n_nonzero
    if d.ndim != 1 or d.size > _WILCOXON_PERMUTATION_N or not (ties or n_nonzero < d.size):
        return float(stats.wilcoxon(x, y).pvalue)
    ranks = np.zeros(d.size)
    ranks[nonzero] = stats.rankdata(np.abs(d[nonzero]))

    def r_plus(signed: np.ndarray, axis: int = -1) -> np.ndarray:
        return np.sum((signed > 0) * ranks, axis=axis)

    return float(stats.permutation_test((d,), r_plus, permutation_type="samples", vectorized=True,
                                        n_resamples=9999, alternative="two-sided", axis=-1).pvalue)


def _marginal_means(cells: np.ndarray, axis: int) -> np.ndarray:
    """Per-participant means over ``axis`` of the cells that have trials (NaN where none has)."""
    with np.errstate(invalid="ignore", divide="ignore"):
        n = np.sum(np.isfinite(cells), axis=axis)
        return np.where(n > 0, np.nansum(cells, axis=axis) / np.maximum(n, 1), np.nan)


def study_statistics(
    arrays: StudyArrays, alpha: float = 0.05, methods: Sequence[str] | None = None
) -> dict[str, Any]:
    """The statistics of docs/method.md (Analysis) for one simulated study (fast path).

    Parameters
    ----------
    arrays : StudyArrays
        Cell means of one study.
    alpha : float
        Significance level of the post hoc tests.
    methods : sequence of str, optional
        Names of the methods along the arrays' last axis (default: the studies' three,
        when there are three). The method-specific rows (funneling vs inverse) need them.

    Returns
    -------
    dict
        ``s1_*``: ``F``, ``p`` (GG-corrected), ``eps``, ``p_mauchly`` per effect
        (``location``, ``method``, ``interaction``); ``s1_error_by_method`` (n_methods,) and
        ``s1_error_by_location`` (n_locations,), mm; ``s1_interaction_locations``: locations
        (0-based) with a Bonferroni-significant paired t-test between some methods;
        ``s2_*`` / ``s2_hit_*``: ``chi2``, ``p`` of the Friedman tests; the target-containing
        tests (``s2_hit_*``) run on per-participant marginal means over the other factor,
        and ``s2_hit_n_location`` / ``s2_hit_n_method`` (``s2_hit_n``: the smaller) count
        the participants they keep. With funneling and inverse among ``methods``:
        ``s1_method_pairs`` (Bonferroni p of each method pair, by ``"a vs b"``),
        ``s1_only_funneling_vs_inverse`` (only that pair significant, inverse lower),
        ``s1_inverse_differs_locations`` (0-based locations where the inverse differs from
        every other method), ``s2_reduction`` (1 - inverse / funneling mean count),
        ``s2_inverse_fewer`` (Bonferroni Wilcoxon significant, inverse lower), and the
        directional claims' p values of :data:`DIRECTIONAL_TESTS` (``s1_inverse_below_p``,
        ``s2_inverse_fewer_p``: the Bonferroni p where the inverse filter is on the paper's
        side, else 1) and of :data:`REVERSE_TESTS` (``s1_inverse_above_p``,
        ``s2_inverse_more_p``: the same where funneling is on the paper's side).
    """
    from ..analysis.fast import friedman_batch, rm_anova2_batch

    out: dict[str, Any] = {}
    a = rm_anova2_batch(arrays.error_mm[None])
    for j, eff in enumerate(("location", "method", "interaction")):
        out[f"s1_{eff}_F"] = float(a["F"][0, j])
        out[f"s1_{eff}_p"] = float(a["p_gg"][0, j])
        out[f"s1_{eff}_eps"] = float(a["eps"][0, j])
        out[f"s1_{eff}_p_mauchly"] = float(a["p_mauchly"][0, j])
    out["s1_error_by_method"] = arrays.error_mm.mean(axis=(0, 1))
    out["s1_error_by_location"] = arrays.error_mm.mean(axis=(0, 2))
    e = arrays.error_mm
    n_m = e.shape[2]
    pairs = [(i, j) for i in range(n_m) for j in range(i + 1, n_m)]
    pair_p = {(i, j): np.minimum(_paired_t_p(e[:, :, i], e[:, :, j]) * len(pairs), 1.0) for i, j in pairs}
    sig = np.zeros(e.shape[1], dtype=bool)
    for p_loc in pair_p.values():
        sig |= p_loc < alpha
    out["s1_interaction_locations"] = np.flatnonzero(sig)
    for prefix, c in (("s2", arrays.count), ("s2_hit", arrays.count_hit)):
        for factor, axis in (("location", 2), ("method", 1)):
            m = _marginal_means(c, axis)
            keep = np.all(np.isfinite(m), axis=1)
            out[f"{prefix}_n_{factor}"] = int(keep.sum())
            if keep.sum() < 2:
                out[f"{prefix}_{factor}_chi2"], out[f"{prefix}_{factor}_p"] = np.nan, np.nan
                continue
            f = friedman_batch(m[keep][None])
            out[f"{prefix}_{factor}_chi2"] = float(f["chi2"][0])
            out[f"{prefix}_{factor}_p"] = float(f["p"][0])
        out[f"{prefix}_n"] = min(out[f"{prefix}_n_location"], out[f"{prefix}_n_method"])
    names = tuple(methods) if methods is not None else (STUDY_METHODS if n_m == len(STUDY_METHODS) else ())
    if "funneling" in names and "inverse" in names:
        fun, inv = names.index("funneling"), names.index("inverse")
        per = e.mean(axis=1)  # (n, n_methods): per-participant method means
        p_pairs = {(i, j): min(1.0, float(_paired_t_p(per[:, i], per[:, j])) * len(pairs)) for i, j in pairs}
        out["s1_method_pairs"] = {f"{names[i]} vs {names[j]}": v for (i, j), v in p_pairs.items()}
        fi = tuple(sorted((fun, inv)))
        out["s1_only_funneling_vs_inverse"] = bool(
            p_pairs[fi] < alpha and all(v >= alpha for k, v in p_pairs.items() if k != fi)
            and per[:, inv].mean() < per[:, fun].mean())
        others = [k for k in range(n_m) if k != inv]
        differs = np.ones(e.shape[1], dtype=bool)
        for k in others:
            differs &= pair_p[tuple(sorted((k, inv)))] < alpha
        out["s1_inverse_differs_locations"] = np.flatnonzero(differs)
        cm = arrays.count.mean(axis=1)
        out["s2_reduction"] = float(1.0 - cm[:, inv].mean() / cm[:, fun].mean())
        p_w = min(1.0, _wilcoxon_p(cm[:, inv], cm[:, fun]) * len(pairs))
        out["s2_inverse_fewer"] = bool(p_w < alpha and cm[:, inv].mean() < cm[:, fun].mean())
        # The directional claims as p values: the Bonferroni p where the inverse filter is
        # on the paper's side, 1 where it is not (significant only in the paper's direction).
        out["s1_inverse_below_p"] = p_pairs[fi] if per[:, inv].mean() < per[:, fun].mean() else 1.0
        out["s2_inverse_fewer_p"] = p_w if cm[:, inv].mean() < cm[:, fun].mean() else 1.0
        # The reverse: the same tests, significant where funneling is on the paper's side.
        out["s1_inverse_above_p"] = p_pairs[fi] if per[:, inv].mean() > per[:, fun].mean() else 1.0
        out["s2_inverse_more_p"] = p_w if cm[:, inv].mean() > cm[:, fun].mean() else 1.0
    return out


def simulate_statistics(
    n: int,
    study_indices: Sequence[int],
    design: PowerDesign,
    bank: FeatureBank | None = None,
) -> list[dict[str, Any]]:
    """Simulate and analyse studies ``study_indices`` of sample size ``n`` (one task)."""
    b = bank if bank is not None else default_bank()
    out = []
    for j in study_indices:
        rng = np.random.default_rng([int(design.seed), int(n), int(j)])
        arrays = simulate_cell_means(
            int(n), rng, bank=b, model=design.model, repetitions=design.repetitions,
            methods=design.methods, locations=design.locations, hypothesis=design.hypothesis,
            level_db=design.level_db,
        )
        out.append(study_statistics(arrays, design.alpha, design.methods or b.methods))
    return out


def power_table(
    results: dict[int, list[dict[str, Any]]],
    alpha: float = 0.05,
    tests: Sequence[tuple[str, str]] = TESTS + DIRECTIONAL_TESTS + REVERSE_TESTS,
) -> list[dict[str, Any]]:
    """Power per N and test: share of studies with p < alpha and its binomial standard error.

    Parameters
    ----------
    results : dict
        ``{N: [statistics of each study]}``; each study's dict holds ``<test>_p``.
    alpha : float
    tests : sequence of (key, label)
        Default :data:`TESTS`, :data:`DIRECTIONAL_TESTS` then :data:`REVERSE_TESTS`; a test
        no study computed (the directional ones without funneling and the inverse filter)
        is left out.

    Returns
    -------
    list of dict
        ``n_participants``, ``test``, ``label``, ``power``, ``se`` (binomial standard error),
        ``n_studies`` (studies where the test could be computed).
    """
    rows = []
    for n in sorted(results):
        res = results[n]
        for key, label in tests:
            if not any(f"{key}_p" in r for r in res):
                continue
            p = np.array([r.get(f"{key}_p", np.nan) for r in res], dtype=float)
            ok = np.isfinite(p)
            power = float(np.mean(p[ok] < alpha)) if ok.any() else float("nan")
            k = int(ok.sum())
            rows.append({
                "n_participants": int(n), "test": key, "label": label, "power": power, "n_studies": k,
                "se": float(np.sqrt(power * (1 - power) / k)) if k else float("nan"),
            })
    return rows


#: A test is "powered" at N when its power reaches this (the usual 80 %).
ROBUST_POWER = 0.8


def _test_contrast() -> dict[str, str]:
    """Which contrast's direction each test concludes on (the omnibus method tests: their post hoc)."""
    out = {}
    for name, c in CONTRASTS.items():
        for key in ("paper", "reverse", "omnibus"):
            out[c[key]] = name
    return out


def effect_directions(tables: dict[str, list[dict[str, Any]]]) -> dict[str, dict[str, dict[int, str]]]:
    """The direction of each contrast under each hypothesis, per N, read from its power table.

    ``"paper"`` where studies significant in the paper's direction outnumber those
    significant in the reverse by more than two standard errors of the difference of the
    two shares, ``"reverse"`` for the opposite, ``"none"`` otherwise (neither direction
    shows in the simulated studies).

    Parameters
    ----------
    tables : dict
        ``{hypothesis: power_table(...) rows}`` with the rows of :data:`DIRECTIONAL_TESTS`
        and :data:`REVERSE_TESTS`.

    Returns
    -------
    dict
        ``{contrast: {hypothesis: {N: direction}}}`` for the contrasts of :data:`CONTRASTS`
        the tables have.
    """
    out: dict[str, dict[str, dict[int, str]]] = {}
    for name, c in CONTRASTS.items():
        for h, rows in tables.items():
            by = {(r["test"], r["n_participants"]): r for r in rows}
            for (test, n), r in by.items():
                if test != c["paper"] or (c["reverse"], n) not in by:
                    continue
                a, b = r["power"], by[(c["reverse"], n)]["power"]
                k = max(r["n_studies"], 1)
                se = np.sqrt(max(a + b - (a - b) ** 2, 0.0) / k)
                d = "paper" if a - b > 2 * se else "reverse" if b - a > 2 * se else "none"
                out.setdefault(name, {}).setdefault(h, {})[int(n)] = d
    return out


def robust_conclusions(tables: dict[str, list[dict[str, Any]]], threshold: float = ROBUST_POWER) -> list[dict[str, Any]]:
    """Where every hypothesis agrees: per test and N, whether the test is powered under all, and in which direction.

    A conclusion is robust only where every hypothesis gives the same verdict (powered at
    ``threshold`` or not) and, for a test of the inverse filter against funneling
    (:data:`CONTRASTS`: the directional tests, their reverse, and the omnibus method tests,
    whose post hoc direction it is), the same direction of the effect
    (:func:`effect_directions`): a method test powered under every hypothesis is no
    conclusion where they predict opposite winners.

    Parameters
    ----------
    tables : dict
        ``{hypothesis name: power_table(...) rows}``, every table over the same tests and N.
    threshold : float
        Power at which a test counts as powered.

    Returns
    -------
    list of dict
        ``test``, ``label``, ``n_participants``, ``power`` ({hypothesis: power}),
        ``direction`` ({hypothesis: direction}, or None for a test without a contrast),
        ``conclusion`` (``"powered"``, ``"not powered"`` or ``"depends on the hypothesis"``)
        and ``robust`` (True only where every hypothesis agrees).
    """
    names = list(tables)
    if not names:
        return []
    keyed = {h: {(r["test"], r["n_participants"]): r for r in tables[h]} for h in names}
    directions = effect_directions(tables)
    contrast_of = _test_contrast()
    out = []
    for r in tables[names[0]]:
        key = (r["test"], r["n_participants"])
        powers = {h: keyed[h][key]["power"] if key in keyed[h] else float("nan") for h in names}
        verdicts = {bool(p >= threshold) for p in powers.values() if np.isfinite(p)}
        complete = all(np.isfinite(p) for p in powers.values())
        robust = complete and len(verdicts) == 1
        direction = None
        contrast = contrast_of.get(r["test"])
        if contrast is not None and contrast in directions:
            direction = {h: directions[contrast].get(h, {}).get(int(r["n_participants"]), "unknown") for h in names}
            robust = robust and len(set(direction.values())) == 1 and "unknown" not in direction.values()
        conclusion = ("powered" if verdicts == {True} else "not powered") if robust else "depends on the hypothesis"
        out.append({"test": r["test"], "label": r["label"], "n_participants": r["n_participants"], "power": powers,
                    "direction": direction, "conclusion": conclusion, "robust": robust})
    return out


def directional_shares(results: dict[int, list[dict[str, Any]]], alpha: float = 0.05) -> dict[str, dict[str, dict[str, float]]]:
    """Share of studies significant in the paper's direction, in the reverse, and in neither, per contrast and N.

    Parameters
    ----------
    results : dict
        ``{N: [statistics of each study]}`` (:func:`study_statistics`).
    alpha : float

    Returns
    -------
    dict
        ``{contrast: {str(N): {"paper": share, "reverse": share, "neither": share}}}`` for
        the contrasts of :data:`CONTRASTS` the studies computed (N as a string, as JSON keys).
    """
    out: dict[str, dict[str, dict[str, float]]] = {}
    for name, c in CONTRASTS.items():
        for n in sorted(results):
            res = results[n]
            pa = np.array([r.get(f"{c['paper']}_p", np.nan) for r in res], dtype=float)
            pr = np.array([r.get(f"{c['reverse']}_p", np.nan) for r in res], dtype=float)
            ok = np.isfinite(pa) & np.isfinite(pr)
            if not ok.any():
                continue
            a, r = pa[ok] < alpha, pr[ok] < alpha  # exclusive: one of the two p is 1
            out.setdefault(name, {})[str(int(n))] = {"paper": float(np.mean(a)), "reverse": float(np.mean(r)),
                                                     "neither": float(np.mean(~a & ~r))}
    return out


def direction_sentences(directions: dict[str, dict[str, dict[int, str]]], n: int | None = None) -> dict[str, str]:
    """One sentence per contrast: whether the hypotheses agree on its direction (at N ``n``, default the largest).

    Parameters
    ----------
    directions : dict
        :func:`effect_directions`.
    n : int, optional

    Returns
    -------
    dict
        ``{contrast: sentence}``.
    """
    out = {}
    for name, by_h in directions.items():
        c = CONTRASTS[name]
        at = n if n is not None else max(max(v) for v in by_h.values())
        d = {h: v.get(at, "unknown") for h, v in by_h.items()}
        reads = {"paper": (f"predicts {c['paper_reads']} (the paper's direction)",
                           f"predict {c['paper_reads']} (the paper's direction)"),
                 "reverse": (f"predicts the reverse, {c['reverse_reads']}", f"predict the reverse, {c['reverse_reads']}"),
                 "none": ("shows neither direction", "show neither direction"),
                 "unknown": ("was not simulated at this N", "were not simulated at this N")}
        kinds = list(dict.fromkeys(d.values()))
        if len(kinds) == 1:
            who = "every hypothesis" if len(d) > 1 else f"{next(iter(d))}"
            out[name] = f"at N = {at}, {who} {reads[kinds[0]][0]} for {c['label']}"
        else:
            parts = []
            for k in kinds:
                hs = [h for h, v in d.items() if v == k]
                parts.append(f"{' and '.join(hs)} {reads[k][len(hs) > 1]}")
            out[name] = f"at N = {at}, the direction of {c['label']} depends on the hypothesis: " + "; ".join(parts)
    return out


def paper_implied_power(
    n_participants: Sequence[int],
    alpha: float = 0.05,
    p_bonferroni: float = PAPER_S1_PAIR_P,
    n_pairs: int = PAPER_S1_PAIRS,
    n_paper: int = PAPER_N,
) -> dict[str, Any]:
    """Power of a replication implied by the paper's own Study 1 statistic, funneling vs inverse.

    The paper's Bonferroni-corrected p of the paired t-test (``p_bonferroni`` over
    ``n_pairs`` pairs, ``n_paper`` participants) gives its t and its effect size
    ``d_z = t / sqrt(n_paper)``; a replication of ``N`` participants testing the same pair
    with the same correction has the power of a two-sided paired t-test at level
    ``alpha / n_pairs`` with noncentrality ``d_z sqrt(N)`` (noncentral t), at the effect as
    published and at half of it (published effects are often inflated).

    Parameters
    ----------
    n_participants : sequence of int
        Sample sizes N of the replication (each >= 2).
    alpha : float
        Family-wise significance level.
    p_bonferroni : float
        The paper's reported (corrected) p.
    n_pairs : int
        Comparisons the correction covered.
    n_paper : int
        The paper's participants.

    Returns
    -------
    dict
        ``t``, ``d_z``, ``p_bonferroni``, ``n_pairs``, ``n_paper``, and ``power`` and
        ``power_half`` ({str(N): power}).
    """
    p_unc = p_bonferroni / n_pairs
    t = float(stats.t.isf(p_unc / 2.0, n_paper - 1))
    d = t / np.sqrt(n_paper)
    out: dict[str, Any] = {"t": t, "d_z": float(d), "p_bonferroni": p_bonferroni, "n_pairs": n_pairs,
                           "n_paper": n_paper, "alpha": alpha, "power": {}, "power_half": {}}
    for n in n_participants:
        n = int(n)
        if n < 2:
            raise ValidationError(f"a paired t-test needs at least 2 participants, got {n}")
        crit = stats.t.isf(alpha / n_pairs / 2.0, n - 1)
        for key, eff in (("power", d), ("power_half", d / 2.0)):
            nc = eff * np.sqrt(n)
            out[key][str(n)] = float(stats.nct.sf(crit, n - 1, nc) + stats.nct.cdf(-crit, n - 1, nc))
    return out


def paper_implied_wilcoxon_power(
    n_participants: Sequence[int],
    alpha: float = 0.05,
    p_bonferroni: float = PAPER_S2_PAIR_P,
    n_pairs: int = PAPER_S2_PAIRS,
    n_paper: int = PAPER_N,
    n_studies: int = 4000,
    seed: int = 2023,
) -> dict[str, Any]:
    """Power of a replication implied by the paper's own Study 2 statistic, funneling vs inverse.

    The paper's Bonferroni-corrected p of the Wilcoxon signed-rank test (``p_bonferroni``
    over ``n_pairs`` pairs, ``n_paper`` participants) gives its standard normal statistic
    ``z``. The effect it implies is the shift ``theta`` of normally distributed paired
    differences (SD 1, the paired t-test's model of Study 1) at which the signed-rank
    statistic's expected ``z`` at ``n_paper`` participants is the paper's (the mean of
    ``W+``, ``N p1 + N (N - 1) p2 / 2`` with ``p1 = Phi(theta)``, ``p2 = Phi(theta sqrt 2)``;
    Lehmann, Nonparametrics, 1975, Sec. 4.2). A replication of ``N`` testing the same
    pair with the same correction is simulated ``n_studies`` times
    (:func:`scipy.stats.wilcoxon`, as the power simulation tests it), at ``theta`` and at
    half of it (published effects are often inflated); the binomial SE of each power is at
    most ``0.5 / sqrt(n_studies)``.

    Parameters
    ----------
    n_participants, alpha, p_bonferroni, n_pairs, n_paper
        As :func:`paper_implied_power` (here the paper's Study 2 p, Sec. III.C).
    n_studies : int
        Simulated replications per N and effect.
    seed : int
        Seed of the simulation.

    Returns
    -------
    dict
        ``z``, ``theta`` (the implied shift in SDs of the differences), ``p_bonferroni``,
        ``n_pairs``, ``n_paper``, ``alpha``, ``n_studies``, and ``power`` and
        ``power_half`` ({str(N): power}).
    """
    from scipy import optimize

    z = float(stats.norm.isf(p_bonferroni / n_pairs / 2.0))

    def expected_z(theta: float, n: int) -> float:
        mean = n * stats.norm.cdf(theta) + n * (n - 1) / 2.0 * stats.norm.cdf(theta * np.sqrt(2.0))
        return (mean - n * (n + 1) / 4.0) / np.sqrt(n * (n + 1) * (2 * n + 1) / 24.0)

    theta = float(optimize.brentq(lambda t: expected_z(t, n_paper) - z, 0.0, 10.0))
    out: dict[str, Any] = {"z": z, "theta": theta, "p_bonferroni": p_bonferroni, "n_pairs": n_pairs,
                           "n_paper": n_paper, "alpha": alpha, "n_studies": n_studies, "power": {}, "power_half": {}}
    for n in n_participants:
        n = int(n)
        if n < 2:
            raise ValidationError(f"a signed-rank test needs at least 2 participants, got {n}")
        for k, (key, eff) in enumerate((("power", theta), ("power_half", theta / 2.0))):
            rng = np.random.default_rng([seed, n, k])  # the same numbers whichever N are asked for
            p = stats.wilcoxon(rng.normal(eff, 1.0, (n_studies, n)), axis=1).pvalue
            out[key][str(n)] = float(np.mean(np.minimum(p * n_pairs, 1.0) < alpha))
    return out


def _connect(client_cls: Any, scheduler: str) -> Any:
    """A Dask client of the scheduler at ``scheduler`` (``tcp://host:port``), or ValidationError in one line."""
    import re

    from .._validation import shorten

    if not re.fullmatch(r"(?:[a-z]+://)?[^\s/:]+:\d{1,5}", scheduler):
        raise ValidationError(f"scheduler must be an address like tcp://host:8786, got {shorten(scheduler)}")
    try:
        return client_cls(scheduler, timeout=SCHEDULER_TIMEOUT_S)
    except (OSError, TimeoutError, ValueError) as exc:
        raise ValidationError(f"cannot reach the Dask scheduler at {shorten(scheduler)} within "
                              f"{SCHEDULER_TIMEOUT_S} s ({shorten(str(exc), 120)}); start it, or leave out "
                              "--scheduler for a cluster on this machine") from None


@contextmanager
def dask_client(*, scheduler: str | None = None, n_workers: int | None = None, client: Any = None) -> Iterator[Any]:
    """A Dask client for the duration of a ``with`` block: the cluster options of ``power``.

    Parameters
    ----------
    scheduler : str, optional
        Address of a Dask scheduler (``tcp://host:8786``); default a
        ``distributed.LocalCluster`` on this machine (no dashboard) with ``n_workers``
        single-threaded processes, closed when the block ends.
    n_workers : int, optional
        LocalCluster workers (default: the CPU count).
    client : distributed.Client, optional
        Use this client as it is (not closed at the end).

    Yields
    ------
    distributed.Client
    """
    if client is not None:
        yield client
        return
    from distributed import Client, LocalCluster

    cluster = None
    if scheduler:
        client = _connect(Client, scheduler)
    else:
        import os

        cluster = LocalCluster(n_workers=n_workers or os.cpu_count() or 1, threads_per_worker=1, processes=True,
                               dashboard_address=None)
        client = Client(cluster)
    try:
        yield client
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def run_power(
    design: PowerDesign,
    *,
    scheduler: str | None = None,
    n_workers: int | None = None,
    chunk: int = 10,
    client: Any = None,
    progress: Callable[[int, int], None] | None = None,
    local: bool = False,
    bank: FeatureBank | None = None,
) -> dict[str, Any]:
    """Run a power analysis on Dask (or in this process with ``local=True``).

    Parameters
    ----------
    design : PowerDesign
    scheduler : str, optional
        Address of a Dask scheduler (``tcp://host:8786``); default a
        ``distributed.LocalCluster`` on this machine with ``n_workers`` processes.
    n_workers : int, optional
        LocalCluster workers (default: the CPU count).
    chunk : int
        Studies per task.
    client : distributed.Client, optional
        Use this client instead of creating one.
    progress : callable, optional
        ``progress(done_studies, total_studies)`` as tasks finish.
    local : bool
        Run everything in this process (no Dask), same numbers.
    bank : FeatureBank, optional
        Default :func:`default_bank` (sent to the workers once).

    Returns
    -------
    dict
        ``label`` (the model notice), ``levels`` (the bank's level rule), ``design`` (JSON-ready), ``results`` ({N: list of
        per-study statistics}), ``table`` (:func:`power_table`), ``directional``
        (:func:`directional_shares`), ``elapsed_s``.
    """
    import time

    if isinstance(chunk, bool) or not isinstance(chunk, (int, np.integer)) or chunk < 1:
        raise ValidationError(f"chunk must be an integer >= 1, got {chunk!r}")
    b = bank if bank is not None else default_bank()
    missing = [m for m in design.methods or () if m not in b.methods]
    if missing:
        raise ValidationError(
            f"methods: the feature bank has no stimuli of {', '.join(missing)} (it has {', '.join(b.methods)}); "
            f"build one with scripts/build_feature_bank.py --methods {','.join(dict.fromkeys((*b.methods, *missing)))} "
            "--out FILE and pass it (vibrofocus power --bank FILE)")
    tasks = [(n, list(range(s, min(s + chunk, design.n_studies))))
             for n in design.n_participants for s in range(0, design.n_studies, chunk)]
    total = len(design.n_participants) * design.n_studies
    results: dict[int, list[dict[str, Any]]] = {n: [] for n in design.n_participants}
    parts: dict[tuple[int, int], list[dict[str, Any]]] = {}
    t0 = time.perf_counter()
    done = 0
    if local:
        for n, idx in tasks:
            parts[(n, idx[0])] = simulate_statistics(n, idx, design, b)
            done += len(idx)
            if progress is not None:
                progress(done, total)
    else:
        from distributed import as_completed

        with dask_client(scheduler=scheduler, n_workers=n_workers, client=client) as dask:
            bank_f = dask.scatter(b, broadcast=True)
            futures = {dask.submit(simulate_statistics, n, idx, design, bank_f, pure=False): (n, idx)
                       for n, idx in tasks}
            for fut in as_completed(futures):
                n, idx = futures[fut]
                parts[(n, idx[0])] = fut.result()
                done += len(idx)
                if progress is not None:
                    progress(done, total)
    for (n, _start), res in sorted(parts.items()):
        results[n].extend(res)
    from .hypotheses import hypothesis as find_hypothesis

    return {
        "label": find_hypothesis(design.hypothesis).label(),
        "hypothesis": find_hypothesis(design.hypothesis).to_dict(),
        "levels": b.levels,
        "design": {
            "n_participants": list(design.n_participants), "n_studies": design.n_studies,
            "repetitions": design.repetitions, "methods": list(design.methods or b.methods),
            "locations": list(design.locations or range(1, len(b.locations_xy) + 1)),
            "alpha": design.alpha, "seed": design.seed,
            "model": (design.model or find_hypothesis(design.hypothesis).model()).to_dict(),
            "hypothesis": design.hypothesis, "level_db": design.level_db,
        },
        "results": results,
        "table": power_table(results, design.alpha),
        "directional": directional_shares(results, design.alpha),
        "elapsed_s": time.perf_counter() - t0,
    }
