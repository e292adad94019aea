"""``vibrofocus power``: study power by simulation, on Dask."""

from __future__ import annotations

from pathlib import Path

import typer

from ._errors import user_errors
from ._options import SEED_MAX, comma_list, force_option
from ._command import command


def _ints(text: str, name: str) -> tuple[int, ...]:
    return comma_list(text, name, int)


@command(
    "power",
    epilog="Example: vibrofocus power --participants 10,15,20,25,30 --studies 200 --out power/",
)
def power_command(
    participants: str = typer.Option("10,15,20,25,30", "--participants", "-n",
                                     help="Sample sizes N, comma separated, each from 3 to 1000."),
    studies: int = typer.Option(200, "--studies", min=1, max=100_000, help="Simulated studies per N."),
    repetitions: int = typer.Option(3, "--repetitions", min=1, max=100, help="Trials per condition and study."),
    methods: str | None = typer.Option(None, "--methods", help="Methods, comma separated: at least two of the "
                                                               "feature bank's (the shipped bank: funneling, inverse, "
                                                               "combination, the default; others, such as minimax, "
                                                               "from a bank of --bank)."),
    bank: Path | None = typer.Option(None, "--bank", help="Feature bank (.npz) built by "
                                                          "scripts/build_feature_bank.py --methods ... --out FILE "
                                                          "(default the one shipped with vibrofocus)."),
    locations: str | None = typer.Option(None, "--locations", help="Location numbers 1-9, comma separated, at "
                                                                   "least two (default 1-9)."),
    alpha: float = typer.Option(0.05, "--alpha", help="Significance level, in (0, 1)."),
    seed: int = typer.Option(0, "--seed", min=0, max=SEED_MAX,
                             help="Master seed (study j of size N uses [seed, N, j])."),
    scheduler: str | None = typer.Option(
        None, "--scheduler", help="Dask scheduler address (tcp://host:8786); default a LocalCluster on this machine."
    ),
    workers: int | None = typer.Option(None, "--workers", min=1, max=256,
                                       help="LocalCluster worker processes (default: CPUs)."),
    local: bool = typer.Option(False, "--no-dask", help="Run in this process without Dask (same numbers)."),
    out: Path | None = typer.Option(None, "--out", "-o", help="Folder for power.json, power.csv and power.png."),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="No progress bar."),
    force: bool = force_option(),
    hypotheses: str = typer.Option(
        "all", "--hypotheses",
        help="Hypotheses of how simulated participants read the felt field, comma separated, or all (default): "
             "each is simulated with the same seeds, side by side, and a conclusion (a test powered at 80 % or "
             "not) is marked robust only where all agree.",
    ),
    skin: str = typer.Option("nominal", "--skin",
                             help="Skin preset of the simulated forearms. Only nominal for now: the perceptual "
                                  "model and its feature bank are fitted on it (docs: simulated participants)."),
) -> None:
    """Power of each test of docs/method.md (Analysis) against the number of participants, by simulation.

    Studies are simulated with the perceptual MODEL of simulated participants (model v3,
    fitted to the source paper's statistics), not data, under each hypothesis of how they
    read the felt field (--hypotheses): the power is that of the model's effect sizes. The
    paper's directional claims (inverse below funneling; fewer points with the inverse
    filter) and their reverse are reported beside the omnibus tests, with the power that
    the paper's own Study 1 statistic implies for a replication.
    """
    with user_errors():
        from rich.console import Console
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn
        from rich.table import Table

        from .._atomic import allow_overwrite
        from .._validation import check_in_range
        from ..simulation.perception import MODEL_LABEL
        from ..simulation.power import DIRECTIONAL_TESTS, REVERSE_TESTS, TESTS, PowerDesign, run_power

        allow_overwrite(force)
        from ..errors import ValidationError
        from ..skin import skin_preset
        from ..simulation.perception import STUDY_SKIN

        if skin_preset(skin).name != STUDY_SKIN:
            # Its effect sizes come from a model fitted on one skin: on another, the numbers
            # would look like power but rest on nothing fitted.
            raise ValidationError(
                f"--skin {skin}: the simulated participants' perceptual model and its feature bank are fitted on "
                f"the {STUDY_SKIN} skin only; power on {skin} needs them refitted on it first"
            )
        check_in_range(alpha, "--alpha", 0.0, 1.0, inclusive=False)
        from ..simulation.hypotheses import available_hypotheses, hypothesis as find_hypothesis

        names = (available_hypotheses() if hypotheses.strip() == "all"
                 else tuple(dict.fromkeys(find_hypothesis(h.strip()).name for h in hypotheses.split(",") if h.strip())))
        if not names:
            raise ValidationError("--hypotheses: name at least one (or all)")
        design = PowerDesign(
            n_participants=_ints(participants, "--participants"), n_studies=studies, repetitions=repetitions,
            methods=tuple(m.strip() for m in methods.split(",") if m.strip()) if methods else None,
            locations=_ints(locations, "--locations") if locations else None, alpha=alpha, seed=seed,
            hypothesis=names[0],
        )
        feature_bank = None
        if bank is not None:
            from ..simulation.bank import FeatureBank

            feature_bank = FeatureBank.load(bank)
        if out is not None:
            from .._atomic import check_writable, make_output_folder

            make_output_folder(out)
            check_writable(out / "power.json", what="power results")  # before the simulations, not after
        console = Console(stderr=True)
        console.print(f"[yellow]{MODEL_LABEL}[/]")
        import dataclasses

        from ..simulation.power import (CONTRASTS, direction_sentences, effect_directions, paper_implied_power,
                                        robust_conclusions)

        per: dict[str, dict] = {}
        with Progress(
            TextColumn("studies"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
            console=console, disable=quiet,
        ) as bar:
            each = len(design.n_participants) * design.n_studies
            task = bar.add_task("studies", total=each * len(names))
            for k, name in enumerate(names):
                per[name] = run_power(
                    dataclasses.replace(design, hypothesis=name), scheduler=scheduler, n_workers=workers, local=local,
                    bank=feature_bank,
                    progress=lambda done, total, _k=k: bar.update(task, completed=_k * each + done),
                )
        result = dict(per[names[0]])
        result["hypotheses"] = {name: {"label": r["label"], "hypothesis": r["hypothesis"], "table": r["table"]}
                                for name, r in per.items()}
        tables = {name: r["table"] for name, r in per.items()}
        result["robust"] = robust_conclusions(tables)
        result["directional"] = {c: {name: r["directional"][c] for name, r in per.items() if c in r["directional"]}
                                 for c in CONTRASTS if any(c in r["directional"] for r in per.values())}
        directions = effect_directions(tables)
        result["directions"] = directions
        result["direction_sentences"] = direction_sentences(directions)
        result["paper_implied"] = paper_implied_power(design.n_participants, alpha)
        result["elapsed_s"] = sum(r["elapsed_s"] for r in per.values())
        robust = {(r["test"], r["n_participants"]): r for r in result["robust"]}
        table = Table(title=f"Power by simulation ({MODEL_LABEL}; stimuli at {result['levels']} levels), "
                            f"{design.n_studies} studies per N, alpha {alpha}; *: robust, every hypothesis agrees "
                            f"on powered (>= 0.8) or not and, for a method test, on the direction of the effect")
        table.add_column("test")
        table.add_column("hypothesis")
        for n in design.n_participants:
            table.add_column(f"N={n}", justify="right")
        for key, label in TESTS + DIRECTIONAL_TESTS + REVERSE_TESTS:
            for name in names:
                by = {(r["test"], r["n_participants"]): r for r in per[name]["table"]}
                if (key, design.n_participants[0]) not in by:
                    continue  # a directional claim without funneling and the inverse filter
                cells = []
                for n in design.n_participants:
                    cell = f"{by[(key, n)]['power']:.2f}" if by[(key, n)]["n_studies"] else "not run"
                    cells.append(cell + ("*" if robust.get((key, n), {}).get("robust") else ""))
                table.add_row(label if name == names[0] else "", name, *cells)
        if "s1_inverse_vs_funneling" in result["directional"]:
            imp = result["paper_implied"]
            label = (f"Study 1 inverse vs funneling, the paper's own effect (Bonferroni p = {imp['p_bonferroni']:g} "
                     f"-> t({imp['n_paper'] - 1}) = {imp['t']:.2f}, d_z = {imp['d_z']:.2f}; noncentral t)")
            for k, (key, what) in enumerate((("power", "as published"), ("power_half", "half of it"))):
                table.add_row(label if k == 0 else "", what,
                              *[f"{imp[key][str(n)]:.2f}" for n in design.n_participants])
        Console().print(table)
        for sentence in result["direction_sentences"].values():
            Console().print(sentence[0].upper() + sentence[1:] + ".")
        console.print(f"{len(names) * each} studies in {result['elapsed_s']:.1f} s")
        if out is not None:
            paths = write_power(result, out)
            console.print("wrote " + ", ".join(str(p) for p in paths))
        for name in names:
            console.print(f"[yellow]{per[name]['label']}[/]")


def write_power(result: dict, out: Path) -> list[Path]:
    """Write power.json, power.csv (the table) and power.png (power against N per test).

    Each file appears whole or not at all (:mod:`vibrofocus._atomic`) and says it comes
    from simulated participants: ``label`` in the JSON, ``hypothesis`` and ``model``
    columns in the CSV (one block of rows per hypothesis, with ``robust``: every hypothesis
    agrees), the title of the plot (the first hypothesis').
    """
    import json

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import pandas as pd

    from .._atomic import save_figure, write_text
    from ..simulation.power import DIRECTIONAL_TESTS, TESTS

    hyps = result.get("hypotheses") or {result.get("hypothesis", {}).get("name", "v3-centroid"):
                                         {"label": result["label"], "table": result["table"]}}
    robust = {(r["test"], r["n_participants"]): r["robust"] for r in result.get("robust", [])}
    table = pd.concat([pd.DataFrame(h["table"]).assign(hypothesis=name, model=h["label"]) for name, h in hyps.items()],
                      ignore_index=True)
    table["robust"] = [robust.get((t, n)) for t, n in zip(table["test"], table["n_participants"])]
    csv = write_text(out / "power.csv", table.to_csv(index=False), what="power table")
    keys = ("label", "levels", "hypothesis", "design", "table", "hypotheses", "robust", "directional", "directions",
            "direction_sentences", "paper_implied", "elapsed_s")
    js = write_text(out / "power.json", json.dumps({k: result[k] for k in keys if k in result}, indent=1),
                    what="power results")
    first = next(iter(hyps))
    table = table[table["hypothesis"] == first]
    fig, ax = plt.subplots(figsize=(7, 4.5))
    try:
        for key, label in TESTS + DIRECTIONAL_TESTS:
            t = table[table["test"] == key]
            if t.empty:
                continue
            ax.errorbar(t["n_participants"], t["power"], yerr=t["se"], marker="o", capsize=3, label=label)
        ax.axhline(0.8, color="grey", lw=0.8, ls="--")
        ax.set_xlabel("participants N")
        ax.set_ylabel("power")
        ax.set_ylim(-0.02, 1.02)
        levels = f"; stimuli at {result['levels']} levels" if "levels" in result else ""
        ax.set_title(f"Power by simulation — {result['label']}{levels}", fontsize=9)
        ax.legend(fontsize=7, loc="lower right")
        fig.tight_layout()
        png = save_figure(fig, out / "power.png", what="power plot", dpi=120)
    finally:
        plt.close(fig)
    return [js, csv, png]
