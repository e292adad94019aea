"""Where to put the actuators: the workflow under ``design-layout`` (docs/design-layout.md)."""

from __future__ import annotations

import contextlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .progress import Progress, QuietProgress

__all__ = ["LayoutOutcome", "design_layout"]


@dataclass
class LayoutOutcome:
    """What :func:`design_layout` made.

    Attributes
    ----------
    result : PlacementResult
        The search's result (:func:`vibrofocus.placement.search_layout`): the layout, its
        score, the paper's 2 x 2 at 45 mm on the same targets, each start.
    table : list of dict
        The comparison with the paper's layout, one row per target then the worst and the mean
        (:func:`vibrofocus.placement.comparison_rows`).
    skin : str
        The skin model searched on (a preset's name, or the calibration whose fit it was).
    paths : list of Path
        The files written (layout.json, layout.png, comparison.csv, design-layout.json),
        empty without ``out``.
    """

    result: Any
    table: list[dict]
    skin: str
    paths: list[Path]


def design_layout(settings: Any = None, *, skin: str = "nominal", calibration: Path | None = None,
                  scheduler: str | None = None, workers: int | None = None, local: bool = False,
                  out: Path | None = None, progress: Progress | None = None) -> LayoutOutcome:
    """Search actuator positions for the best worst-target peak contrast at the drive limit, and write them.

    Parameters
    ----------
    settings : PlacementSettings, optional
        Region, number of actuators and their least spacing, targets, method, drive limit,
        fidelity floor (:class:`~vibrofocus.placement.PlacementSettings`; default its defaults:
        4 actuators in 90 x 90 mm around the paper's grid, its 9 targets, the inverse filter, 10 V).
    skin : str
        Skin preset of the model searched on (``nominal``, ``low``, ``high``, ``voigt-fit``).
    calibration : Path, optional
        A calibration whose fitted skin model (its stored fit, or a layered fit made now)
        replaces the preset.
    scheduler, workers, local
        The Dask options, as ``power``'s: a scheduler address, the LocalCluster's workers,
        or this process alone.
    out : Path, optional
        Folder for the files (checked before the search runs).
    progress : Progress, optional
        One note per step of the search.

    Returns
    -------
    LayoutOutcome
    """
    from ..placement import PlacementSettings, comparison_rows, search_layout
    from ..simulation.power import dask_client
    from ..skin import ForearmParameters

    progress = progress if progress is not None else QuietProgress()
    settings = settings if settings is not None else PlacementSettings()
    if calibration is not None:
        from .._atomic import protect
        from ..calibration import fit_model, load_calibration

        protect(calibration, "calibration")
        cal = load_calibration(calibration)
        fit = cal.fit if getattr(cal, "fit", None) is not None else fit_model(cal, law="layered")
        participant, skin = fit.participant, f"fitted to {Path(calibration).name} ({fit.law})"
    else:
        participant = ForearmParameters.nominal(1, skin=skin)
    if out is not None:
        from .._atomic import check_writable, make_output_folder

        make_output_folder(out)
        check_writable(out / "layout.json", what="layout")
    if settings.method == "minimax":
        progress.note("minimax takes seconds per design and the search makes hundreds of layouts x targets: "
                      "expect hours on one machine (the inverse filter, the default, takes about a minute)",
                      notice=True)
    with contextlib.ExitStack() as stack:
        client = None if local else stack.enter_context(dask_client(scheduler=scheduler, n_workers=workers))
        result = search_layout(settings, participant=participant, client=client, progress=progress.note)
    progress.note(f"{result.n_layouts} layouts scored in {result.elapsed_s:.1f} s")
    table = comparison_rows(result)
    paths = _write(result, table, skin, out) if out is not None else []
    return LayoutOutcome(result, table, skin, paths)


def _write(result: Any, table: list[dict], skin: str, out: Path) -> list[Path]:
    """layout.json, layout.png, comparison.csv and design-layout.json in ``out``."""
    import csv
    import io as _io
    import json

    from ..io import json_safe, save_figure, write_layout_json, write_text
    from ..placement import plot_layout

    about = {"made_by": "vibrofocus design-layout", "skin": skin, "method": result.settings.method,
             "limit_v": result.settings.limit_v, "worst_contrast_db": result.score.worst_db,
             "mean_contrast_db": result.score.mean_db,
             "paper_worst_contrast_db": None if result.paper is None else result.paper.worst_db}
    paths = [write_layout_json(result.layout.to_dict(), out / "layout.json", about=about)]
    fig = plot_layout(result)
    paths.append(save_figure(fig, out / "layout.png", what="layout figure", dpi=120))
    buf = _io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=list(table[0]), lineterminator="\n")
    writer.writeheader()
    writer.writerows({k: (f"{v:.4g}" if isinstance(v, float) else v) for k, v in row.items()} for row in table)
    paths.append(write_text(out / "comparison.csv", buf.getvalue(), what="comparison table"))
    report = {**result.to_dict(), "skin": skin}
    paths.append(write_text(out / "design-layout.json",
                            json.dumps(json_safe(report), indent=2, allow_nan=False) + "\n", what="search report"))
    return paths
