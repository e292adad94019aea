"""``vibrofocus play``: play a drives file (written by ``vibrofocus render``) on a rig."""

from __future__ import annotations

import json
from pathlib import Path

import typer

from ._errors import user_errors
from .main import app


def load_drives(path: Path):
    """Read ``drives`` (n_actuators, n_samples) V and ``fs`` Hz from an ``.npz`` file.

    Raises
    ------
    ValidationError
        Missing file, not an npz, missing or malformed arrays.
    """
    import zipfile

    import numpy as np

    from .._validation import as_array, check_positive
    from ..errors import ValidationError

    if not path.is_file():
        raise ValidationError(f"drives file {path}: no such file")
    try:
        with open(path, "rb") as fh:
            head = fh.read(4)
    except OSError as exc:
        raise ValidationError(f"drives file {path}: cannot be read ({exc.strerror or exc})") from None
    if head[:2] != b"PK":  # an .npz is a zip archive
        raise ValidationError(
            f"drives file {path}: not a readable .npz file (it does not start as a zip archive; write it with "
            "vibrofocus render --out FILE.npz or numpy.savez(FILE, drives=..., fs=...))"
        )
    try:
        with np.load(path, allow_pickle=False) as data:
            missing = [k for k in ("drives", "fs") if k not in data.files]
            if missing:
                raise ValidationError(
                    f"drives file {path}: missing array(s) {', '.join(missing)} (it holds {', '.join(data.files) or 'nothing'})"
                )
            raw = data["drives"]
            if raw.dtype.kind == "b":
                raise ValidationError(f"drives in {path} must be voltages, got dtype bool")
            drives = as_array(raw, f"drives in {path}", ndim=2, finite=False)
            fs_arr = np.asarray(data["fs"])
    except (OSError, ValueError, zipfile.BadZipFile) as exc:
        if isinstance(exc, ValidationError):
            raise
        raise ValidationError(f"drives file {path}: not a readable .npz file ({exc})") from None
    if fs_arr.size != 1:
        raise ValidationError(f"drives file {path}: fs must be one number, got shape {fs_arr.shape}")
    return drives, check_positive(fs_arr.reshape(()).item(), f"fs in {path}")


@app.command("play")
def play(
    drives_file: Path = typer.Argument(..., help="An .npz with arrays drives (n_actuators, n) V and fs (Hz)."),
    rig: str = typer.Option("simulated", "--rig", help="simulated | audio | nidaq"),
    rig_config: Path | None = typer.Option(None, "--rig-config", help="Hardware settings file for audio/nidaq."),
    seed: int | None = typer.Option(None, "--seed", min=0, help="Participant seed of the simulated forearm."),
    dry_run: bool = typer.Option(False, "--dry-run", help="Only run the safety checks; play nothing."),
    as_json: bool = typer.Option(False, "--json", help="Print machine-readable JSON."),
) -> None:
    """Play a drives file on the actuators, through the safety layer (limits, fades)."""
    with user_errors():
        import numpy as np

        from ..errors import ValidationError
        from ..rigs import make_rig

        drives, fs = load_drives(drives_file)
        with make_rig(rig, config=rig_config, seed=seed) as r:
            if abs(fs - r.fs) > 1e-9 * r.fs:
                raise ValidationError(
                    f"drives file {drives_file} is at {fs:g} Hz but the {rig} rig runs at {r.fs:g} Hz; render it again "
                    "for this rig"
                )
            safe = r.check(drives)  # refuses before anything is opened
            if not dry_run:
                r.play(drives)
        summary = {
            "file": str(drives_file), "rig": rig, "played": not dry_run, "fs": fs,
            "duration_s": drives.shape[1] / fs,
            "peak_v": np.abs(safe).max(axis=1).round(6).tolist(),
            "rms_v": np.sqrt(np.mean(safe**2, axis=1)).round(6).tolist(),
        }
        if as_json:
            typer.echo(json.dumps(summary, indent=2))
        else:
            verb = "played" if not dry_run else "checked (not played)"
            peaks = ", ".join(f"{p:.3g}" for p in summary["peak_v"])
            typer.echo(f"{verb} {drives.shape[0]} channels, {summary['duration_s']:.3f} s on the {rig} rig; "
                       f"peak per channel [V]: {peaks}")
