"""The tables of docs/simulated-participants.md made from the fit (a MODEL, not data).

:func:`table` evaluates the default hypothesis on seeds 0..N-1 and writes the side-by-side
table with the paper, the parameters of every hypothesis, the residuals and the power
table between their markers in ``docs/simulated-participants.md`` (atomically); with
``check`` it only compares (``scripts/fit_participants.py table``).
"""

from __future__ import annotations

from vibrofocus.io import write_text
from vibrofocus.simulation.fitting import residuals
from vibrofocus.simulation.hypotheses import hypothesis
from vibrofocus.simulation.paper import compare, comparison_markdown, seed_statistics
from vibrofocus.simulation.perception import MODEL_LABEL, PARAMETER_SOURCES, PerceptualModel

from .markers import ROOT, replace_between_markers

PAGES = {"docs": ROOT / "docs" / "simulated-participants.md"}


def _value(v) -> str:
    if isinstance(v, tuple):
        return "(" + ", ".join(_value(x) for x in v) + ")"
    return f"{v:.4g}" if isinstance(v, float) else str(v)


def parameters_markdown() -> str:
    """The parameters of every hypothesis' fitted model with their kind and note, as markdown."""
    from vibrofocus.simulation.hypotheses import available_hypotheses

    names = available_hypotheses()
    models = {h: hypothesis(h).model() for h in names}
    lines = [f"*{MODEL_LABEL}.* Values of each hypothesis' model (`hypothesis(name).model()`: the defaults of "
             "`PerceptualModel()` changed by the hypothesis' fit; SI units: m, s, dB, Hz); ranges (lo, hi) are "
             "uniform across simulated participants.", "",
             "| parameter | " + " | ".join(f"`{h}`" for h in names) + " | `PerceptualModel()` | kind | note |",
             "|---|" + "---|" * (len(names) + 3)]
    for name, (kind, note) in PARAMETER_SOURCES.items():
        values = [_value(getattr(models[h], name)) for h in names] + [_value(getattr(PerceptualModel(), name))]
        lines.append(f"| `{name}` | " + " | ".join(values) + f" | {kind} | {note} |")
    return "\n".join(lines)


#: The power table of the docs: sample sizes and studies per size.
POWER_SIZES, POWER_STUDIES = (10, 20, 30), 200


def power_markdown() -> str:
    """Power of each test against N under every hypothesis (``vibrofocus power``'s numbers), as markdown."""
    from vibrofocus.simulation.bank import default_bank
    from vibrofocus.simulation.hypotheses import available_hypotheses
    from vibrofocus.simulation.power import DIRECTIONAL_TESTS, ROBUST_POWER, TESTS, PowerDesign, robust_conclusions, run_power

    names = available_hypotheses()
    tables = {h: run_power(PowerDesign(n_participants=POWER_SIZES, n_studies=POWER_STUDIES, hypothesis=h),
                           local=True)["table"] for h in names}
    robust = {(r["test"], r["n_participants"]): r for r in robust_conclusions(tables)}
    sizes = " / ".join(map(str, POWER_SIZES))
    lines = ["*" + "; ".join(hypothesis(h).label() for h in names) + f".* Power (share of {POWER_STUDIES} simulated studies with p < 0.05; binomial SE at most 3.5 points) "
             f"of each test at N = {sizes} participants, under each hypothesis, stimuli at {default_bank().levels} "
             f"levels, from `vibrofocus power --participants {','.join(map(str, POWER_SIZES))} --studies "
             f"{POWER_STUDIES}`. A conclusion (powered at {ROBUST_POWER:.0%} or not) is *robust* where every "
             "hypothesis agrees; the last column gives them.", "",
             "| test | " + " | ".join(f"`{h}`, N = {sizes}" for h in names) + " | robust conclusions |",
             "|---|" + "---:|" * len(names) + "---|"]
    for key, label in TESTS + DIRECTIONAL_TESTS:
        powers = {h: {r["n_participants"]: r["power"] for r in tables[h] if r["test"] == key} for h in names}
        verdicts = [f"N = {n}: {robust[(key, n)]['conclusion']}" for n in POWER_SIZES if robust[(key, n)]["robust"]]
        lines.append(f"| {label} | " + " | ".join(" / ".join(f"{powers[h][n]:.2f}" for n in POWER_SIZES) for h in names)
                     + f" | {'; '.join(verdicts) or 'none: the hypotheses disagree'} |")
    return "\n".join(lines)


def table(n_seeds: int, check: bool) -> int:
    seeds = range(n_seeds)
    stats = seed_statistics(None, seeds)
    rows = compare(stats)
    label = hypothesis().label()
    resid = (f"`scripts/fit_participants.py report` ({label}; the default hypothesis, the table's {n_seeds} seeds; "
             "model: median over seeds):\n\n```\n" + residuals(stats) + "\n```")
    power = power_markdown()
    blocks = {
        PAGES["docs"]: {"participants-table": comparison_markdown(rows, seeds, label=label),
                        "participants-parameters": parameters_markdown(), "fit-residuals": resid,
                        "power-table": power},
    }
    stale = []
    for page, parts in blocks.items():
        text = page.read_text(encoding="utf-8")
        new = text
        for name, block in parts.items():
            new = replace_between_markers(new, name, block, page)
        if new != text:
            stale.append(page)
            if not check:
                write_text(page, new, what="page")
    print(blocks[PAGES["docs"]]["participants-table"])
    if check:
        print("up to date" if not stale else "out of date: " + ", ".join(map(str, stale)))
        return 1 if stale else 0
    print("wrote " + (", ".join(map(str, stale)) if stale else "nothing (up to date)"))
    return 0
