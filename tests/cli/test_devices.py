"""``vibrofocus devices`` and ``vibrofocus straps``."""

from __future__ import annotations

import json

from typer.testing import CliRunner

from vibrofocus.cli.main import app

runner = CliRunner()


def test_devices_lists_or_explains_each_kind():
    result = runner.invoke(app, ["devices", "--json"])
    assert result.exit_code == 0, result.output
    out = json.loads(result.output)
    for kind in ("audio", "nidaq"):
        # Either devices are listed or a note says why none are.
        assert out[kind]["devices"] or out[kind]["note"]
    try:
        import nidaqmx.system

        nidaqmx.system.System.local().driver_version
    except Exception:  # noqa: BLE001 - no NI driver on this machine
        assert "NI-DAQmx driver is not installed" in out["nidaq"]["note"]


def test_devices_table_prints():
    result = runner.invoke(app, ["devices"])
    assert result.exit_code == 0, result.output
    assert "Audio devices" in result.output


def test_straps_on_a_rig_without_sensors_is_a_clear_error(tmp_path):
    cfg = tmp_path / "nidaq.json"
    cfg.write_text(json.dumps({"kind": "nidaq", "channels": {"actuators": ["ao0", "ao1", "ao2", "ao3"],
                                                              "vibrometer": "ai0"},
                               "vibrometer": {"decoder": "velocity", "sensitivity": 0.005}}))
    result = runner.invoke(app, ["straps", "--rig", "nidaq", "--rig-config", str(cfg)])
    assert result.exit_code == 2
    assert result.output.startswith("error:")


def test_the_tone_on_a_high_gain_chain_plays_at_the_largest_level_within_the_limits():
    """Gain 100 and 12 V at full scale put 1 % into 12 V peak: the tone is lowered, not refused."""
    from types import SimpleNamespace

    import numpy as np

    from vibrofocus.cli.devices import TONE_FRACTION, tone_drive
    from vibrofocus.rigs.safety import EnergyBudget, SafetyLimits, check_drive

    limits, fs = SafetyLimits(), 48000.0
    drive, digital_peak = tone_drive(SimpleNamespace(amplifier_gain=100.0, volts_full_scale=12.0), limits, fs, 4, 10.0)
    EnergyBudget(limits, 4, fs).admit(check_drive(drive, fs, 4, limits), 0.0)  # refused at 1 %: 12 V peak
    assert 0.004 < digital_peak < TONE_FRACTION  # 4 V RMS at the actuators: 0.47 %
    np.testing.assert_allclose(np.abs(drive[0]).max(), digital_peak * 100 * 12, rtol=1e-4)
    # A usual chain keeps 1 %.
    _, usual = tone_drive(SimpleNamespace(amplifier_gain=10.0, volts_full_scale=1.0), limits, fs, 4, 10.0)
    assert usual == TONE_FRACTION
