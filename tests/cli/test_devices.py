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
