"""``vibrofocus latency`` on the simulated rig: clicks through its loopback, onsets found in
the recording, the statistics and the report."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from vibrofocus.errors import ValidationError
from vibrofocus.realtime import click_drive, latency_figure, measure_latency, onset_s
from vibrofocus.rigs import DeviceError, make_rig
from vibrofocus.rigs.simulated import SimulatedForearm


def test_onset_is_found_below_a_sample():
    fs = 10_000.0
    drive = click_drive(fs, 4, 2, 1.0)
    base = onset_s(drive[1], fs)
    # The same click, delayed by 12.25 samples (a fractional delay in the frequency domain).
    n = 4 * drive.shape[1]
    spectrum = np.fft.rfft(drive[1], n) * np.exp(-2j * np.pi * np.fft.rfftfreq(n) * 12.25)
    late = np.fft.irfft(spectrum, n)
    assert onset_s(late, fs) - base == pytest.approx(12.25 / fs, abs=0.05 / fs)
    assert onset_s(-late, fs) == pytest.approx(onset_s(late, fs))  # an inverting loopback


def test_no_click_in_the_recording_is_a_device_error(rng):
    with pytest.raises(DeviceError, match="no click came back"):
        onset_s(1e-3 * rng.standard_normal(1000), 10_000.0)
    with pytest.raises(DeviceError, match="no click came back"):
        onset_s(np.zeros(100), 10_000.0)


def test_simulated_rig_reports_its_modelled_latency():
    rig = SimulatedForearm(seed=1, latency_s=3.3e-3)
    report = measure_latency(rig, count=20, spacing_s=0.0, loopback=1, channel=3, amplitude_v=2.0)
    stats = report.stats_ms
    assert stats["mean"] == pytest.approx(3.3, abs=1e-6)
    assert stats["sd"] == pytest.approx(0.0, abs=1e-9) and stats["max"] == pytest.approx(3.3, abs=1e-6)
    assert rig.n_played == 20 and np.all(rig.outputs_v == 0)
    data = report.to_dict()
    assert data["count"] == 20 and len(data["latencies_ms"]) == 20
    fig = latency_figure(report)
    assert fig.axes[0].get_xlabel().startswith("onset latency")


def test_bad_channels_are_refused():
    rig = make_rig("simulated")
    with pytest.raises(ValidationError, match="one loopback input"):
        measure_latency(rig, count=2, spacing_s=0, loopback=2)
    with pytest.raises(ValidationError, match="actuator outputs 1..4"):
        measure_latency(rig, count=2, spacing_s=0, loopback=1, channel=5)
    with pytest.raises(ValidationError, match="count"):
        measure_latency(rig, count=1, spacing_s=0, loopback=1)
    assert rig.n_played == 0


def test_cli_json_and_figure(tmp_path):
    fig = tmp_path / "latency.png"
    done = subprocess.run([sys.executable, "-m", "vibrofocus", "latency", "--count", "10", "--spacing", "0",
                           "--figure", str(fig), "--json"], cwd=tmp_path, capture_output=True, text=True,
                          timeout=300, env=dict(os.environ, PYTHONDONTWRITEBYTECODE="1", MPLBACKEND="Agg"))
    assert done.returncode == 0, done.stderr
    data = json.loads(done.stdout)
    assert data["rig"] == "simulated" and data["count"] == 10
    assert set(data["latency_ms"]) == {"mean", "sd", "p99", "min", "max"}
    assert fig.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.parametrize("args, needle", [
    (["--figure", "x.svg"], "use a .png"),
    (["--loopback", "3"], "one loopback input"),
    (["--rig", "nidaq"], "needs a rig config"),
])
def test_cli_errors_are_one_line(tmp_path, args, needle):
    done = subprocess.run([sys.executable, "-m", "vibrofocus", "latency", "--count", "2", *args], cwd=tmp_path,
                          capture_output=True, text=True, timeout=300, env=dict(os.environ, PYTHONDONTWRITEBYTECODE="1"))
    assert done.returncode == 2
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error:") and needle in lines[0], lines


def test_cli_says_at_once_that_the_simulated_rig_has_no_latency():
    # Issue 54, item 9: the first line came after the imports and the rig (14 s here),
    # and only the last one said why the simulated rig reads 0 ms.
    from typer.testing import CliRunner

    from vibrofocus.cli.main import app

    result = CliRunner().invoke(app, ["latency", "--count", "2", "--spacing", "0"])
    assert result.exit_code == 0, result.output
    first = result.output.splitlines()[0]
    assert first.startswith("playing 2 clicks") and "no latency by construction" in first, first
    assert "onset latency: mean 0.000 ms" in result.output
