"""The simulated participants beside the source paper: statistics over many seeds.

The statistics of de Vlam et al. (IEEE ToH 16(4), 2023), as kept in
``simulation/data/psychophysics.json`` (``paper_statistics``), are compared with the same
statistics of many simulated 20-participant studies (the fast path:
:func:`~vibrofocus.simulation.bank.simulate_cell_means` and
:func:`~vibrofocus.simulation.power.study_statistics`). For each row of the comparison the
model's median and 90 % interval over the seeds are given, and the share of seeds in
which the row's direction and significance are reproduced. Used by
``scripts/fit_participants.py`` (fit, ``docs/simulated-participants.md`` and README
tables) and by the tests. Simulated participants are a model, not data.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._validation import check_in_range
from .bank import FeatureBank, default_bank, simulate_cell_means
from .perception import MODEL_LABEL, MODEL_VERSION, PerceptualModel, psychophysics_data
from .power import study_statistics

__all__ = [
    "N_PARTICIPANTS",
    "BEST_LOCATIONS",
    "INTERACTION_LOCATIONS",
    "Row",
    "ROWS",
    "seed_statistics",
    "compare",
    "comparison_markdown",
]

#: Participants in each of the paper's studies.
N_PARTICIPANTS = 20
#: 0-based indices of the paper's best locations (4, 5, 7, 8).
BEST_LOCATIONS = np.array([4, 5, 7, 8]) - 1
#: 0-based indices of the locations where the paper's post hoc tests found the interaction (1, 3, 9).
INTERACTION_LOCATIONS = np.array([1, 3, 9]) - 1
ALPHA = 0.05


def _best_first(s: dict[str, Any]) -> bool:
    """Direction of the paper's Fig. 6: locations 4, 5, 7, 8 have a lower mean error than the others."""
    e = np.asarray(s["s1_error_by_location"])
    others = np.setdiff1d(np.arange(e.size), BEST_LOCATIONS)
    return bool(e[BEST_LOCATIONS].mean() < e[others].mean())


def _exact_best(s: dict[str, Any]) -> bool:
    e = np.asarray(s["s1_error_by_location"])
    return set(np.argsort(e)[: BEST_LOCATIONS.size]) == set(BEST_LOCATIONS)


def _interaction_at(s: dict[str, Any]) -> float:
    """Share of the paper's interaction locations (1, 3, 9) where the inverse filter differs
    from both other methods (Bonferroni paired t-tests), as in the paper's post hoc tests."""
    return float(np.isin(INTERACTION_LOCATIONS, s["s1_inverse_differs_locations"]).mean())


def _location1_among_worst(s: dict[str, Any]) -> bool:
    """Location 1 is among the five locations with the highest mean error (Fig. 6)."""
    e = np.asarray(s["s1_error_by_location"])
    return bool(np.argsort(np.argsort(e))[0] >= e.size - 5)


@dataclass(frozen=True)
class Row:
    """One row of the comparison.

    Attributes
    ----------
    label : str
        What is compared.
    paper : str
        The paper's value, as text.
    value : callable or None
        ``value(stats) -> float``: the model's number in one study (median and 90 %
        interval are taken over seeds); None for a row of shares only.
    reproduced : callable or None
        ``reproduced(stats) -> bool | float``: whether (or how much of) the row's
        direction and significance one simulated study reproduces; None where the paper
        gives no value to reproduce.
    criterion : str
        What ``reproduced`` checks, in words.
    short : bool
        Also in the README's short table.
    digits : int
        Decimals of ``value``.
    """

    label: str
    paper: str
    value: Callable[[dict[str, Any]], float] | None
    reproduced: Callable[[dict[str, Any]], bool | float] | None
    criterion: str
    short: bool = False
    digits: int = 2


def _key(name: str) -> Callable[[dict[str, Any]], float]:
    return lambda s: float(s[name])


def _sig(name: str) -> Callable[[dict[str, Any]], bool]:
    return lambda s: bool(s[f"{name}_p"] < ALPHA)


def _ns(name: str) -> Callable[[dict[str, Any]], bool]:
    return lambda s: bool(s[f"{name}_p"] >= ALPHA)


HIT_CRITERION = "p >= 0.05 (a test that could not run, too few participants kept: not reproduced)"


def _rows() -> tuple[Row, ...]:
    p = psychophysics_data()["paper_statistics"]
    s1l, s1m, s1i, s2l = p["study1_location"], p["study1_method"], p["study1_interaction"], p["study2_location"]
    s2m = p["study2_method"]
    eps = s1l["ddof1"] / 8.0
    rows = [
        Row("Study 1 location, F", f"F({s1l['ddof1']}, {s1l['ddof2']}) = {s1l['F']}, p < {s1l['p_max']} (GG)",
            _key("s1_location_F"), _sig("s1_location"), "p (GG) < 0.05", short=True),
        Row("Study 1 location, GG epsilon (sphericity)", f"{eps:.2f} (= {s1l['ddof1']} / 8): sphericity violated",
            _key("s1_location_eps"), lambda s: bool(s["s1_location_p_mauchly"] < ALPHA), "Mauchly p < 0.05"),
        Row("Study 1 method, F", f"F({s1m['ddof1']}, {s1m['ddof2']}) = {s1m['F']}, p = {s1m['p']}",
            _key("s1_method_F"), _sig("s1_method"), "p (GG) < 0.05", short=True),
        Row("Study 1 method, inverse vs funneling", "inverse lower error (p = 0.007)", None,
            lambda s: s["s1_method_pairs"]["funneling vs inverse"] < ALPHA
            and s["s1_error_by_method"][1] < s["s1_error_by_method"][0],
            "Bonferroni paired t-test significant, inverse lower error", short=True),
        Row("Study 1 method, post hoc", "only funneling vs inverse (p = 0.007), inverse lower", None,
            lambda s: s["s1_only_funneling_vs_inverse"],
            "Bonferroni paired t-tests: only that pair significant, inverse lower error", short=True),
        Row("Study 1 location x method, F", f"F({s1i['ddof1']}, {s1i['ddof2']}) = {s1i['F']}, p < {s1i['p_max']}",
            _key("s1_interaction_F"), _sig("s1_interaction"), "p (GG) < 0.05", short=True),
        Row("interaction post hoc at locations 1, 3, 9", "inverse differs from both other methods at 1, 3, 9",
            None, _interaction_at,
            "share of 1, 3, 9 where the inverse differs from both others (Bonferroni; mean over seeds)", short=True),
        Row("best locations", "4, 5, 7, 8 (lowest error)", None, _best_first,
            "mean error over 4, 5, 7, 8 below that over the other five", short=True),
        Row("best locations, exactly", "4, 5, 7, 8", None, _exact_best, "the four lowest errors are at 4, 5, 7, 8"),
        Row("location 1 among the worst", "1 is not among the best (Fig. 6)", None, _location1_among_worst,
            "location 1 among the five highest mean errors"),
        Row("Study 2 location, chi2(8)", f"chi2({s2l['dof']}) = {s2l['chi2']}", _key("s2_location_chi2"),
            _sig("s2_location"), "p < 0.05", short=True),
        Row("Study 2 method, chi2(2)", f"chi2({s2m['dof']}) = {s2m['chi2']}, p < {s2m['p_max']}",
            _key("s2_method_chi2"), _sig("s2_method"), "p < 0.05", short=True),
        Row("Study 2, fewer points with the inverse filter than funneling",
            f"{s2m['reduction']:.0%} fewer (p = {s2m['inverse_fewer_than_funneling_p']})",
            lambda s: 100.0 * s["s2_reduction"], lambda s: s["s2_inverse_fewer"],
            "Bonferroni Wilcoxon significant, inverse fewer; value: reduction in %", short=True, digits=0),
        Row("Study 2, trials containing the target: participants kept", "not given (20 tested)",
            _key("s2_hit_n"), None, "", short=True, digits=0),
        Row("Study 2, trials containing the target: location, chi2(8)", "not significant",
            _key("s2_hit_location_chi2"), _ns("s2_hit_location"), HIT_CRITERION, short=True),
        Row("Study 2, trials containing the target: method, chi2(2)", "not significant",
            _key("s2_hit_method_chi2"), _ns("s2_hit_method"), HIT_CRITERION, short=True),
    ]
    return tuple(rows)


#: The rows compared (built from the data file).
ROWS: tuple[Row, ...] = _rows()


def seed_statistics(
    model: PerceptualModel | None = None,
    seeds: Iterable[int] = range(20),
    *,
    n_participants: int = N_PARTICIPANTS,
    bank: FeatureBank | None = None,
    hypothesis: Any = None,
) -> list[dict[str, Any]]:
    """Statistics of one simulated study per seed (study ``s`` draws from ``default_rng([s, 16])``).

    Parameters
    ----------
    model : PerceptualModel, optional
        Default: the hypothesis' fitted model.
    seeds : iterable of int
    n_participants : int
    bank : FeatureBank, optional
        Default :func:`~vibrofocus.simulation.bank.default_bank`.
    hypothesis : str or Hypothesis, optional
        How the participants read the felt field (default
        :data:`~vibrofocus.simulation.hypotheses.DEFAULT_HYPOTHESIS`).

    Returns
    -------
    list of dict
        :func:`~vibrofocus.simulation.power.study_statistics` of each study, with
        ``felt_share``: the share of the trials whose stimulus the participant felt.
    """
    b = bank if bank is not None else default_bank()
    from .hypotheses import hypothesis as find_hypothesis

    h = find_hypothesis(hypothesis)
    m = model or h.model()
    out = []
    for s in seeds:
        arrays = simulate_cell_means(n_participants, np.random.default_rng([int(s), 16]), bank=b, model=m, hypothesis=h)
        out.append({**study_statistics(arrays, methods=b.methods), "felt_share": float(np.mean(arrays.felt))})
    return out


def _interval(values: np.ndarray, level: float) -> tuple[float, float, float]:
    v = values[np.isfinite(values)]
    if v.size == 0:
        return (float("nan"),) * 3
    lo = 50.0 * (1.0 - level)
    med, a, b = np.percentile(v, [50.0, lo, 100.0 - lo])
    return float(med), float(a), float(b)


def compare(stats: list[dict[str, Any]], level: float = 0.9) -> list[dict[str, Any]]:
    """The comparison rows for studies ``stats`` (one per seed).

    Parameters
    ----------
    stats : list of dict
        From :func:`seed_statistics`.
    level : float
        Central interval, in (0, 1).

    Returns
    -------
    list of dict
        Per row of :data:`ROWS` (then one per method: Study 1 mean error, mm): ``label``,
        ``paper``, ``median``, ``low``, ``high`` (NaN where the row has no value),
        ``share`` (share of seeds reproducing the row, NaN where the paper gives nothing
        to reproduce), ``criterion``, ``short``, ``digits``.
    """
    check_in_range(level, "level", 0.0, 1.0, inclusive=False)
    out = []
    for row in ROWS:
        med = low = high = float("nan")
        if row.value is not None:
            med, low, high = _interval(np.array([row.value(s) for s in stats], dtype=float), level)
        share = float(np.mean([float(row.reproduced(s)) for s in stats])) if row.reproduced is not None else float("nan")
        out.append({"label": row.label, "paper": row.paper, "median": med, "low": low, "high": high, "share": share,
                    "criterion": row.criterion, "short": row.short, "digits": row.digits})
    by_method = np.array([s["s1_error_by_method"] for s in stats], dtype=float)
    for k, meth in enumerate(default_bank().methods[: by_method.shape[1]]):
        med, low, high = _interval(by_method[:, k], level)
        out.append({"label": f"Study 1 mean error, {meth} (mm)", "paper": "not in the data file", "median": med,
                    "low": low, "high": high, "share": float("nan"), "criterion": "", "short": True, "digits": 1})
    return out


def _num(row: dict[str, Any]) -> str:
    if not np.isfinite(row["median"]):
        return "—"
    d = row["digits"]
    return f"{row['median']:.{d}f} [{row['low']:.{d}f}, {row['high']:.{d}f}]"


def comparison_markdown(rows: list[dict[str, Any]], seeds: range, *, short: bool = False,
                        label: str = MODEL_LABEL) -> str:
    """A markdown table of :func:`compare` rows, headed by the model notice.

    Parameters
    ----------
    rows : list of dict
    seeds : range
        Seeds of the simulated studies the rows summarize (for the heading).
    short : bool
        Only the rows marked ``short`` and no criterion column (README).
    label : str
        The notice (default the model's; pass the hypothesis' label,
        :meth:`~vibrofocus.simulation.hypotheses.Hypothesis.label`).
    """
    head = (f"*{label}.* {len(seeds)} simulated studies of {N_PARTICIPANTS} participants "
            f"(seeds {seeds.start}-{seeds.stop - 1}); model: median [90 % interval] over the seeds; reproduced: "
            "share of seeds in which the row's direction and significance are those of the paper.")
    lines = [head, ""]
    if short:
        lines += [f"| statistic | paper | model v{MODEL_VERSION} (simulated) | reproduced |", "|---|---|---|---:|"]
    else:
        lines += [f"| statistic | paper | model v{MODEL_VERSION} (simulated) | reproduced | criterion |",
                  "|---|---|---|---:|---|"]
    for r in rows:
        if short and not r["short"]:
            continue
        share = f"{r['share']:.0%}" if np.isfinite(r["share"]) else "—"
        cells = [r["label"], r["paper"], _num(r), share] + ([] if short else [r["criterion"] or "—"])
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)
