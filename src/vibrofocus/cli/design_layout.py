"""``vibrofocus design-layout``: where to put the actuators, searched on a skin model."""

from __future__ import annotations

from pathlib import Path

import typer

from ._command import command
from ._errors import user_errors
from ._options import LIMIT_V_MIN, comma_list, force_option

_HELP = {
    "rect": "Region where actuators may sit: a rectangle WIDTH,LENGTH in mm across and along the arm, centred on "
            "--centre-mm (default 90,90: around the paper's grid).",
    "band": "Region as a band around the arm, CIRCUMFERENCE,LENGTH in mm (the forearm unrolled: x is arc length "
            "and wraps); instead of --rect-mm.",
    "targets": "Target points, mm, as x,y pairs separated by ';' (default the paper's 9 locations at 10 mm pitch); "
               "they become the layout's locations 1..N in this order.",
    "method": "inverse (default: the paper's pseudo-inverse, about 20 ms per target) or minimax (peak-contrast "
              "designs, seconds per target: the search takes hours on one machine; give it a Dask --scheduler).",
    "calibration": "Search on the skin model fitted to this calibration (.nc; its stored fit, or a layered fit) "
                   "instead of --skin.",
}


def _pair(text: str, name: str) -> tuple[float, float]:
    from ..errors import ValidationError

    values = comma_list(text, name, float)
    if len(values) != 2:
        raise ValidationError(f"{name} must be two numbers, mm, separated by a comma, got {text!r}")
    return values[0] * 1e-3, values[1] * 1e-3


def _targets(text: str):
    import numpy as np

    return np.array([_pair(p, "--targets-mm") for p in text.split(";") if p.strip()])


@command("design-layout", epilog="Example: vibrofocus design-layout --actuators 6 --rect-mm 100,80 --out layout6/")
def design_layout_command(
    out: Path = typer.Option(..., "--out", "-o", help="Folder for layout.json, layout.png, comparison.csv and "
                                                      "design-layout.json."),
    actuators: int = typer.Option(4, "--actuators", "-n", min=1, max=64, help="Number of actuators."),
    rect_mm: str | None = typer.Option(None, "--rect-mm", help=_HELP["rect"]),
    band_mm: str | None = typer.Option(None, "--band-mm", help=_HELP["band"]),
    centre_mm: str = typer.Option("0,0", "--centre-mm", help="Centre of the region, x,y in mm (a band uses y)."),
    targets_mm: str | None = typer.Option(None, "--targets-mm", help=_HELP["targets"]),
    min_spacing_mm: float = typer.Option(20.0, "--min-spacing-mm", min=1.0, max=500.0,
                                         help="Least distance between two actuators' centres, mm (the actuator's "
                                              "size and room for its guard)."),
    pitch_mm: float = typer.Option(15.0, "--pitch-mm", min=1.0, max=500.0, help="Candidate grid pitch, mm."),
    skin: str = typer.Option("nominal", "--skin", help="Skin preset: nominal | low | high | voigt-fit."),
    calibration: Path | None = typer.Option(None, "--calibration", "-c", help=_HELP["calibration"]),
    limit_v: float = typer.Option(10.0, "--limit-v", min=LIMIT_V_MIN, max=20.0, help="Drive limit, V peak."),
    method: str = typer.Option("inverse", "--method", "-m", help=_HELP["method"]),
    min_fidelity: float = typer.Option(0.8, "--min-fidelity", min=0.01, max=1.0,
                                       help="Fidelity floor at every target."),
    scheduler: str | None = typer.Option(None, "--scheduler", help="Dask scheduler address (tcp://host:8786); "
                                                                   "default a LocalCluster on this machine."),
    workers: int | None = typer.Option(None, "--workers", min=1, max=256, help="LocalCluster worker processes."),
    local: bool = typer.Option(False, "--no-dask", help="Run in this process without Dask (same result)."),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="No progress lines."),
    force: bool = force_option(),
) -> None:
    """Search where to put N actuators for the best worst-target peak contrast at the drive limit.

    Candidate positions on a grid over the region; a greedy start (one actuator at a time)
    and, for 4 actuators, the paper's 2x2 at 45 mm, each refined by moving one actuator to a
    neighbouring candidate while the worst target's contrast improves (docs/design-layout.md).
    Writes an array layout file (layout.json) that `vibrofocus calibrate --layout` takes, a
    figure of each target's contrast beside the paper's layout, and the table against it.
    """
    with user_errors():
        from rich.console import Console

        from .._atomic import allow_overwrite
        from ..errors import ValidationError
        from ..placement import PlacementSettings, Region
        from ..workflows import QuietProgress, design_layout

        allow_overwrite(force)
        if rect_mm and band_mm:
            raise ValidationError("give --rect-mm or --band-mm, not both")
        cx, cy = _pair(centre_mm, "--centre-mm")
        region = (Region.band(*_pair(band_mm, "--band-mm"), centre_y_m=cy) if band_mm
                  else Region.rectangle(*_pair(rect_mm or "90,90", "--rect-mm"), centre_xy=(cx, cy)))
        settings = PlacementSettings(region=region, n_actuators=actuators, min_spacing_m=min_spacing_mm * 1e-3,
                                     pitch_m=pitch_mm * 1e-3, method=method, limit_v=limit_v,
                                     min_fidelity=min_fidelity,
                                     targets_xy=_targets(targets_mm) if targets_mm else None)
        console = Console(stderr=True)
        shown = QuietProgress()
        if not quiet:
            shown.note = lambda message, **details: console.print(message, highlight=False)
        done = design_layout(settings, skin=skin, calibration=calibration, scheduler=scheduler, workers=workers,
                             local=local, out=out, progress=shown)
        Console().print(comparison_table(done), highlight=False)
        if done.paths:
            console.print("wrote " + ", ".join(str(p) for p in done.paths), highlight=False)


def comparison_table(done):
    """The designed layout against the paper's 2x2 at 45 mm, as the terminal shows it."""
    from rich.table import Table

    r = done.result
    table = Table(title=f"{r.settings.n_actuators} actuators ({r.settings.method}, {r.settings.limit_v:g} V, "
                        f"skin {done.skin}) against the paper's 2x2 at 45 mm: peak contrast against the other "
                        "targets, fidelity, tap at the limit")
    for column in done.table[0]:
        table.add_column(column.replace("_", " "), justify="right")
    for row in done.table:
        table.add_row(*[f"{v:.2f}" if isinstance(v, float) else str(v) for v in row.values()])
    return table
