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
    dry_run: bool = typer.Option(False, "--dry-run", help="Only run the safety checks; play nothing. With a hardware "
                                 "rig, the checks come from --rig-config alone: the interface need not be there."),
    as_json: bool = typer.Option(False, "--json", help="Print machine-readable JSON."),
) -> None:
    """Play a drives file on the actuators, through the safety layer (limits, fades)."""
    with user_errors():
        import numpy as np

        from ..io.drives import read_drives
        from ..rigs import make_rig

        check_rig_options(rig, rig_config)
        if dry_run and rig != "simulated":
            # The checks from the config file alone: a lab checks its drives against its
            # limits before the interface is plugged in.
            from ..rigs import check_drive, load_rig_config
            from ..rigs.hardware import check_amplifier_input

            cfg = load_rig_config(rig_config)
            limits, rig_fs = cfg.limits.build(), cfg.fs
            drives, fs = _read_at_rate(read_drives, drives_file, limits.max_duration_s, rig_fs, rig)
            safe = check_drive(drives, rig_fs, cfg.n_actuators, limits)
            check_amplifier_input(safe, cfg)
        else:
            with make_rig(rig, config=rig_config, seed=seed) as r:
                limits = r.limits
                # The rig's duration limit is checked from the file's header, before the
                # samples are decompressed.
                drives, fs = _read_at_rate(read_drives, drives_file, limits.max_duration_s, r.fs, rig)
                safe = r.check(drives)  # refuses before anything is opened
                if not dry_run:
                    r.play(drives)
        from ..rigs.safety import windowed_rms

        n_window = max(1, int(round(limits.rms_window_s * fs)))
        summary = {
            "file": str(drives_file), "rig": rig, "played": not dry_run, "fs": fs,
            "duration_s": drives.shape[1] / fs,
            "peak_v": np.abs(safe).max(axis=1).round(6).tolist(),
            # What the limit holds: the largest RMS over any window of rms_window_s (a
            # drive shorter than the window counts as followed by silence).
            "rms_v": windowed_rms(safe**2, n_window).round(6).tolist(),
            "rms_window_s": limits.rms_window_s,
            "limits": {"peak_v": limits.peak_v, "rms_v": limits.rms_v},
        }
        if as_json:
            typer.echo(json.dumps(summary, indent=2))
        else:
            verb = "played" if not dry_run else "checked (not played)"
            peaks = ", ".join(f"{p:.3g}" for p in summary["peak_v"])
            rms = ", ".join(f"{v:.3g}" for v in summary["rms_v"])
            typer.echo(f"{verb} {drives.shape[0]} channels, {summary['duration_s']:.3f} s on the {rig} rig; "
                       f"peak per channel [V]: {peaks} (limit {limits.peak_v:g}); RMS over any "
                       f"{limits.rms_window_s:g} s [V]: {rms} (limit {limits.rms_v:g})")


def _read_at_rate(read_drives, path, max_duration_s: float, rig_fs: float, rig: str):
    """Read a drives file and refuse one made for another sample rate."""
    from ..errors import ValidationError

    drives, fs = read_drives(path, max_duration_s=max_duration_s)
    if abs(fs - rig_fs) > 1e-9 * rig_fs:
        raise ValidationError(f"drives file {path} is at {fs:g} Hz but the {rig} rig runs at {rig_fs:g} Hz; render it "
                              "again for this rig")
    return drives, fs
