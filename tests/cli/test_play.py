"""``vibrofocus play``: a drives file through the safety layer onto a rig."""

from __future__ import annotations

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from vibrofocus.cli.main import app
from vibrofocus.signals import ricker

FS = 10_000.0
runner = CliRunner()


def write_drives(path, amplitude=2.0, fs=FS, **extra):
    drives = np.zeros((4, 2000))
    drives[2] = amplitude * ricker(FS, duration=0.2, t0=0.05)
    np.savez(path, drives=drives, fs=fs, **extra)
    return drives


def test_plays_on_the_simulated_rig(tmp_path):
    path = tmp_path / "tap.npz"
    write_drives(path)
    result = runner.invoke(app, ["play", str(path), "--rig", "simulated", "--json"])
    assert result.exit_code == 0, result.output
    out = json.loads(result.output)
    assert out["played"] and out["duration_s"] == pytest.approx(0.2)
    np.testing.assert_allclose(out["peak_v"], [0, 0, 2.0, 0], atol=1e-6)


def test_dry_run_checks_without_playing(tmp_path):
    path = tmp_path / "tap.npz"
    write_drives(path)
    result = runner.invoke(app, ["play", str(path), "--dry-run"])
    assert result.exit_code == 0, result.output
    assert "checked (not played)" in result.output


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(amplitude=12.0), "over the limit of 10 V"),
        (dict(fs=48_000.0), "is at 48000 Hz but the simulated rig runs at 10000 Hz"),
    ],
)
def test_unsafe_or_foreign_drives_are_refused(tmp_path, kwargs, message):
    path = tmp_path / "bad.npz"
    write_drives(path, **kwargs)
    result = runner.invoke(app, ["play", str(path)])
    assert result.exit_code == 2
    assert message in " ".join(result.output.split())


def flat(result) -> str:
    return " ".join(result.output.split())  # rich wraps long messages


def test_bad_files_are_named(tmp_path):
    result = runner.invoke(app, ["play", str(tmp_path / "none.npz")])
    assert result.exit_code == 2 and "no such file" in flat(result)
    path = tmp_path / "nofs.npz"
    np.savez(path, drives=np.zeros((4, 10)))
    result = runner.invoke(app, ["play", str(path)])
    assert result.exit_code == 2 and "missing array(s) fs (it holds drives)" in flat(result)
    junk = tmp_path / "junk.npz"
    junk.write_text("not a zip")
    result = runner.invoke(app, ["play", str(junk)])
    assert result.exit_code == 2 and "not a readable .npz file" in " ".join(result.output.split())


def test_hardware_rig_without_config_is_refused(tmp_path):
    path = tmp_path / "tap.npz"
    write_drives(path)
    result = runner.invoke(app, ["play", str(path), "--rig", "audio"])
    assert result.exit_code == 2
    assert "needs a rig config file" in " ".join(result.output.split())


def test_a_plain_npy_or_foreign_file_is_named_not_a_traceback(tmp_path):
    npy = tmp_path / "drives.npy"
    np.save(npy, np.zeros((4, 10)))
    result = runner.invoke(app, ["play", str(npy)])
    assert result.exit_code == 2, result.output
    assert "drives.npy" in flat(result) and ".npz" in flat(result)
    assert result.exception is None or isinstance(result.exception, SystemExit)
    other = tmp_path / "calibration.nc"
    other.write_bytes(b"\x89HDF\r\n\x1a\n" + bytes(100))
    result = runner.invoke(app, ["play", str(other)])
    assert result.exit_code == 2 and "not a readable .npz file" in flat(result)
    assert "pickle" not in flat(result)


def test_boolean_drives_are_not_voltages(tmp_path):
    path = tmp_path / "bool.npz"
    np.savez(path, drives=np.ones((4, 100), dtype=bool), fs=FS)
    result = runner.invoke(app, ["play", str(path)])
    assert result.exit_code == 2, result.output
    assert "bool" in flat(result)


def test_the_reported_rms_is_the_enforced_one_over_any_window(tmp_path):
    """0.2 s of a 2 V peak tap: its RMS over 1 s (what the limit holds) is sqrt(energy / 1 s), not the file's own RMS."""
    path = tmp_path / "tap.npz"
    drives = write_drives(path)
    result = runner.invoke(app, ["play", str(path), "--dry-run", "--json"])
    assert result.exit_code == 0, result.output
    out = json.loads(result.output)
    from vibrofocus.rigs import SafetyLimits, check_drive

    safe = check_drive(drives, FS, 4, SafetyLimits())
    expected = np.sqrt(np.sum(safe**2, axis=1) / FS / 1.0)  # energy over a 1 s window of silence after it
    np.testing.assert_allclose(out["rms_v"], expected, rtol=1e-5, atol=1e-9)
    assert out["rms_window_s"] == 1.0


def test_a_hardware_dry_run_needs_only_the_config_file(tmp_path):
    """No interface is opened: the checks come from the lab's config (here an audio interface that is not there)."""
    cfg = {"kind": "audio", "fs": FS, "amplifier_gain": 10.0, "volts_full_scale": 1.0,
           "device": {"name": "an interface that is not plugged in"},
           "channels": {"actuators": [1, 2, 3, 4], "vibrometer": 1},
           "vibrometer": {"decoder": "displacement", "sensitivity": 1e-6}, "limits": {"peak_v": 5.0}}
    lab = tmp_path / "lab.json"
    lab.write_text(json.dumps(cfg))
    ok, loud = tmp_path / "ok.npz", tmp_path / "loud.npz"
    write_drives(ok, amplitude=4.0)
    write_drives(loud, amplitude=6.0)
    result = runner.invoke(app, ["play", str(ok), "--rig", "audio", "--rig-config", str(lab), "--dry-run", "--json"])
    assert result.exit_code == 0, result.output
    assert json.loads(result.output)["played"] is False
    result = runner.invoke(app, ["play", str(loud), "--rig", "audio", "--rig-config", str(lab), "--dry-run"])
    assert result.exit_code == 2 and "over the limit of 5 V" in result.output
