"""The hypotheses' measured tables, printed by ``scripts/hypotheses_table.py`` (a MODEL, not data).

Every registered hypothesis, with its fitted parameters, simulates the same 40 studies of
20 participants (the fit's held-out seeds, ``vibrofocus.simulation.fitting.HELD_OUT_SEEDS``)
on a feature bank. Two tables:

- ``hypotheses-measured`` (:func:`markdown`): with the fast path and the vectorized
  statistics, per hypothesis the mean Study 1 error per method, the share of studies in
  which the inverse filter's mean error is below funneling's, and the shares in which the
  method tests and the paper's directional claims are significant;
- ``hypotheses-findings`` (:func:`findings_markdown`): per finding of the paper, in how
  many of the held-out studies it holds under each hypothesis, analysed independently
  (:mod:`.findings`), beside the issue's baseline (:mod:`.baseline`) and each finding's
  bar: two thirds of the studies for the two headline findings, the baseline's share for
  the others; a count under its bar is marked. Then each hypothesis' fit loss and
  held-out loss (the default is the one of lowest held-out loss).
"""

from __future__ import annotations

import math

import numpy as np

from vibrofocus.simulation.bank import FeatureBank, simulate_cell_means
from vibrofocus.simulation.fitting import HELD_OUT_SEEDS
from vibrofocus.simulation.hypotheses import DEFAULT_HYPOTHESIS, available_hypotheses, hypothesis, hypothesis_fits
from vibrofocus.simulation.power import study_statistics

from .baseline import HEADLINE_BAR, HEADLINE_KEYS, baseline
from .findings import ROWS, held_out

SEEDS = HELD_OUT_SEEDS
N = 20


def baseline_counts() -> dict | None:
    """The baseline's counts on the table's seeds (``holds``, ``studies``, ``s2_reduction``), or None."""
    return baseline().get(f"{SEEDS[0]}-{SEEDS[-1]}")


def bar(key: str, base: dict | None) -> int | None:
    """The least count of studies at which the finding ``key`` meets its bar (None: no bar known)."""
    if key in HEADLINE_KEYS:
        return math.ceil(HEADLINE_BAR * len(SEEDS))
    return None if base is None else base["holds"].get(key)


def row(name: str, bank: FeatureBank) -> str:
    stats = []
    for seed in SEEDS:
        st = study_statistics(simulate_cell_means(N, np.random.default_rng([seed, N]), bank=bank, hypothesis=name))
        stats.append(st)
    err = np.array([s["s1_error_by_method"] for s in stats])
    share = lambda key: f"{np.mean([s[key] < 0.05 for s in stats]):.0%}"  # noqa: E731
    lower = f"{np.mean(err[:, 1] < err[:, 0]):.0%}"
    red = np.median([s["s2_reduction"] for s in stats])
    return (f"| `{name}` | {' / '.join(f'{v:.2f}' for v in err.mean(axis=0))} | {lower} | {share('s1_method_p')} | "
            f"{share('s1_inverse_below_p')} | {share('s2_method_p')} | {share('s2_inverse_fewer_p')} | {red:.0%} |")


def markdown(bank: FeatureBank) -> str:
    lines = [f"{len(SEEDS)} studies of {N} participants (seeds {SEEDS[0]}-{SEEDS[-1]}), feature bank of "
             f"{bank.n_forearms} forearms at {bank.levels} levels; `scripts/hypotheses_table.py`. Labels: "
             + "; ".join(f"{hypothesis(h).label()}" for h in available_hypotheses()) + ".", "",
             "| hypothesis | Study 1 error, funneling / inverse / combination (mm) | inverse below funneling "
             "| Study 1 method (RM-ANOVA) | inverse below funneling (Bonferroni) | Study 2 method (Friedman) "
             "| fewer points with the inverse (Bonferroni) | Study 2 reduction (median) |",
             "|---|---|---:|---:|---:|---:|---:|---:|"]
    lines += [row(name, bank) for name in available_hypotheses()]
    return "\n".join(lines)


def _seeds(budget: dict | None) -> str:
    """The random path of a search's budget: the ``--rng-seed`` of each stage, first to last."""
    seeds = []
    while budget is not None:
        seeds.insert(0, str(budget["rng_seed"]))
        budget = budget.get("start")
    return "-".join(seeds)


def findings_markdown(bank: FeatureBank) -> str:
    """Per finding, in how many held-out studies it holds under each hypothesis."""
    names = available_hypotheses()
    res = {name: held_out(SEEDS, N, bank, name) for name in names}
    fits = hypothesis_fits()["hypotheses"]
    base = baseline_counts()
    head = " | ".join(f"`{n}`{' (default)' if n == DEFAULT_HYPOTHESIS else ''}" for n in names)
    lines = [f"Held-out check: {len(SEEDS)} studies of {N} participants (seeds {SEEDS[0]}-{SEEDS[-1]}, never used "
             f"by the fit), feature bank of {bank.n_forearms} forearms at {bank.levels} levels, each hypothesis with "
             "its fitted parameters, analysed with pingouin and scipy (`scripts/check_findings.py`, "
             "`scripts/hypotheses_table.py`). Baseline: the participants of commit c313a27 (model v3, every method "
             "at equal peak drive) on the same seeds, by that commit's own check "
             "(`scripts/fits/baseline-c313a27.json`). Bar: the two headline findings in two thirds of the studies, "
             "every other finding at least as often as under the baseline; **below** marks a count under its bar. "
             "A model, not data.", "",
             f"| finding of the paper | {head} | baseline (c313a27) | bar |", "|---|" + "---:|" * (len(names) + 2)]
    for label, key in ROWS:
        least = bar(key, base)
        cells = []
        for n in names:
            k = sum(bool(r[key]) for r in res[n])
            cells.append(f"{k} of {len(SEEDS)}" + (" **below**" if least is not None and k < least else ""))
        known = base is not None and key in base["holds"]
        cells.append(f"{base['holds'][key]} of {base['studies']}" if known else "not measured")
        cells.append("—" if least is None else f"{least} or more")
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    red = {n: np.array([r["s2_reduction"] for r in res[n]]) for n in names}
    base_red = (f"{base['s2_reduction']['median']:.0%} [{base['s2_reduction']['p5']:.0%}, "
                f"{base['s2_reduction']['p95']:.0%}]" if base is not None else "not measured")
    lines.append("| Study 2 reduction of selected points, inverse vs funneling (paper: about 20 %), median [5th, 95th "
                 "percentile] | " + " | ".join(f"{np.median(v):.0%} [{np.percentile(v, 5):.0%}, "
                                             f"{np.percentile(v, 95):.0%}]" for v in red.values())
                 + f" | {base_red} | — |")
    # The losses are those adopt recorded, on the seeds it recorded with them (the same for
    # every fit: tests/simulation/test_hypotheses.py).
    some = next(iter(fits.values()))
    fit_seeds, held = (f"{a}-{b - 1}" for a, b in (some["fit_seeds"], some["held_out_seeds"]))
    # Every hypothesis has the same paths (tests/simulation/test_hypotheses.py): name them once.
    path_seeds = " / ".join(_seeds(p["budget"]) for p in some["paths"])
    lines.append(f"| fit loss of each random path of the search (its seeds {path_seeds}; the "
                 "lowest is kept) | " + " | ".join(" / ".join(f"{p['loss_fit']:.3f}" for p in fits[n]["paths"])
                                                   if n in fits else "not fitted" for n in names) + " | — | — |")
    for title, key in ((f"fit loss, the search's weights (fit seeds {fit_seeds}), the path kept", "loss_fit"),
                       (f"held-out loss, the search's weights (seeds {held}; lowest: the default)",
                        "loss_held_out_search_weights"),
                       (f"held-out loss, the standard objective, every finding weighted alike (seeds {held})",
                        "loss_held_out")):
        lines.append(f"| {title} | " + " | ".join(f"{fits[n][key]:.3f}" if n in fits else "not fitted"
                                                  for n in names) + " | — | — |")
    return "\n".join(lines)
