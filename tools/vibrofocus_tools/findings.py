"""The paper's findings in simulated 20-participant studies, checked independently (a MODEL, not data).

Each study is drawn on the fast path (feature bank + perceptual model, as ``power`` and
the fit draw them), and analysed HERE with pingouin and scipy only, independently of
``vibrofocus.analysis`` and of the statistics the fit optimizes
(tests/tools/test_findings.py checks that this module imports neither). The findings are
those of de Vlam et al. (IEEE ToH 16(4), 2023, doi:10.1109/TOH.2023.3270362), Sec. III.B-C.
``scripts/check_findings.py`` prints them for a range of seeds; ``scripts/hypotheses_table.py``
prints them for every hypothesis.
"""

from __future__ import annotations

import warnings
from itertools import combinations

import numpy as np
import pandas as pd
import pingouin as pg
from scipy import stats

from vibrofocus.simulation.bank import FeatureBank, simulate_cell_means
from vibrofocus.simulation.hypotheses import hypothesis
from vibrofocus.simulation.perception import PerceptualModel

from .joint import add_joint, headline

ALPHA = 0.05
METHODS = ("funneling", "inverse", "combination")
FUN, INV, COMB = 0, 1, 2
BEST = {3, 4, 6, 7}  # locations 4, 5, 7, 8 (0-based)
POST_HOC = (0, 2, 8)  # locations 1, 3, 9


def _long(cells: np.ndarray) -> pd.DataFrame:
    n, n_l, n_m = cells.shape
    s, l, m = np.meshgrid(np.arange(n), np.arange(n_l), np.arange(n_m), indexing="ij")
    return pd.DataFrame({"s": s.ravel(), "l": l.ravel(), "m": m.ravel(), "y": cells.ravel()})


def _ttest_p(a: np.ndarray, b: np.ndarray) -> float:
    return float(stats.ttest_rel(a, b).pvalue)


def _friedman(x: np.ndarray) -> float:
    """Friedman p over columns of x (participants x levels); NaN if it cannot run."""
    x = x[np.all(np.isfinite(x), axis=1)]
    if x.shape[0] < 3:
        return float("nan")
    return float(stats.friedmanchisquare(*x.T).pvalue)


def _wilcoxon_p(a: np.ndarray, b: np.ndarray) -> float:
    d = a - b
    d = d[np.isfinite(d)]
    if d.size < 2 or np.all(d == 0):
        return 1.0
    return float(stats.wilcoxon(d[d != 0]).pvalue) if np.count_nonzero(d) >= 2 else 1.0


def study2_findings(count: np.ndarray, count_hit: np.ndarray) -> dict[str, float | bool]:
    """Study 2's findings for one study from its cell means, shape (n_participants, 9, 3) each."""
    out: dict[str, float | bool] = {}
    out["s2_location"] = _friedman(count.mean(axis=2)) < ALPHA
    cm = count.mean(axis=1)  # (n, 3)
    out["s2_method"] = (_friedman(cm) < ALPHA and min(1.0, 3 * _wilcoxon_p(cm[:, INV], cm[:, FUN])) < ALPHA
                        and cm[:, INV].mean() < cm[:, FUN].mean())
    out["s2_reduction"] = float(1.0 - cm[:, INV].mean() / cm[:, FUN].mean())
    out["s2_headline"] = headline(out["s2_method"], out["s2_reduction"])
    # Target-containing trials: per-participant marginal means (averaged over the other
    # factor's cells that have such a trial), so no participant is dropped for one empty cell.
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        hit_loc, hit_meth = np.nanmean(count_hit, axis=2), np.nanmean(count_hit, axis=1)
    out["s2_hit_location_ns"] = not (_friedman(hit_loc) < ALPHA)
    out["s2_hit_method_ns"] = not (_friedman(hit_meth) < ALPHA)
    out["s2_hit_n_location"] = int(np.all(np.isfinite(hit_loc), axis=1).sum())
    out["s2_hit_n_method"] = int(np.all(np.isfinite(hit_meth), axis=1).sum())
    return out


def findings(error: np.ndarray, count: np.ndarray, count_hit: np.ndarray) -> dict[str, float | bool]:
    """The findings for one study from its cell means, shape (n_participants, 9, 3) each."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        a = pg.rm_anova(_long(error), dv="y", within=["l", "m"], subject="s", correction=True)
    p = {row.Source: (row.p_GG_corr if "p_GG_corr" in a and np.isfinite(row.p_GG_corr) else row.p_unc)
         for row in a.itertuples()}
    out: dict[str, float | bool] = {}
    out["s1_location"] = p["l"] < ALPHA
    out["s1_sphericity_violated"] = bool(a.loc[a["Source"] == "l", "p_spher"].iloc[0] < ALPHA)
    by_loc = error.mean(axis=(0, 2))
    out["s1_best_4578"] = set(np.argsort(by_loc)[:4]) == BEST
    out["s1_loc1_among_worst"] = int(np.argsort(np.argsort(by_loc))[0]) >= 4
    meth = error.mean(axis=1)  # (n, 3)
    pair_p = {(i, j): min(1.0, 3 * _ttest_p(meth[:, i], meth[:, j])) for i, j in combinations(range(3), 2)}
    only_fi = pair_p[(FUN, INV)] < ALPHA and pair_p[(FUN, COMB)] >= ALPHA and pair_p[(INV, COMB)] >= ALPHA
    out["s1_method"] = p["m"] < ALPHA and only_fi and meth[:, INV].mean() < meth[:, FUN].mean()
    out["s1_method_significant"] = p["m"] < ALPHA
    out["s1_inverse_lower"] = pair_p[(FUN, INV)] < ALPHA and meth[:, INV].mean() < meth[:, FUN].mean()
    at = []
    for loc in POST_HOC:
        e = error[:, loc, :]
        pi = [min(1.0, 3 * _ttest_p(e[:, INV], e[:, k])) for k in (FUN, COMB)]
        at.append(all(x < ALPHA for x in pi))
    out["s1_interaction"] = p["l * m"] < ALPHA
    out["s1_interaction_at_139"] = p["l * m"] < ALPHA and all(at)
    out["s1_interaction_at_139_share"] = float(np.mean(at))
    out.update(study2_findings(count, count_hit))
    return add_joint(out)


ROWS = [
    ("Study 1 location significant (Greenhouse-Geisser)", "s1_location"),
    ("Study 1 location: sphericity violated (Mauchly)", "s1_sphericity_violated"),
    ("best locations exactly 4, 5, 7, 8", "s1_best_4578"),
    ("location 1 among the five worst", "s1_loc1_among_worst"),
    ("Study 1 method significant", "s1_method_significant"),
    ("inverse lower error than funneling (Bonferroni)", "s1_inverse_lower"),
    ("... and ONLY funneling vs inverse (Bonferroni), inverse lower", "s1_method"),
    ("Study 1 interaction significant", "s1_interaction"),
    ("... with post hoc at 1, 3 and 9 (inverse vs both others)", "s1_interaction_at_139"),
    ("Study 2 location significant (Friedman)", "s2_location"),
    ("Study 2 method significant, inverse fewer than funneling", "s2_method"),
    ("... and 10-30 % fewer points (the paper: about 20 %)", "s2_headline"),
    ("target-containing trials: location not significant", "s2_hit_location_ns"),
    ("target-containing trials: method not significant", "s2_hit_method_ns"),
    ("Study 1 as a whole: location, method and interaction significant, inverse lower", "s1_all"),
    ("Study 2 as a whole: location and method significant (inverse fewer), target-containing tests n.s.",
     "s2_all"),
]


def held_out(seeds: range, n: int, bank: FeatureBank, name: str | None = None,
             model: PerceptualModel | None = None) -> list[dict[str, float | bool]]:
    """The findings of one study per seed (study ``s`` draws from ``default_rng([s, 16])``)."""
    h = hypothesis(name)
    res = []
    for s in seeds:
        arrays = simulate_cell_means(n, np.random.default_rng([s, 16]), bank=bank, model=model or h.model(),
                                     hypothesis=h)
        res.append(findings(arrays.error_mm, arrays.count, arrays.count_hit))
    return res


def findings_table(res: list[dict[str, float | bool]], n: int, base: dict[str, np.ndarray] | None = None) -> str:
    """The findings of the studies ``res`` as a markdown table (``base``: the baseline's outcomes beside them)."""
    from .baseline import paired_difference_p

    lines = ["| finding | holds in | baseline (c313a27) | paired McNemar p |\n|---|---|---|---|" if base is not None
             else "| finding | holds in |\n|---|---|"]
    for label, key in ROWS:
        mine = np.array([bool(r[key]) for r in res])
        extra = (f" | {int(base[key].sum())} of {len(res)} | {paired_difference_p(mine, base[key]):.3g}"
                 if base is not None else "")
        lines.append(f"| {label} | {int(mine.sum())} of {len(res)}{extra} |")
    tail = " | | |" if base is not None else " |"  # the rows below fill only the first two columns
    red = np.array([r["s2_reduction"] for r in res])
    lines.append(f"| Study 2 reduction of selected points, inverse vs funneling | median {np.median(red):.1%} "
                 f"[{np.percentile(red, 5):.1%}, {np.percentile(red, 95):.1%}]{tail}")
    lines.append(f"| target-containing tests: participants kept (location, method), median | "
                 f"{np.median([r['s2_hit_n_location'] for r in res]):.0f}, "
                 f"{np.median([r['s2_hit_n_method'] for r in res]):.0f} of {n}{tail}")
    share = np.mean([r["s1_interaction_at_139_share"] for r in res])
    lines.append(f"| share of locations 1, 3, 9 with the inverse differing from both | {share:.0%}{tail}")
    return "\n".join(lines)
