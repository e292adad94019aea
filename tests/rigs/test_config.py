"""Rig configuration files: the examples load, bad files are refused with specific messages."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from vibrofocus.errors import ValidationError
from vibrofocus.rigs import AudioRigConfig, NidaqRigConfig, RigConfig, load_rig_config, make_rig, parse_rig_config

EXAMPLES = Path(__file__).resolve().parents[2] / "examples" / "rigs"


def audio_dict(**extra) -> dict:
    cfg = {
        "kind": "audio", "amplifier_gain": 10.0, "volts_full_scale": 1.0,
        "channels": {"actuators": [1, 2, 3, 4], "vibrometer": 1},
        "vibrometer": {"decoder": "velocity", "sensitivity": 0.005},
    }
    cfg.update(extra)
    return cfg


def test_examples_load_with_their_settings():
    audio = load_rig_config(EXAMPLES / "audio.toml")
    assert isinstance(audio, AudioRigConfig)
    assert audio.channels.actuators == [1, 2, 3, 4]
    assert audio.output_peak_v == pytest.approx(1.0)  # 10 V at the actuator through 20 dB
    nidaq = RigConfig.from_file(EXAMPLES / "nidaq.toml")
    assert isinstance(nidaq, NidaqRigConfig)
    assert nidaq.physical("ao2") == "Dev1/ao2"
    assert nidaq.force_sensors.build().names == ("proximal strap", "distal strap")
    assert nidaq.limits.build().peak_v == 10.0


def test_json_and_toml_agree(tmp_path):
    path = tmp_path / "rig.json"
    path.write_text(json.dumps(audio_dict()))
    cfg = load_rig_config(path)
    assert cfg == parse_rig_config(audio_dict())
    assert cfg.vibrometer.build().sensitivity == 0.005


@pytest.mark.parametrize(
    "change, message",
    [
        (dict(amplifer_gain=10.0), r"amplifer_gain: unknown setting"),
        (dict(amplifier_gain=-1), r"amplifier_gain: Input should be greater than 0"),
        (dict(kind="midi"), r"kind: must be 'audio' or 'nidaq', got 'midi'"),
        (dict(channels={"actuators": [1, 1, 2, 3], "vibrometer": 1}), r"channels: .*distinct output channels"),
        (dict(channels={"actuators": [0, 1, 2, 3], "vibrometer": 1}), r"channels.actuators.0: .*greater than or equal to 1"),
        (dict(channels={"actuators": [1, 2, 3, 4], "vibrometer": 1, "loopback_output": 5}),
         r"loopback_output and loopback_input go together"),
        (dict(channels={"actuators": [1, 2, 3, 4], "vibrometer": 1, "loopback_output": 4, "loopback_input": 2}),
         r"loopback_output 4 is also an actuator output"),
        (dict(vibrometer={"decoder": "acceleration", "sensitivity": 1.0}), r"vibrometer.decoder: Input should be"),
        (dict(vibrometer={"decoder": "velocity"}), r"vibrometer.sensitivity: Field required"),
        (dict(volts_full_scale=0.5), r"needs 1 V at the interface .* volts_full_scale = 0.5 V. Drives would clip: "
                                     r"raise amplifier_gain, or lower limits.peak_v to at most 5 V"),
        (dict(limits={"peak_v": 5.0, "rms_v": 0}), r"limits.rms_v: Input should be greater than 0"),
        (dict(latency_samples=-3), r"latency_samples: Input should be greater than or equal to 0"),
        (dict(force_sensors={"channels": ["3"]}), r"force_sensors: audio interfaces are AC-coupled"),
        # hard ceilings and the amplifier cap (docs/hardware.md)
        (dict(amplifier_gain=float("inf")), r"amplifier_gain: Input should be a finite number"),
        (dict(amplifier_gain=1.0), r"needs 10 V into the amplifier .* amplifier_input_max_v = 1 V. Check amplifier_gain"),
        (dict(amplifier_input_max_v=20.0), r"amplifier_input_max_v: Input should be less than or equal to 10"),
        (dict(limits={"peak_v": 30.0}), r"limits.peak_v: Input should be less than or equal to 20"),
        (dict(limits={"rms_v": 100.0}), r"limits.rms_v: Input should be less than or equal to 5.66"),
        (dict(limits={"max_duration_s": 1000.0}), r"limits.max_duration_s: Input should be less than or equal to 60"),
        (dict(limits={"fade_s": 0.0}), r"limits.fade_s: Input should be greater than or equal to 0.0001"),
        (dict(limits={"fade_s": 100.0}), r"limits.fade_s: Input should be less than or equal to 0.05"),
        (dict(limits={"peak_v": float("nan")}), r"limits.peak_v: Input should be a finite number"),
    ],
)
def test_bad_audio_settings_are_named(change, message):
    with pytest.raises(ValidationError, match=message):
        parse_rig_config(audio_dict(**change))


def test_bad_nidaq_settings_are_named():
    base = {"kind": "nidaq", "channels": {"actuators": ["ao0", "ao1", "ao2", "ao3"], "vibrometer": "ai0"},
            "vibrometer": {"decoder": "displacement", "sensitivity": 1e-6}}
    with pytest.raises(ValidationError, match=r"actuator channel 'ai1' is not an analog output"):
        parse_rig_config({**base, "channels": {"actuators": ["ao0", "ai1", "ao2", "ao3"], "vibrometer": "ai0"}})
    with pytest.raises(ValidationError, match=r"vibrometer channel 'ao1' is not an analog input"):
        parse_rig_config({**base, "channels": {"actuators": ["ao0"], "vibrometer": "ao1"}})
    with pytest.raises(ValidationError, match=r"amplifier_input_max_v = 5 V is more than the analog outputs can "
                                              r"put out \(ao_max_v = 2 V\)"):
        parse_rig_config({**base, "amplifier_input_max_v": 5.0, "ao_max_v": 2.0})
    with pytest.raises(ValidationError, match=r"force_sensors: .*names has 1 entries but channels has 2"):
        parse_rig_config({**base, "force_sensors": {"channels": ["ai1", "ai2"], "names": ["a"]}})
    with pytest.raises(ValidationError, match=r"force_sensors.curve: .*strictly increasing"):
        parse_rig_config({**base, "force_sensors": {"channels": ["ai1"],
                                                    "curve": {"volts": [0, 2, 1], "newtons": [0, 1, 2]}}})


def test_file_problems_are_named(tmp_path):
    with pytest.raises(ValidationError, match=r"no such file"):
        load_rig_config(tmp_path / "missing.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text('kind = "audio"\namplifier_gain = = 3\n')
    with pytest.raises(ValidationError, match=r"bad.toml: not valid TOML .*line 2"):
        load_rig_config(bad)
    yaml = tmp_path / "rig.yaml"
    yaml.write_text("kind: audio\n")
    with pytest.raises(ValidationError, match=r"unknown file type '.yaml'; use .toml or .json"):
        load_rig_config(yaml)
    nokind = tmp_path / "nokind.json"
    nokind.write_text(json.dumps({"fs": 1000}))
    with pytest.raises(ValidationError, match=r"kind is missing"):
        load_rig_config(nokind)
    listing = tmp_path / "list.json"
    listing.write_text("[1, 2]")
    with pytest.raises(ValidationError, match=r"must be a table of settings, got list"):
        load_rig_config(listing)


def test_make_rig_needs_a_matching_config():
    with pytest.raises(ValidationError, match=r"the audio rig needs a rig config file"):
        make_rig("audio")
    with pytest.raises(ValidationError, match=r"config is for a 'audio' rig, but --rig asks for 'nidaq'"):
        make_rig("nidaq", config=audio_dict())
    with pytest.raises(ValidationError, match=r"config must be a path, a mapping or a RigConfig, got int"):
        make_rig("audio", config=3)
    with pytest.raises(ValidationError, match=r"rig must be one of"):
        make_rig("serial")


def test_configs_are_frozen():
    cfg = parse_rig_config(audio_dict())
    with pytest.raises(Exception):
        cfg.amplifier_gain = 100.0  # a running rig's gain chain cannot change under it


def _named_commands(text: str) -> list[list[str]]:
    """The `vibrofocus ...` commands a message or comment tells the user to run, as argument lists."""
    import re
    import shlex

    found = re.findall(r"`vibrofocus ([^`]+)`", text)
    found += re.findall(r"^#\s+vibrofocus (.+)$", text, flags=re.MULTILINE)
    return [shlex.split(cmd) for cmd in found]


def _parses(args: list[str], config: Path) -> None:
    """Parse ``vibrofocus ARGS`` as the CLI would, without running it (a bad option raises)."""
    import typer

    from vibrofocus.cli.main import app

    args = [str(config) if a in ("FILE", "this-file.toml") else a for a in args]
    group = typer.main.get_command(app)
    with group.make_context("vibrofocus", list(args), resilient_parsing=False) as ctx:
        name, command, rest = group.resolve_command(ctx, list(args))
        command.make_context(name, rest, parent=ctx)


def test_the_volts_full_scale_measurement_the_error_and_the_example_name_parses(tmp_path):
    config = tmp_path / "lab.toml"
    config.write_text((EXAMPLES / "audio.toml").read_text())
    cfg = audio_dict()
    del cfg["volts_full_scale"]
    with pytest.raises(ValidationError, match="volts_full_scale: required") as info:
        parse_rig_config(cfg)
    for text in (str(info.value), (EXAMPLES / "audio.toml").read_text()):
        commands = [c for c in _named_commands(text) if "--tone" in c]
        assert commands, text
        for args in commands:
            _parses(args, config)  # "No such option: --rig" before


def test_the_rms_ceiling_as_the_docs_write_it_is_accepted_as_the_ceiling():
    from vibrofocus.rigs.safety import RMS_V_CEILING, SafetyLimits

    assert f"{RMS_V_CEILING:.3g}" == "5.66"
    limits = parse_rig_config(audio_dict(limits={"peak_v": 10.0, "rms_v": 5.66})).limits.build()
    assert limits.rms_v == RMS_V_CEILING  # taken as the ceiling itself, never above it
    assert SafetyLimits(rms_v=5.66).rms_v == RMS_V_CEILING
    with pytest.raises(ValidationError, match="less than or equal to 5.66"):
        parse_rig_config(audio_dict(limits={"rms_v": 5.67}))
    with pytest.raises(ValidationError, match="hard ceiling of 5.66"):
        SafetyLimits(rms_v=5.661)
    # The example's comment states the ceilings the code holds.
    assert "hard ceilings: 20 V peak, 5.66 V RMS, 60 s" in (EXAMPLES / "audio.toml").read_text()
