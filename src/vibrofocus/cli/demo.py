"""``vibrofocus demo``: every rendering method at every location on the simulated forearm."""

from __future__ import annotations

import json
from pathlib import Path

import typer
from rich import box
from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table

from ._errors import user_errors
from ._options import SEED_MAX, force_option
from ._command import command

console = Console()
err_console = Console(stderr=True)


def _fmt(value: float, digits: int = 2) -> str:
    if value != value:
        return "—"  # NaN
    text = f"{value:.{digits}f}"
    return text[1:] if text.startswith("-") and float(text) == 0 else text  # never "-0.00"


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


@command("demo", epilog="Example: vibrofocus demo --seed 3 --out demo-output/   or   vibrofocus demo --json")
def demo_command(
    seed: int = typer.Option(0, "--seed", min=0, max=SEED_MAX, help="Simulated participant (forearm) seed."),
    skin: str = typer.Option("nominal", "--skin",
                             help="Skin preset of the simulated forearm: nominal | low | high | voigt-fit "
                                  "(docs: How true is the simulated arm)."),
    out: Path = typer.Option(Path("demo-output"), "--out", "-o",
                             help="Folder for the figures (created; its parent must exist)."),
    figures: bool = typer.Option(True, "--figures/--no-figures", help="Write the PNG figures."),
    as_json: bool = typer.Option(False, "--json", help="Print one JSON object (results and summary) and nothing else."),
    location: int = typer.Option(5, "--field-location", help="Location shown in the focused-field figure (1-9)."),
    per_location: bool = typer.Option(False, "--per-location", help="Also print one row per location and method."),
    paper_figures: bool = typer.Option(
        False, "--paper-figures",
        help="Instead of the demo, draw the source paper's Figs. 4-7 (de Vlam et al. 2023) from the simulated forearm "
        "and a simulated study into OUT (paper_fig4.png ... paper_fig7.png).",
    ),
    participants: int = typer.Option(12, "--participants", min=1, max=200,
                                     help="Simulated participants of the study behind --paper-figures (about 3 s each)."),
    moving: bool = typer.Option(
        False, "--moving",
        help="Instead of the demo: calibrate, fit the skin model to the calibration, render taps along a path "
        "(location 7 to location 3) from the fitted model and write the field as OUT/moving_focus.gif.",
    ),
    moving_speed: float = typer.Option(0.1, "--moving-speed", min=0.01, max=2.0,
                                      help="Speed of the moving focus, m/s (a finger's stroke: 0.01 to 2)."),
    design_from: str = typer.Option(
        "calibration", "--design-from",
        help="Design from a calibration measured first ('calibration', as a user would) or from the "
        "simulator's exact transfer ('model', what a perfect calibration would give).",
    ),
    frontier: bool = typer.Option(
        False, "--frontier",
        help="Also compute the peak-contrast frontier (minimax designs at fidelity 0.8-0.98 and at the "
        "pseudo-inverse's, per location; tens of seconds), add the peak bound to the tables and write "
        "OUT/peak_frontier.png.",
    ),
    peak_bound: bool = typer.Option(
        True, "--peak-bound/--no-peak-bound",
        help="Show the peak bound beside the energy bound: per location, the most peak contrast against every "
        "calibrated point that any drive reaches at the pseudo-inverse's fidelity (one minimax design each, "
        "about a second).",
    ),
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
        import numpy as np

        from .._atomic import allow_overwrite
        from .._validation import check_choice
        from ..calibration import calibrate, save_calibration
        from ..demo import calibrated_transfer, model_transfer, run_demo, summarize
        from ..rigs.simulated import SimulatedForearm

        allow_overwrite(force)
        check_choice(design_from, "--design-from", ("calibration", "model"))
        from ..skin import skin_preset

        skin = skin_preset(skin).name
        if paper_figures:
            _write_paper_figures(out, seed=seed, participants=participants, location=location, skin=skin)
            return
        if moving:
            _write_moving_focus(out, seed=seed, speed_m_s=moving_speed, quiet=as_json, skin=skin)
            return
        rig = SimulatedForearm(seed=seed, skin=skin)
        rig.layout.location_index(location)
        if design_from == "calibration" or figures:
            # Before the calibration starts: a read-only or full output folder is found now.
            from .._atomic import check_writable
            from ..io.calibration_nc import estimate_calibration_bytes

            _make_output_folder(out)
            expected = estimate_calibration_bytes(rig.layout.n_points, rig.layout.n_actuators, 8,
                                                  int(3.0 * rig.fs), 4096) if design_from == "calibration" else 0
            check_writable(out / "calibration.nc", what="calibration", expected_bytes=expected)
        from ..rendering.registry import default_methods

        # Every registered method, a lab's own included, but the opt-in ones (run_demo's default).
        methods = (*default_methods(), *(("minimax",) if with_minimax else ()))
        total = rig.layout.n_locations * len(methods)
        bounds = frontier or peak_bound  # the frontier includes the peak bound
        calibration_info: dict = {}
        with Progress(
            TextColumn("[progress.description]{task.description}"), BarColumn(), MofNCompleteColumn(),
            TimeElapsedColumn(), console=err_console, disable=as_json, transient=True,
        ) as progress:
            transfer = model_transfer
            if design_from == "calibration":
                cal_task = progress.add_task("calibrating", total=None)
                cal = calibrate(
                    rig, participant_id=f"simulated-{seed}",
                    progress=lambda done, n, msg: progress.update(cal_task, completed=done, total=n, description=msg),
                )
                from ._save import save_or_offer_another_path

                from ..calibration.replacing import calibration_owner

                def save_demo_calibration(path: Path) -> Path:
                    # An earlier demo's simulated calibration is replaced as it was; a
                    # participant's is kept (refused if another's, else kept as .1.nc).
                    demo = path.is_file() and (calibration_owner(path) or "").startswith("simulated-")
                    return save_calibration(cal, path, force=demo, keep_previous=not demo)

                cal_path = save_or_offer_another_path(
                    save_demo_calibration, out / "calibration.nc", what="calibration",
                    interactive=False if as_json else None,
                )
                transfer = calibrated_transfer(cal)
                from ..demo import calibration_trust

                calibration_info = {
                    "file": str(cal_path),
                    "method": cal.method,
                    "median_relative_error": _relative_error_to_model(rig, cal),
                    "trust": calibration_trust(cal, rig.transfer(rig.layout.points_xy, cal.freqs)),
                    "quality_ok": bool(cal.quality.ok),
                    "quality_issues": [f"{issue.severity}: {issue.message}" for issue in cal.quality.issues],
                }
            task = progress.add_task("rendering and playing", total=total)
            result = run_demo(rig, transfer=transfer, methods=methods,
                              progress=lambda label: progress.update(task, advance=1, description=label))
            paths = []
            if bounds:
                from ..demo.frontier import FRONTIER_FIDELITIES, peak_frontiers

                n_locations = len({r["location"] for r in result.rows})
                front_task = progress.add_task("peak-contrast frontier" if frontier else "peak bound",
                                               total=n_locations)
                # Without --frontier only the pseudo-inverse's fidelity: the peak bound alone.
                frontiers = peak_frontiers(result, fidelities=FRONTIER_FIDELITIES if frontier else (),
                                           progress=lambda _label: progress.update(front_task, advance=1))
                for row in result.rows:
                    row["peak_bound_db"] = frontiers[row["location"]].peak_bound_db
            if figures:
                from ..demo.figures import write_figures

                progress.update(task, description="writing figures")
                paths = write_figures(result, out, location=location)
                if frontier:
                    from ..demo.frontier import frontier_figure

                    paths.append(frontier_figure(result, frontiers, out / "peak_frontier.png"))
        summary = summarize(result.rows)
        if as_json:
            payload = {
                "seed": seed,
                "rig": "simulated",
                "skin": rig.skin,
                "participant": rig.participant.to_dict(),
                "design_from": design_from,
                "calibration": calibration_info or None,
                "units": {"fidelity": "1", "contrast_db": "dB", "peak_drive_v": "V", "target_peak_m": "m"},
                "results": result.rows,
                "summary": summary,
                "figures": [str(p) for p in paths],
            }
            from ..io.jsonsafe import json_safe

            # Strict JSON: NaN and infinities (a silent point, a perfect contrast) become null.
            typer.echo(json.dumps(json_safe(payload), allow_nan=False, default=float))
            return
        p = rig.participant
        console.print(
            f"[bold]Simulated forearm[/], skin {rig.skin}, seed {seed}: c(250 Hz) = {p.c250_m_s:.2f} m/s, "
            f"alpha(250 Hz) = {p.alpha250_np_m:.0f} Np/m, contact {np.round(p.contact, 2).tolist()}"
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
        columns = ("fid", "shape", "contrast\ndB", "all pts\ndB", "energy\ndB", "bound\ndB",
                   *(("peak\nbound\ndB",) if bounds else ()), "target\nµm", "drive\nV")

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
            console.print(f"Peak-contrast frontier: {sum(f.seconds for f in frontiers.values()):.0f} s for "
                          f"{len(frontiers)} locations ({len(FRONTIER_FIDELITIES) + 1} fidelities each).")
        for path in paths:
            console.print(f"wrote {path}")


def _make_output_folder(out: Path) -> None:
    """Create ``out`` (its parent must exist); a folder that cannot be made is one clear error."""
    from .._atomic import make_output_folder

    make_output_folder(out)


def _write_paper_figures(out: Path, *, seed: int, participants: int, location: int, skin: str) -> None:
    from ..demo.paper_figures import write_paper_figures
    from ..simulation.perception import STUDY_SKIN

    _make_output_folder(out)
    with Progress(TextColumn("[progress.description]{task.description}"), TimeElapsedColumn(), console=err_console,
                  transient=True) as progress:
        task = progress.add_task("starting", total=None)
        paths = write_paper_figures(out, seed=seed, participants=participants, location=location,
                                    progress=lambda label: progress.update(task, description=label), skin=skin)
    console.print(f"The source paper's figure layouts, drawn from the model (simulated forearm, skin {skin}, and "
                  f"simulated participants on the {STUDY_SKIN} skin: not data):")
    for path in paths:
        console.print(f"wrote {path}")


def _write_moving_focus(out: Path, *, seed: int, speed_m_s: float, quiet: bool, skin: str) -> None:
    """``demo --moving``: a moving focus rendered from the skin model fitted to a calibration."""
    from ..calibration import calibrate, fit_model
    from ..demo.moving import moving_focus, write_moving_gif
    from ..rigs.simulated import SimulatedForearm

    _make_output_folder(out)
    rig = SimulatedForearm(seed=seed, skin=skin)
    cal = calibrate(rig, participant_id=f"simulated-{seed}")
    # The model's law is the arm's: layered on the evidence presets, homogeneous on voigt-fit.
    fitted = fit_model(cal, law="layered" if rig.participant.layered is not None else "homogeneous")
    lay = rig.layout
    focus = moving_focus(fitted, lay, rig.fs, start_xy=lay.locations_xy[6], end_xy=lay.locations_xy[2],
                         speed_m_s=speed_m_s)
    arm = SimulatedForearm(seed=seed, noise_m=0.0, dropout_rate=0.0, skin=skin)
    path = write_moving_gif(focus, arm, out / "moving_focus.gif")
    if not quiet:
        console.print(f"fitted {fitted!r}")
        console.print(f"{len(focus.targets_xy)} taps at {speed_m_s:g} m/s from location 7 to 3 "
                      f"(drive scaled by {focus.scale:.2f}); animation: {path}")


def _relative_error_to_model(rig, calibration) -> float:
    """Median |H_measured - H_true| / |H_true| in the calibrated band where the true
    response is within 40 dB of its peak (a simulator-only check, see
    :func:`vibrofocus.calibration.transfer_error`)."""
    from ..calibration import transfer_error

    low, high = calibration.band
    in_band = (calibration.freqs >= low) & (calibration.freqs <= high)
    truth = rig.transfer(rig.layout.points_xy, calibration.freqs[in_band])
    return transfer_error(calibration.H[in_band], truth)["median_relative_error"]
