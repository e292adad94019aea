"""``vibrofocus design-experiment``: the Study 1 trials that best tell the hypotheses apart."""

from __future__ import annotations

from pathlib import Path

import typer

from ._command import command
from ._errors import user_errors
from ._options import SEED_MAX, comma_list, force_option

#: The longer option helps, kept here so that each option is one line of the command.
_HELP = {
    "out": "Folder for protocol.toml, design.json, design.md, identification.png and design-map.png.",
    "calibration": "A participant's calibration (.nc): the design for that arm, its felt fields from the skin "
                   "model fitted to it (instead of --bank; one forearm).",
    "spread": "Half-width of the draws, a fraction of each free parameter's range (1: the whole range the free "
              "fit searches).",
    "population": "A hypothesis whose fitted parameters every hypothesis takes, so that they differ in their "
                  "readout only (default: each its own shipped parameters).",
    "rivals": "A free-fit model recovery's results (scripts/free_fit_recovery.py, .jsonl): each hypothesis' fits "
              "to the others' simulated studies join its draws, so the design seeks trials a rival cannot fit.",
}


@command("design-experiment", epilog="Example: vibrofocus design-experiment --out design/")
def design_experiment_command(
    out: Path | None = typer.Option(None, "--out", "-o", help=_HELP["out"]),
    hypotheses: str = typer.Option("all", "--hypotheses", help="Hypotheses to tell apart, comma separated, or all."),
    bank: Path | None = typer.Option(None, "--bank", help="Feature bank (.npz; default the shipped simulated one)."),
    calibration: Path | None = typer.Option(None, "--calibration", help=_HELP["calibration"]),
    methods: str | None = typer.Option(None, "--methods", help="Candidate methods (default the bank's)."),
    locations: str | None = typer.Option(None, "--locations", help="Candidate location numbers (default all)."),
    levels: str = typer.Option("0,-5,-10,-15,-20,-30", "--levels", help="Candidate levels, dB re the paper's level."),
    responses: str = typer.Option("location", "--responses",
                                  help="Answers a block may take: location (a key), point (on the arm's picture)."),
    information: str = typer.Option("population", "--information",
                                    help="What the greedy choice maximizes: population (given the forearm) or person."),
    threshold: int = typer.Option(0, "--threshold-trials", min=0, max=200,
                                  help="Put a threshold block of this many trials first in protocol.toml (0: none)."),
    budget: int = typer.Option(81, "--budget", min=4, max=20_000, help="Study 1 trials per participant."),
    draws: int = typer.Option(6, "--parameter-draws", min=1, max=64,
                              help="Parameter sets per hypothesis: the shipped one and draws around it."),
    spread: float = typer.Option(1.0, "--parameter-spread", min=0.0, max=1.0, help=_HELP["spread"]),
    forearms: int = typer.Option(6, "--forearms", min=1, max=1000, help="Bank forearms the design integrates over."),
    traits: int = typer.Option(8, "--traits", min=1, max=1000, help="Participants' trait draws per sample."),
    population: str | None = typer.Option(None, "--population", help=_HELP["population"]),
    rivals: Path | None = typer.Option(None, "--rival-fits", help=_HELP["rivals"]),
    per_pair: int = typer.Option(2, "--rival-fits-per-pair", min=1, max=100,
                                 help="Fits of --rival-fits kept per fitted and true hypothesis."),
    participants: str = typer.Option("1,2,3,4,6,8", "--participants", "-n", help="Sample sizes N of the check."),
    studies: int = typer.Option(200, "--studies", min=0, max=100_000,
                                help="Simulated studies per N and hypothesis (0: no check)."),
    pool: int = typer.Option(60, "--pool", min=2, max=100_000,
                             help="Simulated participants per protocol and hypothesis of the check."),
    score_forearms: int = typer.Option(12, "--score-forearms", min=1, max=1000,
                                       help="Bank forearms of the check's participants."),
    score_draws: int = typer.Option(32, "--score-draws", min=1, max=100_000,
                                    help="Trait draws of the check's marginal likelihood."),
    seed: int = typer.Option(0, "--seed", min=0, max=SEED_MAX, help="Seed of the design (the check uses seed + 1)."),
    scheduler: str | None = typer.Option(None, "--scheduler", help="Dask scheduler address (tcp://host:8786)."),
    workers: int | None = typer.Option(None, "--workers", min=1, max=256, help="LocalCluster workers (default CPUs)."),
    local: bool = typer.Option(False, "--no-dask", help="Run the check in this process (same numbers)."),
    force: bool = force_option(),
) -> None:
    """Design the Study 1 blocks that tell the registered hypotheses apart, and check them by simulation.

    Greedily chooses blocks (a method at a level over a grid of locations, answered by a
    location or a point) that maximize
    the expected information gain about which hypothesis is right, within --budget trials
    per participant; then, on Dask, estimates the probability that model choice by
    marginal likelihood picks the true hypothesis against N, for the design and the
    paper's Study 1. Simulated participants: a MODEL, not data (docs: designing a study).
    """
    with user_errors():
        from rich.console import Console

        from .._atomic import allow_overwrite
        from ..simulation.design import DesignSettings
        from ..workflows import design_study

        allow_overwrite(force)
        settings = DesignSettings(
            hypotheses=None if hypotheses.strip() == "all" else comma_list(hypotheses, "--hypotheses", str),
            methods=comma_list(methods, "--methods", str) if methods else None,
            locations=comma_list(locations, "--locations") if locations else None,
            levels_db=comma_list(levels, "--levels", float), budget=budget, n_parameter_draws=draws,
            parameter_spread=spread,
            n_forearms=forearms, n_traits=traits, seed=seed, population=population,
            responses=comma_list(responses, "--responses", str), information=information)
        console = Console(stderr=True)
        done = design_study(settings, participants=comma_list(participants, "--participants"), studies=studies,
                            bank=bank, calibration=calibration, pool=pool, score_forearms=score_forearms,
                            score_draws=score_draws, scheduler=scheduler, workers=workers, local=local, out=out,
                            threshold_trials=threshold, rival_fits=rivals, rival_fits_per_pair=per_pair,
                            progress=_Notes(console))
        _print_design(done, comma_list(participants, "--participants"), console)


class _Notes:
    """The design workflow's notes on stderr."""

    def __init__(self, console) -> None:
        self.console = console

    def step(self, done: int, total: int, message: str) -> None:
        pass

    def note(self, message: str, **details) -> None:
        self.console.print(message)

    def judged(self, result) -> None:
        pass

    def cancelled(self) -> bool:
        return False


def _print_design(done, ns: list[int], console) -> None:
    """The designed blocks and the check's table at the terminal, then the files and the model label."""
    from rich.console import Console
    from rich.table import Table

    from ..simulation.design import FREE_FIT_CAVEAT

    report = done.report
    table = Table(title=f"Designed Study 1 blocks ({report['label']})")
    for col in ("methods", "level (dB)", "locations", "answer", "repetitions", "trials"):
        table.add_column(col)
    for b in report["blocks"]:
        table.add_row(", ".join(b["methods"]), f"{b['level_db']:+g}", " ".join(map(str, b["locations"])),
                      b["response"], str(b["repetitions"]), str(b["trials"]))
    Console().print(table)
    if done.identification is not None:
        t2 = Table(title="P(true hypothesis chosen), marginal likelihood at the shipped parameters")
        t2.add_column("protocol")
        t2.add_column("true hypothesis")
        for n in ns:
            t2.add_column(f"N={n}", justify="right")
        for p, by in done.identification["rates"].items():
            for h, r in by.items():
                t2.add_row(p, h, *[f"{r[n]:.2f}" for n in ns])
        Console().print(t2)
        console.print(FREE_FIT_CAVEAT, markup=False)
    if done.paths:
        console.print("wrote " + ", ".join(str(p) for p in done.paths))
    console.print(f"[yellow]{report['label']}[/]")
