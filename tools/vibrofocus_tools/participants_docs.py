"""The tables of docs/simulated-participants.md made from the fits (a MODEL, not data).

:func:`table` writes the parameters of every hypothesis, the fits' budget, the
posterior-predictive check's statement and the power table between their markers in
``docs/simulated-participants.md`` (atomically); with ``check`` it only compares
(``scripts/fit_participants.py table``). The check's own table is written by
``scripts/ppc_table.py --docs``.
"""

from __future__ import annotations

from vibrofocus.io import write_text
from vibrofocus.simulation.hypotheses import hypothesis
from vibrofocus.simulation.perception import MODEL_LABEL, PARAMETER_SOURCES, PerceptualModel

from .markers import ROOT, replace_between_markers

PAGES = {"docs": ROOT / "docs" / "simulated-participants.md"}


def _value(v) -> str:
    if isinstance(v, tuple):
        return "(" + ", ".join(_value(x) for x in v) + ")"
    return f"{v:.4g}" if isinstance(v, float) else str(v)


def _cell(h, model, name: str) -> str:
    """One hypothesis' value of a parameter, marked free (with its range), inert or fixed."""
    free = {r.index: r for r in h.free_parameters if r.name == name}
    value = getattr(model, name)
    if name in h.inert_parameters():
        return f"{_value(value)} (inert)"

    def one(v, key):
        return f"**{_value(v)}**" if key in free else (f"{_value(v)} (assumed)" if _key(name, key) in h.assumed
                                                        else _value(v))
    if isinstance(value, tuple):
        return "(" + ", ".join(one(v, i) for i, v in enumerate(value)) + ")"
    return one(value, None)


def _key(name: str, index) -> str:
    return name if index is None else f"{name}[{index}]"


def parameters_markdown() -> str:
    """Every hypothesis' parameters, which are free (fitted within a sourced range), and the ranges, as markdown."""
    from vibrofocus.simulation.hypotheses import available_hypotheses

    names = available_hypotheses()
    hs = {n: hypothesis(n) for n in names}
    models = {n: hs[n].model() for n in names}
    lines = [f"*{MODEL_LABEL}.* Each hypothesis' model (`hypothesis(name).model()`; SI units: m, s, dB, Hz). "
             "**Bold**: free under that hypothesis, fitted within its range (below); *inert*: the hypothesis never "
             "reads it (switching it changes no answer, tested), so it is not fitted; *assumed*: fitted to the paper's "
             "statistics but not recovered from the paper's design (docs/fitting-hypotheses.md, \"Parameter "
             "recovery\"), so fixed there as an assumption and not fitted to a lab's trials; others fixed. A pair (lo, hi) "
             "is the uniform range of a trait across simulated participants, except `bias_mean_m`, the population's "
             "mean bias (x across the arm, y along it).", "",
             "| parameter | " + " | ".join(f"`{n}`" for n in names) + " | kind | note |",
             "|---|" + "---|" * (len(names) + 2)]
    free_somewhere = {r.name for h in hs.values() for r in h.free_parameters}
    same = [k for k in PARAMETER_SOURCES if k not in free_somewhere
            and len({repr(getattr(models[n], k)) for n in names}) == 1]
    for name, (kind, note) in PARAMETER_SOURCES.items():
        if name not in same:
            lines.append(f"| `{name}` | " + " | ".join(_cell(hs[n], models[n], name) for n in names)
                         + f" | {kind} | {note} |")
    fixed = "; ".join(f"`{k}` = {_value(getattr(models[names[0]], k))} ({PARAMETER_SOURCES[k][1]})" for k in same)
    lines += ["", f"Fixed, the same under every hypothesis: {fixed}.", "",
              "The free parameters' ranges and their sources:", "",
              "| parameter | range | source |", "|---|---|---|"]
    seen = {}
    for n in names:
        for r in hs[n].free_parameters:
            seen.setdefault(r.key, r)
    for key, r in seen.items():
        lines.append(f"| `{key}` | {r.lo:.4g} to {r.hi:.4g} | {r.source} |")
    return "\n".join(lines)


#: The power table of the docs: sample sizes and studies per size.
POWER_SIZES, POWER_STUDIES = (10, 20, 30), 200


def _direction(conclusion: dict, test: str, contrasts: dict) -> str:
    """`` (funneling < inverse)``: the one direction a robust method conclusion has, or nothing."""
    if not conclusion["direction"]:
        return ""
    c = next(c for c in contrasts.values() if test in (c["paper"], c["reverse"], c["omnibus"]))
    d = next(iter(conclusion["direction"].values()))
    return f" ({c.get(d + '_reads', 'neither direction')})"


def power_markdown() -> str:
    """Power of each test against N under every hypothesis (``vibrofocus power``'s numbers), as markdown."""
    from vibrofocus.simulation.bank import default_bank
    from vibrofocus.simulation.hypotheses import available_hypotheses
    from vibrofocus.simulation.power import (CONTRASTS, DIRECTIONAL_TESTS, REVERSE_TESTS, ROBUST_POWER, TESTS,
                                             PowerDesign, direction_sentences, effect_directions, robust_conclusions,
                                             run_power)

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
    for key, label in TESTS + DIRECTIONAL_TESTS + REVERSE_TESTS:
        powers = {h: {r["n_participants"]: r["power"] for r in tables[h] if r["test"] == key} for h in names}
        verdicts = [f"N = {n}: {robust[(key, n)]['conclusion']}{_direction(robust[(key, n)], key, CONTRASTS)}"
                    for n in POWER_SIZES if robust[(key, n)]["robust"]]
        lines.append(f"| {label} | " + " | ".join(" / ".join(f"{powers[h][n]:.2f}" for n in POWER_SIZES) for h in names)
                     + f" | {'; '.join(verdicts) or 'none: the hypotheses disagree'} |")
    # The omnibus method tests are robust only with one post hoc direction: say which.
    lines += [""] + [f"- {s[0].upper()}{s[1:]}." for s in direction_sentences(effect_directions(tables)).values()]
    return "\n".join(lines)


def budget_markdown() -> str:
    """The shipped fits' budget, seeds and losses (``hypotheses_fit.json``), as markdown."""
    from vibrofocus.simulation.hypotheses import hypothesis_fits

    fits = hypothesis_fits()["hypotheses"]
    # The shipped fits moved every sourced parameter; those parameter recovery did not
    # recover are fixed since (assumed), so "free now" is fewer than "fitted".
    lines = ["| hypothesis | version | fitted parameters (free now) | random / refinement candidates (path seed) | fit seeds | "
             "loss on the fit seeds | held-out seeds | loss on them |", "|---|---|---:|---|---|---:|---|---:|"]
    for name, f in fits.items():
        b = f["budget"]
        h = hypothesis(name)
        lines.append(f"| `{name}` | {f['version']} | {len(h.free_parameters) + len(h.assumed)} "
                     f"({len(h.free_parameters)}) | {b['n_eval']} / "
                     f"{b['n_refine']} ({b['rng_seed']}) | {f['fit_seeds'][0]}–{f['fit_seeds'][1] - 1} | "
                     f"{f['loss_fit']:.2f} | {f['held_out_seeds'][0]}–{f['held_out_seeds'][1] - 1} | "
                     f"{f['loss_held_out']:.2f} |")
    return "\n".join(lines)


def statement_markdown() -> str:
    """What the posterior-predictive check found, in one paragraph (``hypotheses_fit.json``'s ``ppc``)."""
    from vibrofocus.simulation.hypotheses import hypothesis_fits

    fits = hypothesis_fits()
    check = fits.get("ppc")
    if not check:
        return "*No posterior-predictive check is recorded with the shipped fits.*"
    inside = ", ".join(f"{n} {c['inside']}" for n, c in check["hypotheses"].items())
    return (f"**{check['statement'][0].upper() + check['statement'][1:]}.** The default, `{fits['default']}`, is "
            f"the choice of the rule written before the check (\"The posterior-predictive check\"); the paper's 7 "
            f"statistics inside each hypothesis' 90 % interval: {inside}.")


def table(n_seeds: int, check: bool) -> int:
    """Write (or, with ``check``, compare) the generated blocks of docs/simulated-participants.md.

    ``n_seeds`` is kept for the command line; the blocks no longer depend on it.
    """
    blocks = {
        PAGES["docs"]: {"participants-parameters": parameters_markdown(), "fit-budget": budget_markdown(),
                        "ppc-statement": statement_markdown(), "power-table": power_markdown()},
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
    print(blocks[PAGES["docs"]]["ppc-statement"])
    if check:
        print("up to date" if not stale else "out of date: " + ", ".join(map(str, stale)))
        return 1 if stale else 0
    print("wrote " + (", ".join(map(str, stale)) if stale else "nothing (up to date)"))
    return 0
