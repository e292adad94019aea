"""Posterior-predictive check of the hypotheses against the paper's own numbers (a MODEL, not data).

Each registered hypothesis, with its fitted parameters, simulates many studies of the
paper's design (20 participants, 9 locations x 3 methods x 3 repetitions, stimuli at the
paper's levels). For each of the paper's 7 test statistics (de Vlam et al., IEEE ToH
16(4), 2023, Sec. III.B-C: Study 1 location F, its Greenhouse-Geisser epsilon, method F,
interaction F; Study 2 location chi2(8), method chi2(2), and the reduction of selected
points with the inverse filter) the check gives the model's median and 90 % interval
over the studies, and whether the paper's value lies inside. Beside them: the share of
studies in which the Study 1 and Study 2 directions (inverse filter vs funneling,
Bonferroni tests) are significant as in the paper, significant in reverse, or neither;
and the Study 1 answers per target location beside the paper's Fig. 6.

The rule that picks the default hypothesis (written down before any result of this
check was looked at):

1. The default is the hypothesis with the most of the paper's 7 statistics inside its
   90 % posterior-predictive interval (:data:`LEVEL`, over :data:`PPC_SEEDS`).
2. Ties are broken by the paper's Study 1 direction: the larger share of studies in which
   the inverse filter's error is significantly lower than funneling's (Bonferroni paired
   t-test); then the smaller share of studies with the reverse significant; then the
   name, so the choice is deterministic.
3. A hypothesis *reproduces the paper* when at least :data:`MIN_INSIDE` of the 7
   statistics lie inside its interval and the paper's Study 1 direction is significant
   in most (more than half) of its studies. Where the default does not, every output
   says: :data:`NONE_REPRODUCES`.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from ..errors import ValidationError
from .bank import FeatureBank, default_bank, simulate_cell_means
from .fitting.objective import targets
from .perception import posterior_ratio_rule
from .power import directional_shares, study_statistics

__all__ = ["LEVEL", "MIN_INSIDE", "NONE_REPRODUCES", "PPC_SEEDS", "STATISTICS", "FIG6_INSIDE", "reproduces",
           "choose_default", "study_checks", "summarize", "run_ppc", "ppc_markdown", "record_default"]

#: Central interval of the check.
LEVEL = 0.9
#: Statistics (of 7) inside the interval for a hypothesis to reproduce the paper's sizes.
MIN_INSIDE = 5
#: What every output says when no hypothesis reproduces the paper (rule 3).
NONE_REPRODUCES = "no registered hypothesis reproduces both the paper's effect sizes and its Study 1 direction"


def reproduces(check: Mapping[str, Any]) -> bool:
    """Whether one hypothesis' check reproduces the paper (rule 3 of the module).

    Parameters
    ----------
    check : mapping
        ``{"inside": int, "study1": {"paper": share, "reverse": share, "neither": share}, ...}``.
    """
    return int(check["inside"]) >= MIN_INSIDE and float(check["study1"]["paper"]) > 0.5


def choose_default(checks: Mapping[str, Mapping[str, Any]]) -> str:
    """The default hypothesis by the rule of the module (rules 1 and 2).

    Parameters
    ----------
    checks : mapping
        ``{name: check}`` with ``check`` as in :func:`reproduces`.

    Returns
    -------
    str
        The name chosen.
    """
    return min(checks, key=lambda n: (-int(checks[n]["inside"]), -float(checks[n]["study1"]["paper"]),
                                      float(checks[n]["study1"]["reverse"]), n))


#: Seeds of the check's studies (study ``s`` draws from ``default_rng([s, 16])``): seeds no
#: fit, table or earlier check used.
PPC_SEEDS = range(3000, 3200)


#: The paper's 7 statistics: (key of :func:`~vibrofocus.simulation.power.study_statistics`, label, value).
STATISTICS: tuple[tuple[str, str, float], ...] = tuple(targets())
#: Locations (1-9) whose mean perceived position lies inside the target's grid cell in the
#: paper's Fig. 6 (Sec. III.B); not so for the other five.
FIG6_INSIDE = (4, 5, 7, 8)
#: Half the location pitch, m: a mean perceived position within it (per axis) is inside the cell.
_HALF_CELL_M = 5e-3
_DIRECTION_KEYS = ("s1_inverse_below_p", "s1_inverse_above_p", "s2_inverse_fewer_p", "s2_inverse_more_p")


def study_checks(hypothesis: Any, seeds: Sequence[int], *, n_participants: int = 20,
                 bank: FeatureBank | None = None) -> list[dict[str, Any]]:
    """What the check needs of one simulated study per seed, under a hypothesis' fitted model.

    The studies are those of :func:`~vibrofocus.simulation.paper.seed_statistics` (the same
    seeds give the same statistics); the Study 1 answers are counted as they are drawn.

    Parameters
    ----------
    hypothesis : str or Hypothesis
    seeds : sequence of int
    n_participants : int
    bank : FeatureBank, optional
        Default the shipped one.

    Returns
    -------
    list of dict
        Per study: the 7 statistics (:data:`STATISTICS`' keys), the p of the directional
        tests, and ``answers``: Study 1 answer counts, ``[target][answer]`` (9 x 9).
    """
    from .hypotheses import hypothesis as find_hypothesis

    h = find_hypothesis(hypothesis)
    b = bank if bank is not None else default_bank()
    n_loc = len(b.locations_xy)
    out = []
    for s in seeds:
        counts = np.zeros((n_loc, n_loc), dtype=int)
        calls = [0]

        def rule(post: Any, criterion: Any, locations_xy: Any, allowed: Any, percepts: Any, index: Any) -> Any:
            answer, selected = posterior_ratio_rule(post, criterion, locations_xy, allowed, percepts, index)
            if calls[0] % 2 == 0:  # every participant answers Study 1, then Study 2
                np.add.at(counts, (np.asarray(index) % n_loc, answer), 1)
            calls[0] += 1
            return answer, selected

        arrays = simulate_cell_means(n_participants, np.random.default_rng([int(s), 16]), bank=b, model=h.model(),
                                     hypothesis=h, rule=rule)
        st = study_statistics(arrays, methods=b.methods)
        row = {k: float(st[k]) for k, _, _ in STATISTICS}
        row.update({k: float(st[k]) for k in _DIRECTION_KEYS})
        row["answers"] = counts.tolist()
        out.append(row)
    return out


def summarize(studies: Sequence[Mapping[str, Any]], locations_xy: np.ndarray, level: float = LEVEL) -> dict[str, Any]:
    """One hypothesis' check from its studies (:func:`study_checks`).

    Returns
    -------
    dict
        ``statistics``: per key ``{"paper", "median", "low", "high", "inside"}``; ``inside``:
        how many of the 7 lie inside; ``study1`` / ``study2``: shares of studies with the
        paper's direction significant, the reverse, neither; ``answers``: per target (1-9)
        the share of Study 1 answers on each location, the share of studies whose mean
        perceived position lies inside the target's cell, and whether the paper's Fig. 6
        has it inside; ``n_studies``; ``reproduces`` (:func:`reproduces`).
    """
    lo_q = 50.0 * (1.0 - level)
    stats = {}
    for key, label, paper in STATISTICS:
        v = np.array([s[key] for s in studies], dtype=float)
        v = v[np.isfinite(v)]
        med, low, high = (np.percentile(v, [50.0, lo_q, 100.0 - lo_q]) if v.size else (np.nan,) * 3)
        stats[key] = {"label": label, "paper": paper, "median": float(med), "low": float(low), "high": float(high),
                      "inside": bool(low <= paper <= high)}
    shares = directional_shares({20: [dict(s) for s in studies]})
    counts = np.array([s["answers"] for s in studies], dtype=float)  # (studies, target, answer)
    locs = np.asarray(locations_xy, dtype=float)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean_pos = counts @ locs / counts.sum(axis=2, keepdims=True)  # (studies, target, 2)
    inside = np.all(np.abs(mean_pos - locs[None]) < _HALF_CELL_M, axis=2)
    total = counts.sum(axis=(0, 2))
    answers = {str(t + 1): {"share": (counts.sum(axis=0)[t] / max(total[t], 1)).round(4).tolist(),
                            "inside_share": float(inside[:, t].mean()), "paper_inside": (t + 1) in FIG6_INSIDE}
               for t in range(locs.shape[0])}
    out = {"n_studies": len(studies), "level": level, "statistics": stats,
           "inside": int(sum(v["inside"] for v in stats.values())),
           "study1": shares.get("s1_inverse_vs_funneling", {}).get("20", {"paper": 0.0, "reverse": 0.0, "neither": 1.0}),
           "study2": shares.get("s2_inverse_vs_funneling", {}).get("20", {"paper": 0.0, "reverse": 0.0, "neither": 1.0}),
           "answers": answers}
    out["reproduces"] = reproduces(out)
    return out


def _tasks(names: Sequence[str], seeds: Sequence[int], chunk: int) -> list[tuple[str, list[int]]]:
    seeds = list(seeds)
    return [(n, seeds[i:i + chunk]) for n in names for i in range(0, len(seeds), chunk)]


def run_ppc(names: Sequence[str] | None = None, seeds: Sequence[int] = PPC_SEEDS, *, n_participants: int = 20,
            local: bool = False, n_workers: int | None = None, chunk: int = 10, bank: FeatureBank | None = None,
            progress: Callable[[int, int], None] | None = None) -> dict[str, Any]:
    """The posterior-predictive check of every hypothesis, and the default by the module's rule.

    Parameters
    ----------
    names : sequence of str, optional
        Hypotheses (default every registered one).
    seeds : sequence of int
        One study per seed (default :data:`PPC_SEEDS`, 200 studies).
    n_participants : int
    local : bool
        In this process (no Dask); same numbers.
    n_workers : int, optional
        Workers of the ``distributed.LocalCluster`` (one cluster, no dashboard; default
        the CPU count).
    chunk : int
        Studies per task.
    bank : FeatureBank, optional
    progress : callable, optional
        ``progress(done_studies, total_studies)``.

    Returns
    -------
    dict
        ``{"seeds": [first, last + 1], "n_participants", "hypotheses": {name: summary}
        (:func:`summarize`), "default": name, "default_reproduces": bool, "statement": str}``.
    """
    from .hypotheses import available_hypotheses, hypothesis as find_hypothesis

    names = list(names) if names is not None else list(available_hypotheses())
    for n in names:
        find_hypothesis(n)
    seeds = list(seeds)
    if not seeds:
        raise ValidationError("the check needs at least one seed")
    b = bank if bank is not None else default_bank()
    tasks = _tasks(names, seeds, chunk)
    parts: dict[tuple[str, int], list[dict[str, Any]]] = {}
    total, done = len(names) * len(seeds), 0
    if local:
        for name, idx in tasks:
            parts[(name, idx[0])] = study_checks(name, idx, n_participants=n_participants, bank=b)
            done += len(idx)
            if progress is not None:
                progress(done, total)
    else:
        from distributed import Client, LocalCluster, as_completed

        with LocalCluster(n_workers=n_workers or os.cpu_count() or 1, threads_per_worker=1, processes=True,
                          dashboard_address=None) as cluster, Client(cluster) as client:
            bank_f = client.scatter(b, broadcast=True)
            futures = {client.submit(study_checks, name, idx, n_participants=n_participants, bank=bank_f,
                                     pure=False): (name, idx) for name, idx in tasks}
            for fut in as_completed(futures):
                name, idx = futures[fut]
                parts[(name, idx[0])] = fut.result()
                done += len(idx)
                if progress is not None:
                    progress(done, total)
    summaries = {}
    for name in names:
        studies = [s for (n, _), res in sorted(parts.items(), key=lambda kv: (kv[0][0], seeds.index(kv[0][1])))
                   if n == name for s in res]
        summaries[name] = {"label": find_hypothesis(name).label(), **summarize(studies, b.locations_xy)}
    default = choose_default(summaries)
    ok = summaries[default]["reproduces"]
    statement = (f"the default, {default}, reproduces the paper's effect sizes ({summaries[default]['inside']} of 7 "
                 "inside) and its Study 1 direction" if ok else NONE_REPRODUCES)
    return {"seeds": [seeds[0], seeds[-1] + 1], "n_participants": n_participants, "levels": b.levels,
            "hypotheses": summaries, "default": default, "default_reproduces": ok, "statement": statement}


def _share(d: Mapping[str, float]) -> str:
    return f"{d['paper']:.0%} / {d['reverse']:.0%} / {d['neither']:.0%}"


def ppc_markdown(result: Mapping[str, Any]) -> str:
    """The check as markdown: statistics, directions and Fig. 6, one column per hypothesis."""
    hs = result["hypotheses"]
    names = list(hs)
    n = next(iter(hs.values()))["n_studies"]
    lo, hi = result["seeds"]
    head = [f"*{'; '.join(hs[h]['label'] for h in names)}.* {n} simulated studies of {result['n_participants']} "
            f"participants per hypothesis (seeds {lo}-{hi - 1}), stimuli at {result['levels']} levels: the model's "
            "median [90 % interval]; **in** where the paper's value lies inside the interval. Generated by "
            "`scripts/ppc_table.py`.", "",
            "| statistic | paper | " + " | ".join(f"`{h}`" for h in names) + " |",
            "|---|---:|" + "---|" * len(names)]
    for key, label, paper in STATISTICS:
        cells = []
        for h in names:
            s = hs[h]["statistics"][key]
            d = 0 if key == "s2_reduction" else 2
            scale = 100.0 if key == "s2_reduction" else 1.0
            cells.append(f"{s['median'] * scale:.{d}f} [{s['low'] * scale:.{d}f}, {s['high'] * scale:.{d}f}] "
                         + ("**in**" if s["inside"] else "out"))
        shown = f"{paper * 100:.0f} %" if key == "s2_reduction" else f"{paper:.3g}"
        lines = f"| {label}{' (%)' if key == 's2_reduction' else ''} | {shown} | " + " | ".join(cells) + " |"
        head.append(lines)
    head.append("| **inside, of 7** | 7 | " + " | ".join(f"**{hs[h]['inside']}**" for h in names) + " |")
    head.append("| Study 1 direction: paper / reverse / neither | inverse < funneling | "
                + " | ".join(_share(hs[h]["study1"]) for h in names) + " |")
    head.append("| Study 2 direction: paper / reverse / neither | inverse fewer | "
                + " | ".join(_share(hs[h]["study2"]) for h in names) + " |")
    for t in range(1, 10):
        cells = []
        for h in names:
            a = hs[h]["answers"][str(t)]
            cells.append(f"{a['share'][t - 1]:.0%} on target; inside {a['inside_share']:.0%}")
        paper = "inside" if t in FIG6_INSIDE else "outside"
        head.append(f"| Study 1 answers, target {t} (Fig. 6: mean {paper} the cell) | {paper} | "
                    + " | ".join(cells) + " |")
    head += ["", f"Default by the rule written before the check (`vibrofocus.simulation.ppc`): **{result['default']}**; "
             f"{result['statement']}."]
    return "\n".join(head)


def record_default(result: Mapping[str, Any], path: str | os.PathLike) -> dict[str, Any]:
    """Write the check's default and its summary into a fits file (``hypotheses_fit.json``).

    Parameters
    ----------
    result : mapping
        From :func:`run_ppc`, covering every hypothesis of the file.
    path : path-like
        The fits file (written atomically).

    Returns
    -------
    dict
        The file's new content: ``default`` the check's choice, ``ppc`` its summary
        (seeds, per hypothesis: statistics inside, directions; the statement).
    """
    import json

    from .._atomic import write_text

    with open(path, encoding="utf-8") as fh:
        doc = json.load(fh)
    missing = set(doc.get("hypotheses", {})) - set(result["hypotheses"])
    if missing:
        raise ValidationError(f"the check did not cover {', '.join(sorted(missing))}: run it on every hypothesis")
    doc["default"] = result["default"]
    doc["ppc"] = {"rule": "most of the paper's 7 statistics inside the 90 % posterior-predictive interval; ties: the "
                          "larger share of studies with the paper's Study 1 direction significant "
                          "(vibrofocus.simulation.ppc)",
                  "seeds": list(result["seeds"]), "n_participants": result["n_participants"],
                  "statement": result["statement"], "default_reproduces": bool(result["default_reproduces"]),
                  "hypotheses": {n: {"inside": s["inside"], "study1": s["study1"], "study2": s["study2"],
                                     "reproduces": s["reproduces"]} for n, s in result["hypotheses"].items()}}
    write_text(path, json.dumps(doc, indent=1) + "\n", what="fits")
    return doc
