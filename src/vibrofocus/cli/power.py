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

        from .._atomic import allow_overwrite
        from ..workflows import study_power

        allow_overwrite(force)
        console = Console(stderr=True)
        with _PowerProgress(console, quiet=quiet) as shown:
            done = study_power(
                participants=_ints(participants, "--participants"), studies=studies, repetitions=repetitions,
                methods=tuple(m.strip() for m in methods.split(",") if m.strip()) if methods else None, bank=bank,
                locations=_ints(locations, "--locations") if locations else None, alpha=alpha, seed=seed,
                scheduler=scheduler, workers=workers, local=local, out=out, hypotheses=hypotheses, skin=skin,
                progress=shown)
        names, result = list(done.per), done.result
        Console().print(power_table(done))
        for sentence in result["direction_sentences"].values():
            Console().print(sentence[0].upper() + sentence[1:] + ".")
        console.print(f"{len(names) * len(done.design.n_participants) * done.design.n_studies} studies in "
                      f"{result['elapsed_s']:.1f} s")
        if done.paths:
            console.print("wrote " + ", ".join(str(p) for p in done.paths))
        # The model notice was said at the start and heads the table: here only which hypotheses, in which version.
        versions = ", ".join(f"{done.per[n]['hypothesis']['name']} v{done.per[n]['hypothesis']['version']}"
                             for n in names)
        console.print(f"[yellow]hypotheses: {versions}[/]")


def power_table(done):
    """The power table of a :class:`~vibrofocus.workflows.PowerOutcome`, as the terminal shows it."""
    from rich.table import Table

    from ..simulation.perception import MODEL_LABEL
    from ..simulation.power import DIRECTIONAL_TESTS, REVERSE_TESTS, TESTS

    result, per, design, names = done.result, done.per, done.design, list(done.per)
    robust = {(r["test"], r["n_participants"]): r for r in result["robust"]}
    table = Table(title=f"Power by simulation ({MODEL_LABEL}; stimuli at {result['levels']} levels), "
                        f"{design.n_studies} studies per N, alpha {design.alpha}; *: robust, every hypothesis agrees "
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
    if "s2_inverse_vs_funneling" in result["directional"] and "paper_implied_study2" in result:
        imp = result["paper_implied_study2"]
        label = (f"Study 2 inverse vs funneling, the paper's own effect (Bonferroni Wilcoxon p = "
                 f"{imp['p_bonferroni']:g} -> z = {imp['z']:.2f}, a shift of {imp['theta']:.2f} SD; "
                 f"{imp['n_studies']} simulated replications)")
        for k, (key, what) in enumerate((("power", "as published"), ("power_half", "half of it"))):
            table.add_row(label if k == 0 else "", what,
                          *[f"{imp[key][str(n)]:.2f}" for n in design.n_participants])
    return table


class _PowerProgress:
    """The power workflow's :class:`~vibrofocus.workflows.Progress` at the terminal: a bar of the studies."""

    def __init__(self, console, *, quiet: bool):
        from ._progress import progress_bar

        self.console = console
        self.bar = progress_bar(console, label="studies", disable=quiet)
        self.task = None

    def __enter__(self) -> "_PowerProgress":
        return self

    def __exit__(self, *exc) -> None:
        if self.task is not None:
            self.bar.stop()

    def step(self, done: int, total: int, message: str) -> None:
        if self.task is None:
            self.bar.start()
            self.task = self.bar.add_task(message, total=total)
        self.bar.update(self.task, completed=done)

    def note(self, message: str, **details) -> None:
        self.console.print(f"[yellow]{message}[/]" if details.get("notice") else message)

    def judged(self, result) -> None:
        pass

    def cancelled(self) -> bool:
        return False
