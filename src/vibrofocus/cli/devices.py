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
             "range, timing, limits, other programs on the outputs where the host API shows them) without playing "
             "anything; exit 2 at the first problem."),
    tone: bool = typer.Option(
        False, "--tone",
        help="With --check on an audio rig: after the checks, play a 100 Hz sine at 1 % of digital full scale "
             "on the first actuator output, to measure volts_full_scale with a voltmeter (amplifier off; "
             "docs/hardware.md, first-day checklist)."),
    tone_s: float = typer.Option(10.0, "--tone-s", min=0.5, max=30.0, help="How long the --tone plays, s."),
) -> None:
    """List audio interfaces (PortAudio) and NI-DAQmx devices, with their channels.

    With --check FILE, open that rig as a calibration or study would, run the same checks
    it runs before its first play, print what they found, and close it: nothing is played.
    With --tone as well (audio rigs), it then plays a known low digital level for a
    voltmeter: the measurement that sets volts_full_scale.
    """
    if tone and check is None:
        with user_errors():
            from ..errors import ValidationError

            raise ValidationError("--tone plays on the rig of --check RIG_CONFIG; give the config file")
    if check is not None:
        return _check_rig(check, as_json, tone_s if tone else None)
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


#: Digital level and frequency of ``devices --check --tone``: low enough to be harmless
#: at any interface's full scale (1 % of 12 V is 0.12 V into the amplifier), high enough
#: for a handheld meter's AC range.
TONE_FRACTION = 0.01
TONE_HZ = 100.0


def _check_rig(path: Path, as_json: bool, tone_s: float | None = None) -> None:
    with user_errors():
        from rich.console import Console

        from ..errors import ValidationError
        from ..rigs import load_rig_config, make_rig

        cfg = load_rig_config(path)
        if tone_s is not None and cfg.kind != "audio":
            raise ValidationError(f"--tone is for audio rigs, whose output level depends on volts_full_scale; "
                                  f"a {cfg.kind} rig's outputs are set in volts already")
        tone = None
        with make_rig(cfg.kind, config=cfg) as rig:
            if hasattr(rig, "check_outputs_alone"):  # another program feeding the outputs is a problem
                rig.check_outputs_alone()
            lines = [*rig.setup_report, *rig.limits_report()]
            if tone_s is not None:
                tone = _play_tone(rig, cfg, tone_s)
        if as_json:
            out = {"rig": cfg.kind, "config": str(path), "ok": True, "found": lines}
            if tone is not None:
                out["tone"] = tone
            typer.echo(json.dumps(out, indent=2))
            return
        console = Console()
        played = "nothing was played" if tone is None else "then the tone below played"
        console.print(f"{cfg.kind} rig from {path}: every check passed; {played}", highlight=False)
        for line in lines:
            console.print(f"  {line}", highlight=False)
        if tone is not None:
            console.print(
                f"Played {tone['frequency_hz']:g} Hz for {tone['duration_s']:g} s at {100 * tone['digital_peak']:.3g} % "
                f"of digital full scale on output {tone['output_channel']}"
                + ("" if tone["digital_peak"] >= TONE_FRACTION else
                   f" (not {100 * TONE_FRACTION:g} %: with the amplifier's gain of {cfg.amplifier_gain:g} that would "
                   "break the rig's limits at the actuators, were the amplifier on)")
                + f". Set volts_full_scale = (the meter's AC "
                f"RMS reading, V) x {tone['volts_full_scale_per_rms_v']:.1f}. With the configured "
                f"{cfg.volts_full_scale:g} V, the meter should read {tone['expected_rms_v']:.4g} V RMS; if it reads "
                "more, every voltage into the amplifier is higher than the software computes. The stream's output "
                f"latency (what an emergency stop cannot recall) was {1e3 * tone['stream_output_latency_s']:.0f} ms.",
                highlight=False)


def tone_drive(cfg, limits, fs: float, n_actuators: int, seconds: float):
    """The volts_full_scale measuring tone on the first actuator output, and its digital peak.

    At :data:`TONE_FRACTION` of digital full scale, or lower where the chain's gain would
    put more than the rig's limits allow at the actuators (gain 100 and 12 V at full scale
    make 1 % into 12 V peak): the tone then plays at the largest level within the limits,
    measured by the energy budget's own windows (:func:`vibrofocus.rigs.safety.plan_levels`).

    Returns
    -------
    drive : ndarray, shape (n_actuators, n_samples)
        Volts at the actuators.
    digital_peak : float
        The tone's peak as a fraction of digital full scale.
    """
    import numpy as np

    from ..rigs.safety import plan_levels

    n = int(round(seconds * fs))
    # Actuator volts that the rig turns into this digital level: V / (gain * volts_full_scale).
    volts_per_digital = cfg.amplifier_gain * cfg.volts_full_scale
    drive = np.zeros((n_actuators, n))
    drive[0] = TONE_FRACTION * volts_per_digital * np.sin(2 * np.pi * TONE_HZ * np.arange(n) / fs)
    scale = plan_levels([drive], fs, limits).scale_to_fit
    return drive * scale, TONE_FRACTION * scale


def _play_tone(rig, cfg, seconds: float) -> dict:
    """Play the volts_full_scale measuring tone on the first actuator output; describe it."""
    import numpy as np

    drive, digital_peak = tone_drive(cfg, rig.limits, rig.fs, rig.layout.n_actuators, seconds)
    rig.play(drive)
    return {
        "frequency_hz": TONE_HZ, "duration_s": drive.shape[1] / rig.fs, "digital_peak": digital_peak,
        "output_channel": cfg.channels.actuators[0],
        "expected_rms_v": digital_peak * cfg.volts_full_scale / np.sqrt(2),
        "volts_full_scale_per_rms_v": np.sqrt(2) / digital_peak,
        # What a stop cannot recall on this interface: the stream's own output latency.
        "stream_output_latency_s": float(rig.output_latency_s),
    }
