"""``vibrofocus demo``: every rendering method at every location on the simulated forearm."""

from __future__ import annotations

import json
from pathlib import Path

import typer
from rich import box
from rich.console import Console
from rich.table import Table

from ._errors import user_errors
from ._progress import progress_bar
from ._options import SEED_MAX, force_option
from ._command import command

console = Console()
err_console = Console(stderr=True)


def _fmt(value: float, digits: int = 2) -> str:
    if value != value:
        return "—"  # NaN
    text = f"{value:.{digits}f}"
    return text[1:] if text.startswith("-") and float(text) == 0 else text  # never "-0.00"


#: The metric columns' headers, read top-down per column (each line of a header is one
#: row of the table's head, so a word never seems to belong to the column beside it).
METRIC_COLUMNS = ("fid", "shape", "contrast\ndB", "all pts\ndB", "energy\ncontr.\ndB", "energy\nbound\ndB",
                  "peak\nbound\ndB", "target\nµm", "drive\nV")


def metrics_table(title: str, columns: tuple[str, ...], rows: list[list[str]], *, location: bool = False) -> Table:
    """A table of the demo's metrics that fits 80 columns (a pipe, a default terminal).

    Parameters
    ----------
    title : str
        The table's title.
    columns : tuple of str
        Headers of the metric columns (lines split by ``\\n``), after ``method``.
    rows : list of list of str
        One row of cells per method (with the location first when ``location``).
    location : bool
        Add a first ``loc`` column.

    Returns
    -------
    rich.table.Table
    """
    # One space between columns (the box's own separator, no padding) and none at the edges: with
    # every metric column, the longest method name (time_reversal) and signed values,
    # a row is 78 characters wide.
    table = Table(title=title, box=box.SIMPLE_HEAD, padding=0, pad_edge=False, show_edge=False)
    for col in (("loc",) if location else ()) + ("method", *columns):
        table.add_column(col, justify="left" if col == "method" else "right", no_wrap=True)
    for row in rows:
        table.add_row(*row)
    return table


#: The longer help texts of ``demo``'s options.
_HELP = {
    "skin": (
            "Skin preset of the simulated forearm: nominal | low | high | voigt-fit "
            "(docs: How true is the simulated arm)."
    ),
    "paper_figures": (
            "Instead of the demo, draw the source paper's Figs. 4-7 (de Vlam et al. 2023) from the simulated forearm "
            "and a simulated study into OUT (paper_fig4.png ... paper_fig7.png)."
    ),
    "moving": (
            "Instead of the demo: calibrate, fit the skin model to the calibration, render taps along a path "
            "(location 7 to location 3) from the fitted model and write the field as OUT/moving_focus.gif."
    ),
    "design_from": (
            "Design from a calibration measured first ('calibration', as a user would) or from the "
            "simulator's exact transfer ('model', what a perfect calibration would give)."
    ),
    "frontier": (
            "Also compute the peak-contrast frontier (minimax designs at fidelity 0.8-0.98 and at the "
            "pseudo-inverse's, per location; tens of seconds), add the peak bound to the tables and write "
            "OUT/peak_frontier.png."
    ),
    "peak_bound": (
            "Show the peak bound beside the energy bound: per location, the most peak contrast against every "
            "calibrated point that any drive reaches at the pseudo-inverse's fidelity (one minimax design each, "
            "about a second)."
    ),
}


@command("demo", epilog="Example: vibrofocus demo --seed 3 --out demo-output/   or   vibrofocus demo --json")
def demo_command(
    seed: int = typer.Option(0, "--seed", min=0, max=SEED_MAX, help="Simulated participant (forearm) seed."),
    skin: str = typer.Option("nominal", "--skin", help=_HELP["skin"]),
    out: Path = typer.Option(Path("demo-output"), "--out", "-o",
                             help="Folder for the figures (created; its parent must exist)."),
    figures: bool = typer.Option(True, "--figures/--no-figures", help="Write the PNG figures."),
    as_json: bool = typer.Option(False, "--json", help="Print one JSON object (results and summary) and nothing else."),
    location: int = typer.Option(5, "--field-location", help="Location shown in the focused-field figure (1-9)."),
    per_location: bool = typer.Option(False, "--per-location", help="Also print one row per location and method."),
    paper_figures: bool = typer.Option(False, "--paper-figures", help=_HELP["paper_figures"]),
    participants: int = typer.Option(12, "--participants", min=1, max=200,
                                     help="Simulated participants of the study behind --paper-figures (about 3 s each)."),
    moving: bool = typer.Option(False, "--moving", help=_HELP["moving"]),
    moving_speed: float = typer.Option(0.1, "--moving-speed", min=0.01, max=2.0,
                                      help="Speed of the moving focus, m/s (a finger's stroke: 0.01 to 2)."),
    design_from: str = typer.Option("calibration", "--design-from", help=_HELP["design_from"]),
    frontier: bool = typer.Option(False, "--frontier", help=_HELP["frontier"]),
    peak_bound: bool = typer.Option(True, "--peak-bound/--no-peak-bound", help=_HELP["peak_bound"]),
    with_minimax: bool = typer.Option(
        False, "--minimax",
        help="Also render the opt-in peak-contrast (minimax) design at every location (seconds each).",
    ),
    force: bool = force_option(),
) -> None:
    """Calibrate the simulated forearm, then render a tap at every location with every method, play it, measure it.

    First a calibration (exponential sweeps, H1 estimate) measures the transfer matrix at every point; it is saved as OUT/calibration.nc. Then for each of the layout's locations and each method (funneling, inverse, combination, time reversal, contrast, constrained): design from the measured matrix, scale to the drive limit (equal peak drive), play with vibrometer noise, and report fidelity, contrast (against the other locations and against every calibrated point), energy contrast beside the array's bound, the peak bound (the most peak contrast any drive reaches at the pseudo-inverse's fidelity; --no-peak-bound leaves it out), peak drive and the target's peak displacement.

    Figures: propagation with and without correction, the focused field around one location, and a metrics overview.
    """  # noqa: E501
    with user_errors():
        from .._atomic import allow_overwrite
        from .._validation import check_choice
        from ..skin import skin_preset
        from ..workflows import demo_methods, demo_moving_focus, demo_paper_figures
        from ._save import save_or_offer_another_path

        allow_overwrite(force)
        check_choice(design_from, "--design-from", ("calibration", "model"))
        skin = skin_preset(skin).name
        if paper_figures:
            with _Bar(transient=True, columns="elapsed") as bar:
                paths = demo_paper_figures(out, seed=seed, participants=participants, location=location, skin=skin,
                                           progress=bar)
            _print_paper_figures(paths, skin)
            return
        if moving:
            fitted, focus, path = demo_moving_focus(out, seed=seed, speed_m_s=moving_speed, skin=skin)
            if not as_json:
                console.print(f"fitted {fitted!r}")
                console.print(f"{len(focus.targets_xy)} taps at {moving_speed:g} m/s from location 7 to 3 "
                              f"(drive scaled by {focus.scale:.2f}); animation: {path}")
            return
        with _Bar(transient=True, disable=as_json) as bar:
            done = demo_methods(
                out, seed=seed, skin=skin, figures=figures, location=location, design_from=design_from,
                frontier=frontier, peak_bound=peak_bound, with_minimax=with_minimax, progress=bar,
                save_with=lambda save, path: save_or_offer_another_path(
                    save, path, what="calibration", interactive=False if as_json else None))
        if as_json:
            _print_json(done, seed=seed, design_from=design_from)
        else:
            _print_tables(done, seed=seed, design_from=design_from, per_location=per_location, frontier=frontier)


def _print_json(done, *, seed: int, design_from: str) -> None:
    """``demo --json``: one strict JSON object, results and summary."""
    from ..io.jsonsafe import json_safe

    rig = done.rig
    payload = {
        "seed": seed,
        "rig": "simulated",
        "skin": rig.skin,
        "participant": rig.participant.to_dict(),
        "design_from": design_from,
        "calibration": done.calibration or None,
        "units": {"fidelity": "1", "contrast_db": "dB", "peak_drive_v": "V", "target_peak_m": "m"},
        "results": done.result.rows,
        "summary": done.summary,
        "figures": [str(p) for p in done.paths],
    }
    # Strict JSON: NaN and infinities (a silent point, a perfect contrast) become null.
    typer.echo(json.dumps(json_safe(payload), allow_nan=False, default=float))


def _print_tables(done, *, seed: int, design_from: str, per_location: bool, frontier: bool) -> None:
    """The demo's arm, calibration, metrics tables and figures, as the terminal shows them."""
    import numpy as np

    rig, result, summary, calibration_info, bounds = done.rig, done.result, done.summary, done.calibration, done.bounds
    p = rig.participant
    console.print(
        f"[bold]Simulated forearm[/], skin {rig.skin}, seed {seed}: c(250 Hz) = {p.c250_m_s:.2f} m/s, "
        f"alpha(250 Hz) = {p.alpha250_np_m:.0f} Np/m; each actuator's contact with the skin (0-1, 1 = full): "
        + ", ".join(f"{name} {c:.2f}" for name, c in zip(rig.layout.actuator_names, p.contact))
    )
    if calibration_info:
        console.print(
            f"Calibrated ({calibration_info['method']}), saved to {calibration_info['file']}; "
            f"median error of the measured H against the model's true H in band: "
            f"{100 * calibration_info['median_relative_error']:.1f} %"
        )
        trust = calibration_info["trust"]
        band = trust["coherent_band_hz"]
        tap = trust["tap_band_hz"]
        console.print(
            (f"coherence below {trust['min_coherence']:g} somewhere at every frequency" if band is None else
             f"coherence >= {trust['min_coherence']:g} at every point over {band[0]:.0f}-{band[1]:.0f} Hz")
            + f" (the tap's band, within 20 dB of its peak: {tap[0]:.0f}-{tap[1]:.0f} Hz, "
            f"{'covered' if trust['covers_tap_band'] else 'NOT covered'}); H error "
            f"{100 * trust['error_inside']:.1f} % inside, "
            + ("no calibrated bin outside" if trust["error_outside"] != trust["error_outside"]
               else f"{100 * trust['error_outside']:.1f} % outside")
        )
    source = "a measured calibration" if design_from == "calibration" else "the model's exact transfer"
    legend = ("All methods at the same peak drive (the drive limit). fid: correlation with the tap at its "
              "time (combination: with funneling's displacement there); shape: at the best lag (funneling arrives "
              "late); contrast: peak at the target over the "
              "largest at the other locations; all pts: over every calibrated point; energy: energy contrast "
              "against the other locations; bound: the most energy contrast any drive that gives the tap "
              "reaches there" + ("; peak bound: the most peak contrast against every calibrated point any "
                                 "drive reaches at the pseudo-inverse's fidelity (minimax, predicted)."
                                 if bounds else "."))
    columns = METRIC_COLUMNS if bounds else tuple(c for c in METRIC_COLUMNS if not c.startswith("peak"))

    def metric_cells(values: dict) -> list[str]:
        return [_fmt(values["fidelity"]), _fmt(values["shape_fidelity"]), _fmt(values["contrast_db"], 1),
                _fmt(values["contrast_all_points_db"], 1), _fmt(values["energy_contrast_db"], 1),
                _fmt(values["bound_db"], 1),
                *((_fmt(values.get("peak_bound_db", float("nan")), 1),) if bounds else ()),
                _fmt(values["target_peak_m"] * 1e6, 3), _fmt(values["peak_drive_v"], 1)]

    if per_location:
        console.print(metrics_table(
            f"Per location, designed from {source}, measured on the arm (noise on)", columns,
            [[str(row["location"]), row["method"], *metric_cells(row)] for row in result.rows], location=True))
    console.print(metrics_table(
        f"Median over locations, designed from {source}, measured on the arm (noise on)", columns,
        [[method, *metric_cells(values)] for method, values in summary.items()]))
    console.print(legend, style="dim")
    if not per_location:
        console.print("Per location: --per-location, --json, or the metrics figure.", style="dim")
    if frontier:
        from ..demo.frontier import FRONTIER_FIDELITIES

        frontiers = done.frontiers
        console.print(f"Peak-contrast frontier: {sum(f.seconds for f in frontiers.values()):.0f} s for "
                      f"{len(frontiers)} locations ({len(FRONTIER_FIDELITIES) + 1} fidelities each).")
    for path in done.paths:
        console.print(f"wrote {path}")


def _print_paper_figures(paths, skin: str) -> None:
    from ..simulation.perception import STUDY_SKIN

    console.print(f"The source paper's figure layouts, drawn from the model (simulated forearm, skin {skin}, and "
                  f"simulated participants on the {STUDY_SKIN} skin: not data):")
    for path in paths:
        console.print(f"wrote {path}")


class _Bar:
    """A demo workflow's :class:`~vibrofocus.workflows.Progress` at the terminal: one transient bar."""

    def __init__(self, *, transient: bool, disable: bool = False, columns: str = "bar"):
        self.bar = progress_bar(err_console, counts=columns == "bar", disable=disable, transient=transient)
        self.task = None

    def __enter__(self) -> "_Bar":
        self.bar.start()
        return self

    def __exit__(self, *exc) -> None:
        self.bar.stop()

    def step(self, done: int, total: int, message: str) -> None:
        if self.task is None:
            self.task = self.bar.add_task(message, total=None)
        self.bar.update(self.task, completed=done, total=total or None, description=message)

    def note(self, message: str, **details) -> None:
        console.print(message)

    def judged(self, result) -> None:
        pass

    def cancelled(self) -> bool:
        return False
