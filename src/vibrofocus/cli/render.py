"""``vibrofocus render``: drive signals for a tap at a location, from a calibration file."""

from __future__ import annotations

from pathlib import Path

import typer

from ._errors import user_errors
from ._options import LIMIT_V_MIN, N_SAMPLES_RANGE, force_option
from ._command import command


@command("render", epilog="Example: vibrofocus render --calibration P01.nc --method inverse --location 5 "
                               "--out drives.npz --wav drives.wav")
def render_command(
    calibration: Path = typer.Option(..., "--calibration", "-c", help="Calibration file (.nc)."),
    location: int = typer.Option(..., "--location", "-l",
                                 help="Target location number (1-based; 1-9 on the reference layout)."),
    out: Path = typer.Option(..., "--out", "-o", help="Drives file: .npz (for vibrofocus play) or .csv."),
    method: str = typer.Option("inverse", "--method", "-m",
                               help="A registered rendering method: funneling | inverse | combination | "
                                    "time_reversal | contrast | constrained, or a lab's own (vibrofocus.methods "
                                    "entry point)."),
    regularization: str | None = typer.Option(None, "--regularization", help="tikhonov | tsvd (default: plain "
                                                                              "pseudo-inverse)."),
    reg_param: float | None = typer.Option(None, "--reg-param", max=1e3,
                                           help="Regularization relative to the largest singular value "
                                                "(0 < value <= 1000)."),
    n_samples: int | None = typer.Option(None, "--n-samples", min=N_SAMPLES_RANGE[0], max=N_SAMPLES_RANGE[1],
                                         show_default=False,
                                         help="Window length, samples; default the calibration's own resolution "
                                              "(its n_fft: 4096 for the reference setup), where its H holds the "
                                              "impulse responses as measured."),
    limit_v: float | None = typer.Option(None, "--limit-v", min=LIMIT_V_MIN,
                                         help="Drive limit, V peak: at most the rig's limit stored in the calibration, "
                                              "itself never above the rig's own (10 V for the simulated rig, 20 V "
                                              "for any; default: that limit)."),
    refuse: bool = typer.Option(False, "--refuse-over-limit", help="Refuse a design over the limit instead of "
                                                                   "scaling it down."),
    wav: Path | None = typer.Option(None, "--wav", help="Also write a multichannel WAV (float32, full scale = "
                                                        "the drive limit)."),
    force: bool = force_option(),
) -> None:
    """Design drives for a tap at LOCATION with METHOD and write them with their metadata.

    The .npz holds drives (n_actuators, n) in V, fs in Hz and the metadata; the .csv has
    a time column and one column per actuator in V, after '#' metadata lines. The WAV is
    for audio-interface rigs: sample value 1.0 means the drive limit (e.g. 10 V) at the
    actuator, so set the interface and amplifier gain so that digital full scale gives
    that voltage; the scale is written in the metadata (volts_per_full_scale).

    A design that does not fit its window (noise in the measured H spreads a little drive
    over all of it) is made again with the window's ends tapered, as a study does.
    """
    with user_errors():
        import numpy as np

        from .. import __version__
        from .._atomic import DRIVES_CSV, allow_overwrite, check_writable, protect
        from .._validation import check_memory
        from ..calibration import load_calibration
        from ..defaults import DRIVE_LIMIT_V
        from ..errors import ValidationError
        from ..io.drives import DRIVES_SUFFIXES, write_drives, write_drives_wav
        from ..rendering import TransferMatrix
        from ..rendering.render import render_fitted
        from ..rendering.transfer import calibration_window
        from ..rigs.safety import PEAK_V_CEILING, SafetyLimits

        allow_overwrite(force)
        protect(calibration, "calibration")
        if out.suffix.lower() not in DRIVES_SUFFIXES:
            raise ValidationError(f"--out {out}: use a .npz or .csv file name")
        if wav is not None and wav.suffix.lower() != ".wav":
            raise ValidationError(f"--wav {wav}: use a .wav file name")
        if wav is not None and len({out.resolve(), wav.resolve()}) == 1:
            raise ValidationError(f"--out and --wav name the same file {out}")
        for path, what in ((out, "drives file"), (wav, "WAV file")):
            if path is not None:
                check_writable(path, what=what, kind=DRIVES_CSV if path.suffix.lower() == ".csv" else None)
        cal = load_calibration(calibration)
        if n_samples is None:
            n_samples = calibration_window(cal)
        # H on the window, the designs' batched solves and the responses: about ten
        # copies of H (n/2+1 frequencies x points x actuators, complex).
        check_memory(10 * 16 * (n_samples // 2 + 1) * cal.layout.n_points * cal.layout.n_actuators,
                     f"--n-samples {n_samples}")
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
        limit = limit_v if limit_v is not None else rig_limit
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
        typer.echo(f"wrote {out}: {drives.shape[0]} channels x {drives.shape[1]} samples at {cal.fs:g} Hz, "
                   f"peak {np.abs(drives).max():.3g} V"
                   + ("" if rendering.scale == 1.0 else f" (scaled by {rendering.scale:.3g} to the {limit:g} V limit)"))
        typer.echo(f"predicted at location {location}: fidelity {predicted['fidelity']:.3f}, contrast "
                   f"{predicted['contrast_db']:.1f} dB, target peak {rendering.reached_peak_m * 1e6:.3g} µm")
        if wav is not None:
            _, sidecar = write_drives_wav(wav, drives, cal.fs, volts_per_full_scale=limit, metadata=meta)
            typer.echo(f"wrote {wav} (float32, full scale = {limit:g} V) and {sidecar}")
