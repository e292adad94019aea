"""The model-recovery tables of docs/fitting-hypotheses.md, from the results files of the recovery scripts.

``scripts/model_recovery.py`` and ``scripts/free_fit_recovery.py`` append one scored study
per line to a JSON-lines file under ``scripts/fits/recovery/`` (its first line: the run's
settings); the blocks here are pure functions of such a file, so a test can check that
the page shows what the file holds.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from .markers import ROOT

#: Where the recovery scripts keep their results.
RESULTS = ROOT / "scripts" / "fits" / "recovery"


def read_results(path: Path) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    """A results file's settings (its first line) and its scored studies."""
    lines = path.read_text(encoding="utf-8").splitlines()
    if not lines:
        raise SystemExit(f"{path} is empty: no settings line")
    return json.loads(lines[0])["settings"], [json.loads(x) for x in lines[1:] if x.strip()]


def resumed_studies(path: Path, settings: dict[str, Any], *, create: bool = False) -> list[dict[str, Any]]:
    """The studies a results file already holds for a run of ``settings`` (none if it does not exist).

    A file whose first line holds other settings is another run's: refused, so that a
    resumed run never mixes studies of two. ``create``: a file that does not exist is
    started, its first line the settings (a run about to append its studies).
    """
    if not path.exists():
        if create:
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(json.dumps({"settings": settings}) + "\n", encoding="utf-8")
        return []
    held, studies = read_results(path)
    if held != settings:
        raise SystemExit(f"{path} holds a run with other settings; give another --results")
    return studies


def confusion_markdown(names: list[str], counts: list[list[int]], note: str, *,
                       only: list[str] | None = None) -> str:
    """Counts of (true, chosen) as a markdown table with each row's share correct, then ``note``.

    ``only``: the true hypotheses to show a row of (default every one); the columns are
    always every hypothesis, the choices.
    """
    rows = ["| true \\ chosen | " + " | ".join(names) + " | correct |", "|---" * (len(names) + 2) + "|"]
    for name, row in zip(names, counts):
        if only is not None and name not in only:
            continue
        total = sum(row)
        share = f"{row[names.index(name)] / total:.0%}" if total else "-"
        rows.append(f"| {name} | " + " | ".join(str(c) for c in row) + f" | {share} |")
    return "\n".join(rows) + f"\n\n{note}"


def rates_markdown(names: list[str], studies: list[dict[str, Any]], n_participants: int) -> str:
    """Per true hypothesis: the rate chosen with its 95 % exact interval, decisive choices, the lead."""
    from vibrofocus.participant_models.fitting import recovery_rates

    rates = recovery_rates(names, studies)
    rows = ["| true | chosen | 95 % interval | decided by > 2 SE (right / wrong) | most often chosen instead | "
            "true minus best other, nats per participant |", "|---" * 6 + "|"]
    for name, r in rates.items():
        rows.append(f"| {name} | {r['correct']} of {r['studies']} ({r['rate']:.0%}) | {r['low']:.2f}-{r['high']:.2f} | "
                    f"{r['decisive'][0]} / {r['decisive'][1]} | {r['rival'] or '-'} | "
                    f"{r['lead'] / n_participants:+.2f} |")
    return "\n".join(rows)


def free_fit_block(path: Path) -> str:
    """The docs block of a ``scripts/free_fit_recovery.py`` results file (marker: the file's stem)."""
    from vibrofocus.participant_models.fitting import confusion

    settings, studies = read_results(path)
    names = list(settings["hypotheses"])
    n = int(settings["n"])
    run = [name for name in names if any(r["true"] == name for r in studies)]
    per_row = sorted({sum(r["true"] == name for r in studies) for name in run})
    shown = f" ({' and '.join(run)} only)" if run != names else ""
    trials = sum(len(b["methods"]) * len(b["locations"]) * b["repetitions"] for b in settings["plan"])
    plan = ("the paper's Study 1 (every method x location three times, 0 dB)" if settings["plan"] == _paper_plan()
            else f"a designed protocol ({trials} trials per participant)")
    minutes = sum(r.get("elapsed_s", 0.0) for r in studies) / 60.0
    note = (f"{'/'.join(map(str, per_row))} simulated studies of N = {n} per true hypothesis{shown}, "
            "a MODEL, not data; "
            f"{plan}, seed {settings['seed']}; every hypothesis' free parameters{_fixed(settings)} fitted to each study "
            f"({settings['draws']} population draws, Nelder-Mead with {settings['maxiter']} iterations per start) and "
            f"scored by leave-one-participant-out ELPD on {settings['score_draws']} other draws "
            f"(`compare_hypotheses`, the fit of `analyze --hypotheses`); {minutes:.0f} min of wall clock on a "
            "shared 2-core machine. "
            f"Results: `{path.relative_to(ROOT) if path.is_relative_to(ROOT) else path}`.")
    table = confusion_markdown(names, confusion(names, studies), note, only=run)
    return (table + "\n\n"
            + rates_markdown(names, studies, n))


def _fixed(settings: dict[str, Any]) -> str:
    """What a run's ``--fix`` kept out of the fit, as words (nothing without it)."""
    fixed = settings.get("fixed") or {}
    return "".join(f" ({name} with {', '.join(keys)} fixed at its shipped values)" for name, keys in fixed.items())


def _paper_plan() -> list[dict[str, Any]]:
    from vibrofocus.participant_models.design import paper_plan

    return json.loads(json.dumps([vars(b) for b in paper_plan()], default=str))
