"""``vibrofocus devices`` (what hardware is present) and ``vibrofocus straps`` (strap forces)."""

from __future__ import annotations

import json
from pathlib import Path

import typer

from ._errors import user_errors
from ._options import RIG_CONFIG_HELP, SEED_MAX, check_rig_options
from ._command import command


@command("devices", epilog="Example: vibrofocus devices --check examples/rigs/audio.toml")
def devices(
    as_json: bool = typer.Option(False, "--json", help="Print machine-readable JSON."),
    check: Path | None = typer.Option(
        None, "--check", metavar="RIG_CONFIG",
        help="Open the rig of this config file and run its checks at setup (device, channels, rates, output "
             "range, timing, limits) without playing anything; exit 2 at the first problem."),
) -> None:
    """List audio interfaces (PortAudio) and NI-DAQmx devices, with their channels.

    With --check FILE, open that rig as a calibration or study would, run the same checks
    it runs before its first play, print what they found, and close it: nothing is played.
    """
    if check is not None:
        return _check_rig(check, as_json)
    with user_errors():
        from rich.console import Console
        from rich.table import Table

        from ..rigs import list_audio_devices, list_nidaq_devices

        audio, nidaq = list_audio_devices(), list_nidaq_devices()
        if as_json:
            typer.echo(json.dumps({"audio": {"devices": audio.devices, "note": audio.note},
                                   "nidaq": {"devices": nidaq.devices, "note": nidaq.note}}, indent=2))
            return
        console = Console()
        table = Table(title="Audio devices (use the index or name in a rig config's \\[device] table)")
        for col in ("index", "name", "host API", "inputs", "outputs", "default rate (Hz)"):
            table.add_column(col, justify="right" if col in ("index", "inputs", "outputs") else "left")
        for d in audio.devices:
            table.add_row(str(d["index"]), d["name"], d["hostapi"], str(d["inputs"]), str(d["outputs"]),
                          f"{d['default_samplerate']:g}")
        console.print(table)
        if audio.note:
            console.print(f"[yellow]audio:[/] {audio.note}")
        if nidaq.devices:
            ni = Table(title="NI-DAQmx devices")
            for col in ("name", "product", "analog outputs", "analog inputs"):
                ni.add_column(col)
            for d in nidaq.devices:
                ni.add_row(d["name"], d["product_type"], ", ".join(d["ao"]), ", ".join(d["ai"]))
            console.print(ni)
        if nidaq.note:
            console.print(f"[yellow]NI-DAQmx:[/] {nidaq.note}")


@command("straps")
def straps(
    rig: str = typer.Option("simulated", "--rig", help="simulated | audio | nidaq"),
    rig_config: Path | None = typer.Option(None, "--rig-config", help=RIG_CONFIG_HELP),
    seed: int | None = typer.Option(None, "--seed", min=0, max=SEED_MAX,
                                    help="Participant seed of the simulated forearm."),
    target: float | None = typer.Option(None, "--target-n", min=0.01, max=20.0,
                                         help="Target strap force, N (default from the config, 1 N)."),
    tolerance: float | None = typer.Option(None, "--tolerance-n", min=0.0, max=20.0, help="Accepted deviation, N."),
    as_json: bool = typer.Option(False, "--json", help="Print machine-readable JSON."),
) -> None:
    """Read the strap force sensors before a calibration and say whether to tighten or loosen.

    Exits with code 1 when a strap is off target."""
    with user_errors():
        from rich.console import Console
        from rich.table import Table

        from ..rigs import check_straps, make_rig

        check_rig_options(rig, rig_config)
        with make_rig(rig, config=rig_config, seed=seed) as r:
            reading = check_straps(r, target_n=target, tolerance_n=tolerance)
        if as_json:
            typer.echo(json.dumps(reading.to_dict(), indent=2))
        else:
            colour = {"ok": "green", "too loose": "yellow", "too tight": "red", "out of range": "red"}
            table = Table(title=f"Strap forces (target {reading.target_n:g} ± {reading.tolerance_n:g} N)"
                                + (" — simulated" if reading.simulated else ""))
            for col in ("strap", "force (N)", "verdict"):
                table.add_column(col, justify="right" if col == "force (N)" else "left")
            for name, f, v in zip(reading.names, reading.forces_n, reading.verdicts):
                table.add_row(name, "—" if f != f else f"{f:.2f}", f"[{colour[v]}]{v}[/]")
            console = Console()
            console.print(table)
            console.print(reading.message)
        if not reading.ok:
            raise typer.Exit(code=1)


def _check_rig(path: Path, as_json: bool) -> None:
    with user_errors():
        from rich.console import Console

        from ..rigs import load_rig_config, make_rig

        cfg = load_rig_config(path)
        with make_rig(cfg.kind, config=cfg) as rig:
            lines = [*rig.setup_report, *rig.limits_report()]
        if as_json:
            typer.echo(json.dumps({"rig": cfg.kind, "config": str(path), "ok": True, "found": lines}, indent=2))
            return
        console = Console()
        console.print(f"{cfg.kind} rig from {path}: every check passed; nothing was played", highlight=False)
        for line in lines:
            console.print(f"  {line}", highlight=False)
