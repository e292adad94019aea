"""The demo: every rendering method at every location, played on the simulated forearm.

The transfer matrix used for the designs comes from one callable ``transfer(rig, n)``:
by default a measured calibration (:func:`calibrated_transfer`), as a user would work,
or the simulator's exact transfer (:func:`model_transfer`) for comparison.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._docs import fill_doc
from .._validation import check_choice
from ..defaults import N_SAMPLES
from ..errors import ValidationError
from ..rigs.base import Rig

__all__ = ["DemoResult", "calibrated_transfer", "design_window", "model_transfer", "run_demo", "record_clean",
           "summarize"]

#: Metrics every result row carries (the ``--json`` contract, docs/file-formats.md, demo --json).
ROW_KEYS = ("location", "method", "fidelity", "contrast_db", "peak_drive_v", "target_peak_m")


def model_transfer(rig: Rig, n: int) -> np.ndarray:
    """The simulator's exact transfer matrix on ``rfftfreq(n, 1 / rig.fs)``.

    Parameters
    ----------
    rig : Rig
        A rig with a ``transfer(points_xy, freqs)`` method (the simulated forearm).
    n : int
        Window length, samples.

    Returns
    -------
    ndarray, complex, shape (n // 2 + 1, n_points, n_actuators)
        m/V at ``rig.layout.points_xy``.

    Notes
    -----
    Only a model rig knows its true transfer; designing from it shows what a perfect
    calibration would give. A user designs from a measured one (:func:`calibrated_transfer`).
    """
    transfer = getattr(rig, "transfer", None)
    if transfer is None:
        raise ValidationError(f"the {rig.kind} rig has no model transfer; calibrate it first")
    return transfer(rig.layout.points_xy, np.fft.rfftfreq(n, 1 / rig.fs))


def design_window(rig: Rig, minimum: int = N_SAMPLES) -> int:
    """The design window of the demo: the rig's own when it knows its responses.

    A simulated forearm's :meth:`~vibrofocus.rigs.SimulatedForearm.design_window`
    follows its impulse-response length; any other rig gets ``minimum``.

    Parameters
    ----------
    rig : Rig
    minimum : int
        Shortest window, samples.
    """
    own = getattr(rig, "design_window", None)
    return int(minimum) if own is None else int(own(minimum))


@fill_doc
def record_clean(rig: Rig, drive: np.ndarray, points_xy: np.ndarray, *, tail_s: float = 0.0,
                 max_tries: int = 3) -> tuple[np.ndarray, int]:
    """Play and record, repeating a recording spoiled by vibrometer dropouts (NaN).

    A careful operator repeats a measurement whose sensor dropped out rather than
    patching it; so does the demo.

    Parameters
    ----------
    %(rig)s
    drive : ndarray, shape (n_actuators, n_samples)
        Drives, V.
    points_xy : ndarray, shape (n_points, 2)
        Where to record, m.
    tail_s : float
        Extra recording after the drive ends, s.
    max_tries : int
        Recordings at most.

    Returns
    -------
    recording : ndarray, shape (n_points, n_samples + n_tail)
        m; may still hold NaN if every try dropped out.
    repeats : int
        How many times the recording was repeated.
    """
    for attempt in range(max_tries):
        rec = rig.play_and_record(drive, points_xy, tail_s=tail_s)
        if not np.isnan(rec).any():
            return rec, attempt
    return rec, max_tries - 1


@dataclass
class DemoResult:
    """What :func:`run_demo` measured.

    Attributes
    ----------
    rows : list of dict
        One per (location, method), with at least the keys of ``ROW_KEYS``.
    renderings : dict
        ``(location, method) -> Rendering``.
    recordings : dict
        ``(location, method) -> ndarray (n_points, n)``, recorded displacement, m.
    rig : Rig
    H : ndarray
        The transfer matrix used for design.
    """

    rows: list[dict]
    renderings: dict = field(repr=False)
    recordings: dict = field(repr=False)
    rig: Rig = field(repr=False)
    H: np.ndarray = field(repr=False)


def calibrated_transfer(calibration) -> Callable[[Rig, int], Any]:
    """A ``transfer(rig, n)`` callable that designs from a measured calibration.

    Parameters
    ----------
    calibration : vibrofocus.calibration.Calibration
        Measured on the rig the demo plays on, over ``rig.layout.points_xy``.
    """

    def transfer(rig: Rig, n: int) -> Any:
        if calibration.layout != rig.layout:
            raise ValidationError("the calibration was measured on another layout than the rig's")
        from ..rendering import TransferMatrix

        # Its band, provenance and the calibration's kept wrap-around check come with it.
        return TransferMatrix.from_calibration(calibration, n)

    return transfer


def run_demo(
    rig: Rig,
    *,
    methods: Sequence[str] | None = None,
    locations: Sequence[int] | None = None,
    n_samples: int | None = None,
    transfer: Callable[[Rig, int], Any] = model_transfer,
    progress: Callable[[str], None] | None = None,
) -> DemoResult:
    """Render every method at every location, play it and measure how well it focuses.

    Parameters
    ----------
    rig : Rig
        Where to play (the simulated forearm).
    methods : sequence of str, optional
        Rendering methods (docs/method.md, rendering methods); default every registered
        one (:func:`~vibrofocus.rendering.available_methods`: the built-in ones and a
        lab's own) but the opt-in ones (``"minimax"``), which are rendered when named.
    locations : sequence of int, optional
        1-based locations; default all of the layout's.
    n_samples : int, optional
        Design window, samples; default :func:`design_window` of the rig.
    transfer : callable
        ``transfer(rig, n) -> H`` (an array or a
        :class:`~vibrofocus.rendering.TransferMatrix`); default :func:`model_transfer`;
        pass :func:`calibrated_transfer` to design from a measurement.
    progress : callable, optional
        Called with a short label after each (location, method).

    Returns
    -------
    DemoResult
    """
    from ..rendering import available_methods, focus_metrics, render
    from ..rendering.registry import default_methods
    from ..rendering.transfer import as_transfer_matrix

    methods = default_methods() if methods is None else tuple(methods)
    for m in methods:
        check_choice(m, "method", available_methods())
    layout = rig.layout
    locations = list(layout.location_numbers if locations is None else locations)
    for loc in locations:
        layout.location_index(loc)
    n = design_window(rig) if n_samples is None else int(n_samples)
    # One TransferMatrix for every design: validated once, its check and operators kept.
    tm = as_transfer_matrix(transfer(rig, n), rig.fs, layout, n_samples=n)
    H = tm.H
    points = layout.points_xy
    rows, renderings, recordings = [], {}, {}
    for loc in locations:
        for method in methods:
            # Every method at equal peak drive: scaled to the rig's limit (render reports the
            # scale in the Rendering; it warns of nothing).
            rendering = render(method, tm, rig.fs, layout, loc, limit_v=rig.limits.peak_v, on_limit="scale",
                               scale_to_limit=True)
            rec, repeats = record_clean(rig, rendering.drives, points)
            # Contrast against the other locations (the grid a participant names), as
            # Rendering.metrics does; the guards are reported separately.
            measured = focus_metrics(rec, rendering.target_index, rendering.desired, rig.fs, sigma=rendering.sigma,
                                     drives=rendering.drives, compare_indices=np.arange(layout.n_locations))
            every = focus_metrics(rec, rendering.target_index, rendering.desired, rig.fs, sigma=rendering.sigma)
            predicted = rendering.metrics()
            # The bound concerns the design's window: the energy contrast beside it is the
            # prediction's (the recording carries the decay tail past the window).
            row = {"location": int(loc), "method": method}
            row.update({k: float(measured[k]) for k in ("fidelity", "contrast_db", "peak_drive_v", "target_peak_m")})
            row.update(
                compactness=float(measured.get("compactness", np.nan)),
                shape_fidelity=float(measured["shape_fidelity"]),
                shape_lag_s=float(measured["shape_lag_s"]),
                contrast_all_points_db=float(every["contrast_db"]),
                energy_contrast_db=float(measured["energy_contrast_db"]),
                predicted_energy_contrast_db=float(predicted["energy_contrast_db"]),
                bound_db=float(predicted.get("bound_db", np.nan)),
                bound_own_db=float(predicted.get("bound_own_db", np.nan)),
                predicted_fidelity=float(predicted["fidelity"]),
                predicted_contrast_db=float(predicted["contrast_db"]),
                scale=float(rendering.scale),
                repeats=int(repeats),
            )
            rows.append(row)
            renderings[(loc, method)] = rendering
            recordings[(loc, method)] = rec
            if progress is not None:
                progress(f"location {loc}, {method}")
    return DemoResult(rows=rows, renderings=renderings, recordings=recordings, rig=rig, H=H)


def summarize(rows: Sequence[dict]) -> dict[str, dict[str, float]]:
    """Median fidelity, shape fidelity, contrasts (locations, all points, energy) and
    bound (and the peak bound, where the rows have it), target peak and peak drive per method.

    Parameters
    ----------
    rows : sequence of dict
        ``DemoResult.rows``.

    Returns
    -------
    dict of str to dict
        Method to the medians over its rows (NaN ignored).
    """
    out: dict[str, dict[str, float]] = {}
    for method in dict.fromkeys(r["method"] for r in rows):
        sub = [r for r in rows if r["method"] == method]
        out[method] = {
            key: float(np.nanmedian([r[key] for r in sub]))
            for key in ("fidelity", "shape_fidelity", "contrast_db", "contrast_all_points_db", "energy_contrast_db",
                        "bound_db", "peak_bound_db", "target_peak_m", "peak_drive_v")
            if key != "peak_bound_db" or all(key in r for r in sub)  # with the frontier (demo --frontier)
        }
    return out
