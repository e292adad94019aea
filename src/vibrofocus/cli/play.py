"""``vibrofocus play``: play a drives file (written by ``vibrofocus render``) on a rig."""

from __future__ import annotations

import json
from pathlib import Path

import typer

from ._errors import user_errors
from ._options import RIG_CONFIG_HELP, SEED_MAX, check_rig_options
from ._command import command


@command("play")
def play(
    drives_file: Path = typer.Argument(..., help="An .npz with arrays drives (n_actuators, n) V and fs (Hz)."),
    rig: str = typer.Option("simulated", "--rig", help="simulated | audio | nidaq"),
    rig_config: Path | None = typer.Option(None, "--rig-config", help=RIG_CONFIG_HELP),
    seed: int | None = typer.Option(None, "--seed", min=0, max=SEED_MAX,
                                    help="Participant seed of the simulated forearm."),
    dry_run: bool = typer.Option(False, "--dry-run", help="Only run the safety checks; play nothing."),
    as_json: bool = typer.Option(False, "--json", help="Print machine-readable JSON."),
) -> None:
    """Play a drives file on the actuators, through the safety layer (limits, fades)."""
    with user_errors():
        import numpy as np

        from ..errors import ValidationError
        from ..io.drives import read_drives
        from ..rigs import make_rig

        check_rig_options(rig, rig_config)
        with make_rig(rig, config=rig_config, seed=seed) as r:
            # The rig's duration limit is checked from the file's header, before the
            # samples are decompressed.
            drives, fs = read_drives(drives_file, max_duration_s=r.limits.max_duration_s)
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
