"""The demo's modes on the simulated forearm: every method at every location, the source
paper's figures, and a moving focus (docs/method.md, "Rendering methods")."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .progress import Progress, QuietProgress

__all__ = ["DemoOutcome", "demo_methods", "demo_paper_figures", "demo_moving_focus"]

#: ``save_with(save, path) -> path``: call ``save(path)``, or save elsewhere when it fails.
SaveWithFn = Callable[[Callable[[Path], Path], Path], Path]


@dataclass(frozen=True)
class DemoOutcome:
    """What :func:`demo_methods` measured and wrote.

    Attributes
    ----------
    rig : SimulatedForearm
        The arm the taps were played on.
    result : DemoResult
        :func:`~vibrofocus.demo.run_demo`'s rows (with ``peak_bound_db`` when ``bounds``).
    summary : dict
        :func:`~vibrofocus.demo.summarize` of the rows: the median per method.
    calibration : dict
        The calibration's file, method, error against the model and trust (empty when
        designed from the model).
    frontiers : dict
        The peak-contrast frontier per location (empty without ``bounds``).
    paths : list of Path
        The figures written.
    bounds : bool
        Whether the peak bound was computed.
    """

    rig: Any
    result: Any
    summary: dict
    calibration: dict = field(default_factory=dict)
    frontiers: dict = field(default_factory=dict)
    paths: list = field(default_factory=list)
    bounds: bool = False


def _make_output_folder(out: Path) -> None:
    """Create ``out`` (its parent must exist); a folder that cannot be made is one clear error."""
    from .._atomic import make_output_folder

    make_output_folder(out)


def demo_methods(
    out: Path,
    *,
    seed: int = 0,
    skin: str = "nominal",
    figures: bool = True,
    location: int = 5,
    design_from: str = "calibration",
    frontier: bool = False,
    peak_bound: bool = True,
    with_minimax: bool = False,
    save_with: SaveWithFn | None = None,
    progress: Progress | None = None,
) -> DemoOutcome:
    """Calibrate the simulated forearm, then render, play and measure a tap at every location with every method.

    Parameters
    ----------
    out : Path
        Folder for the calibration and the figures (created; its parent must exist).
    seed : int
        The simulated participant (forearm).
    skin : str
        Skin preset of the simulated forearm (a checked preset name).
    figures : bool
        Write the PNG figures.
    location : int
        Location shown in the focused-field figure.
    design_from : {"calibration", "model"}
        Design from a calibration measured first, or from the simulator's exact transfer.
    frontier : bool
        Also compute the peak-contrast frontier and its figure (includes the peak bound).
    peak_bound : bool
        Compute the peak bound per location.
    with_minimax : bool
        Also render the opt-in minimax design.
    save_with : callable, optional
        ``save_with(save, path)`` saves the calibration (default ``save(path)``).
    progress : Progress, optional
        Steps of the calibration, the taps, the frontier and the figures.

    Returns
    -------
    DemoOutcome
    """
    from ..calibration import calibrate, save_calibration
    from ..demo import calibrated_transfer, model_transfer, run_demo, summarize
    from ..rigs.simulated import SimulatedForearm

    progress = progress if progress is not None else QuietProgress()
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
    transfer = model_transfer
    if design_from == "calibration":
        progress.step(0, 0, "calibrating")
        cal = calibrate(rig, participant_id=f"simulated-{seed}", progress=lambda done, n, msg: progress.step(done, n, msg))
        from ..calibration.replacing import calibration_owner

        def save_demo_calibration(path: Path) -> Path:
            # An earlier demo's simulated calibration is replaced as it was; a
            # participant's is kept (refused if another's, else kept as .1.nc).
            demo = path.is_file() and (calibration_owner(path) or "").startswith("simulated-")
            return save_calibration(cal, path, force=demo, keep_previous=not demo)

        cal_path = (save_with or (lambda save, path: save(path)))(save_demo_calibration, out / "calibration.nc")
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
    played = [0]

    def one_more(label: str, count: list[int], of: int) -> None:
        count[0] += 1
        progress.step(count[0], of, label)

    progress.step(0, total, "rendering and playing")
    result = run_demo(rig, transfer=transfer, methods=methods, progress=lambda label: one_more(label, played, total))
    paths: list = []
    frontiers: dict = {}
    if bounds:
        from ..demo.frontier import FRONTIER_FIDELITIES, peak_frontiers

        n_locations = len({r["location"] for r in result.rows})
        what = "peak-contrast frontier" if frontier else "peak bound"
        progress.step(0, n_locations, what)
        # Without --frontier only the pseudo-inverse's fidelity: the peak bound alone.
        frontiers = peak_frontiers(result, fidelities=FRONTIER_FIDELITIES if frontier else (),
                                   progress=lambda _label, _n=[0]: one_more(what, _n, n_locations))
        for row in result.rows:
            row["peak_bound_db"] = frontiers[row["location"]].peak_bound_db
    if figures:
        from ..demo.figures import write_figures

        progress.step(total, total, "writing figures")
        paths = write_figures(result, out, location=location)
        if frontier:
            from ..demo.frontier import frontier_figure

            paths.append(frontier_figure(result, frontiers, out / "peak_frontier.png"))
    return DemoOutcome(rig, result, summarize(result.rows), calibration_info, frontiers, paths, bounds)


def demo_paper_figures(out: Path, *, seed: int, participants: int, location: int, skin: str,
                       progress: Progress | None = None) -> list[Path]:
    """Draw the source paper's Figs. 4-7 from the simulated forearm and a simulated study into ``out``.

    Parameters
    ----------
    out : Path
        The folder (created; its parent must exist).
    seed : int
        The simulated forearm and the simulation's seed.
    participants : int
        Simulated participants of the study behind the figures.
    location : int
        The location of the field figures.
    skin : str
        Skin preset of the simulated forearm.
    progress : Progress, optional
        A step per figure drawn.

    Returns
    -------
    list of Path
        The figures written.
    """
    from ..demo.paper_figures import write_paper_figures

    progress = progress if progress is not None else QuietProgress()
    _make_output_folder(out)
    progress.step(0, 0, "starting")
    return write_paper_figures(out, seed=seed, participants=participants, location=location,
                               progress=lambda label: progress.step(0, 0, label), skin=skin)


def demo_moving_focus(out: Path, *, seed: int, speed_m_s: float, skin: str) -> tuple[Any, Any, Path]:
    """A moving focus rendered from the skin model fitted to a calibration of the simulated forearm.

    Parameters
    ----------
    out : Path
        The folder of ``moving_focus.gif`` (created; its parent must exist).
    seed : int
        The simulated forearm.
    speed_m_s : float
        Speed of the focus, m/s (from location 7 to location 3).
    skin : str
        Skin preset of the simulated forearm.

    Returns
    -------
    (FittedSkin, MovingFocus, Path)
        The fitted model, the focus rendered and the animation written.
    """
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
    return fitted, focus, write_moving_gif(focus, arm, out / "moving_focus.gif")


def _relative_error_to_model(rig, calibration) -> float:
    """Median |H_measured - H_true| / |H_true| in the calibrated band where the true
    response is within 40 dB of its peak (a simulator-only check, see
    :func:`vibrofocus.calibration.transfer_error`)."""
    from ..calibration import transfer_error

    low, high = calibration.band
    in_band = (calibration.freqs >= low) & (calibration.freqs <= high)
    truth = rig.transfer(rig.layout.points_xy, calibration.freqs[in_band])
    return transfer_error(calibration.H[in_band], truth)["median_relative_error"]
