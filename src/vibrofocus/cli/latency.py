"""``vibrofocus latency``: a rig's onset latency and jitter, measured through a loopback."""

from __future__ import annotations

import json
from pathlib import Path

import typer

from ._command import command
from ._errors import user_errors
from ._options import RIG_CONFIG_HELP, SEED_MAX, check_rig_options, force_option

#: --count: at least two clicks (an SD), at most 100 000 (hours at the shortest spacing).
COUNT_RANGE = (2, 100_000)
#: --amplitude-v, V: the click's peak at the actuator (the rig's limit is the upper bound).
AMPLITUDE_RANGE = (1e-3, 20.0)


@command("latency", epilog="Example: vibrofocus latency --rig audio --rig-config rig.toml --loopback 2 "
                           "--count 500 --figure latency.png --json")
def latency(
    rig: str = typer.Option("simulated", "--rig", help="simulated | audio | nidaq"),
    rig_config: Path | None = typer.Option(None, "--rig-config", help=RIG_CONFIG_HELP),
    loopback: int = typer.Option(1, "--loopback", min=1, max=256,
                                 help="Input channel the loopback cable comes back on (1-based; the simulated "
                                      "rig has input 1; on nidaq, input k is ai<k-1>)."),
    channel: int = typer.Option(1, "--channel", min=1, max=256, help="Actuator output the clicks play on (1-based)."),
    count: int = typer.Option(100, "--count", "-n", min=COUNT_RANGE[0], max=COUNT_RANGE[1], help="Clicks."),
    spacing: float = typer.Option(0.2, "--spacing", min=0.0, max=60.0,
                                  help="Time from one click's start to the next, s (0 <= s <= 60)."),
    amplitude_v: float = typer.Option(1.0, "--amplitude-v", min=AMPLITUDE_RANGE[0], max=AMPLITUDE_RANGE[1],
                                      help="Click peak at the actuator, V (within the rig's limit)."),
    figure: Path | None = typer.Option(None, "--figure", help="Write a histogram of the latencies (.png)."),
    seed: int | None = typer.Option(None, "--seed", min=0, max=SEED_MAX, help="Seed of the simulated forearm."),
    as_json: bool = typer.Option(False, "--json", help="Print machine-readable JSON (every latency, ms)."),
    force: bool = force_option(),
) -> None:
    """Play COUNT clicks, one stream each, through a loopback and report their onset latency and jitter.

    Wire an actuator output (--channel) to an input (--loopback) of the interface, with
    the amplifier and actuator disconnected or at a safe level. Each click's onset in the
    recording, less its onset in the drive, is that play's latency; the report gives the
    mean, SD, 99th percentile and maximum, in ms.
    """
    with user_errors():
        from .._atomic import allow_overwrite, check_writable, save_figure
        from ..errors import ValidationError

        allow_overwrite(force)
        check_rig_options(rig, rig_config)
        if figure is not None:
            if figure.suffix.lower() != ".png":
                raise ValidationError(f"--figure {figure}: use a .png file name")
            check_writable(figure, what="latency figure")
        if not as_json:  # said before the imports and the rig (seconds): never a silent start
            typer.echo(f"playing {count} clicks {spacing:g} s apart on the {rig} rig ({count * spacing:.0f} s of "
                       "clicks once it is open)..." + (" It has no latency by construction: this checks the "
                                                      "measurement, which should read 0 ms."
                                                      if rig == "simulated" else ""))
        from ..realtime import latency_figure, measure_latency
        from ..rigs import make_rig

        with make_rig(rig, config=rig_config, seed=seed) as the_rig:
            report = measure_latency(the_rig, count=count, spacing_s=spacing, loopback=loopback, channel=channel,
                                     amplitude_v=amplitude_v)
        if figure is not None:
            save_figure(latency_figure(report), figure, what="latency figure", dpi=120)
        stats = report.stats_ms
        if as_json:
            out = report.to_dict()
            if figure is not None:
                out["figure"] = str(figure)
            typer.echo(json.dumps(out, indent=2))
            return
        typer.echo(f"{rig} rig, {count} clicks {spacing:g} s apart, output {channel} -> input {loopback} at "
                   f"{report.input_fs:g} Hz")
        typer.echo(f"onset latency: mean {stats['mean']:.3f} ms, SD {stats['sd']:.3f} ms, 99th percentile "
                   f"{stats['p99']:.3f} ms, max {stats['max']:.3f} ms (min {stats['min']:.3f} ms)")
        if rig == "simulated":
            typer.echo("the simulated rig plays each sample the moment it is handed over: its latency is 0 by "
                       "construction; measure a hardware rig's with --rig audio or nidaq")
        if figure is not None:
            typer.echo(f"wrote {figure}")
