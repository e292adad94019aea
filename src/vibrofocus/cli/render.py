"""``vibrofocus render``: drive signals for a tap at a location, from a calibration file."""

from __future__ import annotations

from pathlib import Path

import typer

from ._errors import user_errors
from ._options import LIMIT_V_MIN, N_SAMPLES_RANGE, force_option
from ._command import command


@command("render", epilog="Example: vibrofocus render --calibration P01.nc --method inverse --location 5 "
                               "--out drives.npz --wav drives.wav --plot drives.png")
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
    plot: Path | None = typer.Option(None, "--plot", help="Also write the figure of the web app's Preview as a PNG: "
                                                          "the drives, the predicted displacements and their peaks."),
    force: bool = force_option(),
) -> None:
    """Design drives for a tap at LOCATION with METHOD and write them with their metadata.

    The .npz holds drives (n_actuators, n) in V, fs in Hz and the metadata; the .csv has
    a time column and one column per actuator in V, after '#' metadata lines. The WAV is
    for audio-interface rigs: sample value 1.0 means the drive limit (e.g. 10 V) at the
    actuator, so set the interface and amplifier gain so that digital full scale gives
    that voltage; the scale is written in the metadata (volts_per_full_scale). The PNG
    (--plot) is the web app's Preview: drives, predicted displacements, peaks per location.

    A design that does not fit its window (noise in the measured H spreads a little drive
    over all of it) is made again with the window's ends tapered, as a study does.
    """
    with user_errors():
        from .._atomic import allow_overwrite
        from ..workflows.render import render_tap

        allow_overwrite(force)
        outcome = render_tap(calibration, location, out, method=method, regularization=regularization,
                             reg_param=reg_param, n_samples=n_samples, limit_v=limit_v, refuse=refuse, wav=wav,
                             plot=plot)
        for line in outcome.lines:
            typer.echo(line)
