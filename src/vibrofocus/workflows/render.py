"""Render one tap from a calibration file and write its drives, WAV and figure: ``vibrofocus render``'s work.

The drives files are docs/file-formats.md, "Drives files"; the design is
docs/method.md, "Rendering methods". The figure is the web app's *Preview*
(:func:`vibrofocus.rendering.figures.plot_preview`).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

__all__ = ["TapOutcome", "render_tap", "scaling_words"]


@dataclass
class TapOutcome:
    """What :func:`render_tap` made and wrote.

    Attributes
    ----------
    rendering : Rendering
        The design (drives in V, predicted response in m, scale).
    limit_v : float
        The drive limit the design was held to, V peak.
    metadata : dict
        What the drives file stores beside the drives.
    lines : list of str
        What was written and predicted, one line each, for a person to read.
    """

    rendering: Any
    limit_v: float
    metadata: dict[str, Any]
    lines: list[str] = field(default_factory=list)


def scaling_words(scale: float, needed_peak_v: float, limit_v: float) -> str:
    """How a design was scaled to the drive limit, in words (``""`` when it was not).

    Parameters
    ----------
    scale : float
        The factor applied to the design's drives.
    needed_peak_v : float
        The design's own peak drive before scaling, V.
    limit_v : float
        The drive limit, V peak.

    Returns
    -------
    str
        ``"scaled up ×1.07, from 9.33 V to the 10 V limit (equal peak)"`` for a design
        raised to the limit (every method plays at the same peak), ``"scaled down ×0.85,
        from 11.8 V to the 10 V limit (over it)"`` for one that exceeded it.
    """
    if scale == 1.0:
        return ""
    way, why = ("up", "equal peak") if scale > 1.0 else ("down", "over it")
    return f"scaled {way} ×{scale:.3g}, from {needed_peak_v:.3g} V to the {limit_v:g} V limit ({why})"


def _drive_limit(cal: Any, calibration: Path, limit_v: float | None) -> float:
    """The drive limit for ``cal``: ``limit_v`` or the rig's stored limit, never above the rig's own."""
    from ..defaults import DRIVE_LIMIT_V
    from ..errors import ValidationError
    from ..rigs.safety import PEAK_V_CEILING, SafetyLimits

    rig_limits = cal.rig.get("limits") if isinstance(cal.rig.get("limits"), dict) else {}
    rig_limit = rig_limits.get("peak_v", DRIVE_LIMIT_V)
    if isinstance(rig_limit, bool) or not isinstance(rig_limit, (int, float)) or not 0 < rig_limit < float("inf"):
        raise ValidationError(f"{calibration}: the stored rig limit peak_v={rig_limit!r} is not a positive number")
    # A stored limit never loosens the rig's own: the simulated rig's is fixed, and no
    # hardware configuration may pass the hard ceiling; a larger value was edited in.
    kind = cal.rig.get("kind")
    own = SafetyLimits().peak_v if kind == "simulated" else PEAK_V_CEILING
    if rig_limit > own and limit_v is None:
        raise ValidationError(
            f"{calibration}: the stored rig limit peak_v={rig_limit:g} V is above the {own:g} V that "
            + ("the simulated rig has" if kind == "simulated" else "any rig may have (the hard ceiling)")
            + f" (the file may have been edited); give --limit-v, at most {own:g}"
        )
    rig_limit = min(float(rig_limit), own)
    if limit_v is not None and limit_v > rig_limit * (1 + 1e-9):
        raise ValidationError(
            f"--limit-v {limit_v:g} is above the {rig_limit:g} V peak limit of the rig this calibration was "
            f"measured on; such drives could not be played on it (give at most {rig_limit:g})"
        )
    return limit_v if limit_v is not None else rig_limit


def _check_outputs(out: Path, wav: Path | None, plot: Path | None) -> None:
    """Refuse output names of the wrong kind, or twice the same file, before any work."""
    from .._atomic import DRIVES_CSV, check_writable
    from ..errors import ValidationError
    from ..io.drives import DRIVES_SUFFIXES

    if out.suffix.lower() not in DRIVES_SUFFIXES:
        raise ValidationError(f"--out {out}: use a .npz or .csv file name")
    if wav is not None and wav.suffix.lower() != ".wav":
        raise ValidationError(f"--wav {wav}: use a .wav file name")
    if plot is not None and plot.suffix.lower() != ".png":
        raise ValidationError(f"--plot {plot}: use a .png file name")
    seen: dict[Path, str] = {}
    for flag, path in (("--out", out), ("--wav", wav), ("--plot", plot)):
        if path is not None and path.resolve() in seen:
            raise ValidationError(f"{seen[path.resolve()]} and {flag} name the same file {path}")
        if path is not None:
            seen[path.resolve()] = flag
    for path, what in ((out, "drives file"), (wav, "WAV file"), (plot, "figure")):
        if path is not None:
            check_writable(path, what=what, kind=DRIVES_CSV if path.suffix.lower() == ".csv" else None)


def render_tap(calibration: str | os.PathLike, location: int, out: str | os.PathLike, *, method: str = "inverse",
               regularization: str | None = None, reg_param: float | None = None, n_samples: int | None = None,
               limit_v: float | None = None, refuse: bool = False, wav: str | os.PathLike | None = None,
               plot: str | os.PathLike | None = None) -> TapOutcome:
    """Design drives for a tap at ``location`` from a calibration file and write them.

    Parameters
    ----------
    calibration : path-like
        Calibration file (.nc).
    location : int
        Target location number (1-based).
    out : path-like
        Drives file: ``.npz`` or ``.csv`` (docs/file-formats.md, "Drives files").
    method : str
        A registered rendering method.
    regularization : {None, "tikhonov", "tsvd"}
        Of the inverse designs.
    reg_param : float, optional
        Regularization relative to the largest singular value.
    n_samples : int, optional
        Window length, samples; default the calibration's own (its n_fft).
    limit_v : float, optional
        Drive limit, V peak; default the rig's stored limit (never above the rig's own).
    refuse : bool
        Refuse a design over the limit instead of scaling it down.
    wav : path-like, optional
        Also write a multichannel float32 WAV (full scale = the drive limit).
    plot : path-like, optional
        Also write the figure of the web app's *Preview* as a PNG
        (:func:`vibrofocus.rendering.figures.plot_preview`).

    Returns
    -------
    TapOutcome

    Raises
    ------
    ValidationError
        A bad output name, a calibration whose stored limit is not a number or above the
        rig's own, a limit above the rig's, or a design that cannot be made.
    OutputError
        A file cannot be written; a previous file of that name is unchanged.
    """
    import numpy as np

    from .. import __version__
    from .._atomic import protect, save_figure
    from .._validation import check_memory
    from ..calibration import load_calibration
    from ..io.drives import write_drives, write_drives_wav
    from ..rendering import TransferMatrix
    from ..rendering.render import render_fitted
    from ..rendering.transfer import calibration_window

    calibration, out = Path(calibration), Path(out)
    wav, plot = (None if p is None else Path(p) for p in (wav, plot))
    protect(calibration, "calibration")
    _check_outputs(out, wav, plot)
    cal = load_calibration(calibration)
    if n_samples is None:
        n_samples = calibration_window(cal)
    # H on the window, the designs' batched solves and the responses: about ten
    # copies of H (n/2+1 frequencies x points x actuators, complex).
    check_memory(10 * 16 * (n_samples // 2 + 1) * cal.layout.n_points * cal.layout.n_actuators,
                 f"--n-samples {n_samples}")
    limit = _drive_limit(cal, calibration, limit_v)
    tm = TransferMatrix.from_calibration(cal, n_samples)
    rendering = render_fitted(method, tm, cal.fs, cal.layout, location, limit_v=limit,
                              on_limit="refuse" if refuse else "scale", regularization=regularization,
                              reg_param=reg_param, band=cal.band)
    drives = rendering.drives
    predicted = rendering.metrics()
    meta = {
        "software": "vibrofocus", "software_version": __version__, "calibration": str(calibration),
        "participant_id": cal.participant_id, "calibration_created": cal.created, "method": method,
        "location": location, "target_index": rendering.target_index, "fs": cal.fs,
        "actuators": list(cal.layout.actuator_names), "units": "V", "limit_v": limit,
        "scale": rendering.scale, "needed_peak_v": rendering.needed_peak_v,
        "predicted_target_peak_m": rendering.reached_peak_m, "t0_s": rendering.t0,
        "regularization": regularization, "reg_param": reg_param, "band_hz": list(rendering.band),
        "predicted_fidelity": predicted["fidelity"], "predicted_contrast_db": predicted["contrast_db"],
    }
    # Written beside the target and renamed over it: a full disk or Ctrl-C never
    # leaves a truncated drives file, and an old file of that name survives a failure.
    write_drives(out, drives, cal.fs, actuator_names=cal.layout.actuator_names, metadata=meta,
                 predicted=rendering.predicted, desired=rendering.desired)
    scaled = scaling_words(rendering.scale, rendering.needed_peak_v, limit)
    lines = [f"wrote {out}: {drives.shape[0]} channels x {drives.shape[1]} samples at {cal.fs:g} Hz, "
             f"peak {np.abs(drives).max():.3g} V" + (f", {scaled}" if scaled else ""),
             f"predicted at location {location}: fidelity {predicted['fidelity']:.3f}, contrast "
             f"{predicted['contrast_db']:.1f} dB, target peak {rendering.reached_peak_m * 1e6:.3g} µm"]
    if wav is not None:
        _, sidecar = write_drives_wav(wav, drives, cal.fs, volts_per_full_scale=limit, metadata=meta)
        lines.append(f"wrote {wav} (float32, full scale = {limit:g} V) and {sidecar}")
    if plot is not None:
        from ..rendering.figures import plot_preview

        save_figure(plot_preview(rendering, cal.layout, cal.fs, method=method, location=location), plot,
                    what="figure", dpi=100)
        lines.append(f"wrote {plot}: the drives, the predicted displacements and their peaks over the locations")
    return TapOutcome(rendering, limit, meta, lines)
