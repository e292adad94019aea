"""``vibrofocus calibrate`` and ``vibrofocus render`` end to end on the simulated forearm."""

import json

import numpy as np
import pytest
from scipy.io import wavfile
from typer.testing import CliRunner

from vibrofocus.calibration import load_calibration
from vibrofocus.cli.main import app

runner = CliRunner()


def text(result) -> str:
    """The output with rich's line wrapping undone."""
    return " ".join(result.output.split())


@pytest.fixture(scope="module")
def cal_file(tmp_path_factory):
    out = tmp_path_factory.mktemp("cli") / "P01.nc"
    result = runner.invoke(app, ["calibrate", "--rig", "simulated", "--participant", "P01", "--out", str(out),
                                 "--seed", "2", "--method", "h1", "--repeats", "2", "--sweep-s", "1", "--yes"])
    assert result.exit_code == 0, result.output
    assert "Calibration of P01" in text(result) and "wrote" in text(result) and out.is_file()
    return out


def test_calibrate_writes_the_file_and_its_figure(cal_file):
    cal = load_calibration(cal_file)
    assert cal.participant_id == "P01" and cal.method == "h1" and cal.sweep.repeats == 2
    assert cal.rig["kind"] == "simulated" and cal.rig["seed"] == 2
    png = cal_file.with_suffix(".png")
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_render_npz_csv_and_wav_agree(cal_file, tmp_path):
    npz, csv, wav = tmp_path / "d.npz", tmp_path / "d.csv", tmp_path / "d.wav"
    for out, extra in ((npz, ["--wav", str(wav)]), (csv, [])):
        result = runner.invoke(app, ["render", "--calibration", str(cal_file), "--method", "inverse",
                                     "--location", "5", "--out", str(out), *extra])
        assert result.exit_code == 0, result.output
    with np.load(npz) as data:
        drives, fs = data["drives"], float(data["fs"])
        meta = json.loads(str(data["metadata"]))
    assert drives.shape == (4, 4096) and fs == 10_000.0
    assert meta["location"] == 5 and meta["participant_id"] == "P01" and meta["units"] == "V"
    assert np.abs(drives).max() <= meta["limit_v"] + 1e-12
    table = np.loadtxt(csv, delimiter=",", comments="#")
    np.testing.assert_allclose(table[:, 1:].T, drives, rtol=1e-8, atol=1e-12)
    np.testing.assert_allclose(table[:, 0], np.arange(4096) / fs)
    rate, samples = wavfile.read(wav)
    scale = json.loads((tmp_path / "d.wav.json").read_text())["volts_per_full_scale"]
    assert rate == 10_000 and samples.dtype == np.float32 and samples.shape == (4096, 4) and scale == 10.0
    np.testing.assert_allclose(samples.T * scale, drives, rtol=1e-6, atol=1e-6)


def test_render_plot_writes_the_web_previews_figure(cal_file, tmp_path, monkeypatch):
    # --plot draws the one preview figure the web app serves (rendering.figures.plot_preview), saved as PNG.
    import vibrofocus._atomic as atomic

    drawn = []
    real_save = atomic.save_figure
    monkeypatch.setattr(atomic, "save_figure", lambda fig, path, **kw: drawn.append(fig) or real_save(fig, path, **kw))
    png = tmp_path / "tap.png"
    result = runner.invoke(app, ["render", "--calibration", str(cal_file), "--location", "5",
                                 "--out", str(tmp_path / "tap.npz"), "--plot", str(png)])
    assert result.exit_code == 0, result.output
    data = png.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    assert (int.from_bytes(data[16:20], "big"), int.from_bytes(data[20:24], "big")) == (1100, 420)  # 11 x 4.2 in
    (fig,) = drawn
    titles = [ax.get_title() for ax in fig.axes]
    assert titles[:3] == ["drive signals", "target (red), other points (grey)", "peak |u|: ■ actuators, ▲ guards"]
    assert len(fig.axes) == 4 and fig.get_suptitle() == "inverse at location 5"  # three panels and a colour bar
    assert f"wrote {png}" in text(result)
    # The scaling to the limit says which way, from what, and why.
    meta = json.loads(str(np.load(tmp_path / "tap.npz")["metadata"]))
    way = "up" if meta["scale"] > 1 else "down"
    assert (f"scaled {way} ×{meta['scale']:.3g}, from {meta['needed_peak_v']:.3g} V to the 10 V limit "
            f"({'equal peak' if way == 'up' else 'over it'})") in text(result)
    assert "scaled by" not in text(result)


def test_render_refuses_a_plot_that_is_not_a_png(cal_file, tmp_path):
    result = runner.invoke(app, ["render", "--calibration", str(cal_file), "--location", "5",
                                 "--out", str(tmp_path / "tap.npz"), "--plot", str(tmp_path / "tap.npz")])
    assert result.exit_code == 2 and "--plot" in text(result) and ".png" in text(result)
    assert not (tmp_path / "tap.npz").exists()


def test_render_refuses_a_foreign_calibration_file(tmp_path):
    bad = tmp_path / "notes.nc"
    bad.write_text("not a calibration")
    result = runner.invoke(app, ["render", "--calibration", str(bad), "--location", "5",
                                 "--out", str(tmp_path / "d.npz")])
    assert result.exit_code == 2
    assert "notes.nc: is not a netCDF4/HDF5 calibration file" in text(result)


def test_render_refuses_a_location_outside_the_layout(cal_file, tmp_path):
    result = runner.invoke(app, ["render", "--calibration", str(cal_file), "--location", "10",
                                 "--out", str(tmp_path / "d.npz")])
    assert result.exit_code == 2 and "location 10" in text(result)


def test_calibrate_refuses_a_missing_output_folder(tmp_path):
    result = runner.invoke(app, ["calibrate", "--participant", "P", "--out", str(tmp_path / "no" / "P.nc"), "--yes"])
    assert result.exit_code == 2 and "does not exist" in text(result)


def test_render_refuses_a_limit_above_the_rigs(cal_file, tmp_path):
    # The calibration stores the rig's safety limit (10 V); drives (and a WAV whose full
    # scale is the limit) designed for more could never be played safely on that rig.
    out = tmp_path / "d.npz"
    result = runner.invoke(app, ["render", "--calibration", str(cal_file), "--location", "5",
                                 "--limit-v", "25", "--out", str(out)])
    assert result.exit_code == 2, result.output
    assert "--limit-v 25" in text(result) and "10 V" in text(result)
    assert not out.exists()
    lower = runner.invoke(app, ["render", "--calibration", str(cal_file), "--location", "5",
                                "--limit-v", "5", "--out", str(out)])
    assert lower.exit_code == 0, lower.output
    with np.load(out) as data:
        assert np.abs(data["drives"]).max() <= 5.0 + 1e-12


@pytest.mark.parametrize("name, value", [("fs", "ten kHz"), ("rig", "[1, 2]"), ("n_fft", "x")])
def test_render_from_a_calibration_with_a_malformed_attribute_is_one_line(cal_file, tmp_path, name, value):
    import shutil

    import h5py

    bad = tmp_path / "bad.nc"
    shutil.copy(cal_file, bad)
    with h5py.File(bad, "r+") as h5:
        h5.attrs[name] = value
    result = runner.invoke(app, ["render", "--calibration", str(bad), "--location", "5",
                                 "--out", str(tmp_path / "d.npz")])
    assert result.exit_code == 2, result.output
    assert "bad.nc" in text(result) and name in text(result)
    assert result.exception is None or isinstance(result.exception, SystemExit)


def test_calibrate_over_the_duration_limit_does_not_blame_the_amplitude(tmp_path):
    result = runner.invoke(app, ["calibrate", "--participant", "P", "--out", str(tmp_path / "c.nc"),
                                 "--sweep-s", "40", "--yes"])
    assert result.exit_code == 2
    assert "longer than the limit" in text(result) and "sweep_s" in text(result)


def test_calibrate_accepts_method_mimo_and_prints_the_plan_first(tmp_path):
    out = tmp_path / "M.nc"
    result = runner.invoke(app, ["calibrate", "--rig", "simulated", "--participant", "M", "--out", str(out),
                                 "--seed", "3", "--method", "mimo", "--repeats", "4", "--sweep-s", "1", "--yes",
                                 "--no-figure"])
    assert result.exit_code == 0, result.output
    printed = text(result)
    plan = ("plan: mimo: 4 takes of 1.4 s (all 4 actuators at once, 4 Hadamard-coded repeats, every point in each "
            "take) = 5.6 s of sweeps")
    assert plan in printed and printed.index(plan) < printed.index("Calibration of M")
    cal = load_calibration(out)
    assert cal.method == "mimo" and cal.codes.shape == (4, 4) and cal.recordings.shape[:2] == (4, 13)


def test_calibrate_without_a_method_is_mimo_and_h1_prints_its_plan_too(tmp_path):
    result = runner.invoke(app, ["calibrate", "--participant", "D", "--out", str(tmp_path / "D.nc"), "--seed", "3",
                                 "--repeats", "4", "--sweep-s", "0.5", "--yes", "--no-figure"])
    assert result.exit_code == 0, result.output
    assert load_calibration(tmp_path / "D.nc").method == "mimo"
    result = runner.invoke(app, ["calibrate", "--participant", "D", "--out", str(tmp_path / "H.nc"), "--seed", "3",
                                 "--method", "h1", "--repeats", "1", "--sweep-s", "0.5", "--yes", "--no-figure"])
    assert result.exit_code == 0, result.output
    assert "plan: h1: 4 takes of 0.9 s (4 actuator(s) one at a time x 1 repeat(s), every point in each take) = " \
           "3.6 s of sweeps" in text(result)


def test_calibrate_mimo_refuses_repeats_that_cannot_separate_the_actuators(tmp_path):
    out = tmp_path / "M.nc"
    result = runner.invoke(app, ["calibrate", "--participant", "M", "--out", str(out), "--method", "mimo",
                                 "--repeats", "6", "--yes"])
    assert result.exit_code == 2, result.output
    assert "repeats=6 cannot separate 4 actuators" in text(result) and "use 4 or 8" in text(result)
    assert not out.exists()


def test_calibrate_help_names_mimo_as_the_default():
    result = runner.invoke(app, ["calibrate", "--help"], env={"COLUMNS": "200"})
    assert result.exit_code == 0
    assert "mimo (all actuators at once" in text(result) and "default: mimo" in text(result)


@pytest.mark.slow
def test_render_fits_the_window_of_seed_7103s_arm_without_a_window_option(tmp_path):
    """Participant 11 of ``simulate-study -n 20 --seed 7103``: on main ``render`` took a
    4096-sample window and refused the inverse design at location 4 (0.14 % of its response
    past the window, 'try n_samples=8192', where no longer window fits either); the
    studies' renderer tapered the window's ends. ``render`` now does as the study does."""
    from vibrofocus.simulation.simulate import participant_seeds

    cal = tmp_path / "sim-011.nc"
    made = runner.invoke(app, ["calibrate", "--rig", "simulated", "--participant", "sim-011", "--out", str(cal),
                               "--seed", str(participant_seeds(7103, 11)[0]), "--skin", "nominal", "--yes"])
    assert made.exit_code == 0, made.output
    out = tmp_path / "d.npz"
    result = runner.invoke(app, ["render", "--calibration", str(cal), "--method", "inverse", "--location", "4",
                                 "--out", str(out)])
    assert result.exit_code == 0, result.output
    with np.load(out) as data:
        drives, meta = data["drives"], json.loads(str(data["metadata"]))
    assert drives.shape == (4, load_calibration(cal).n_fft)  # the calibration's own resolution
    assert meta["predicted_fidelity"] > 0.8


def test_calibrate_refuses_more_points_than_the_layout_has_before_any_sweep(tmp_path):
    out = tmp_path / "K.nc"
    result = runner.invoke(app, ["calibrate", "--participant", "K", "--out", str(out), "--points", "14", "--yes"])
    assert result.exit_code == 2, result.output
    assert "from 2 to the layout's 13 points, got 14" in text(result)
    assert not out.exists()
    result = runner.invoke(app, ["calibrate", "--participant", "K", "--out", str(out), "--points", "1", "--yes"])
    assert result.exit_code == 2 and not out.exists()


@pytest.mark.slow
def test_calibrate_points_measures_a_subset_and_marks_the_predicted_points(tmp_path):
    out = tmp_path / "S.nc"
    result = runner.invoke(app, ["calibrate", "--participant", "S", "--out", str(out), "--seed", "3", "--points", "7",
                                 "--repeats", "4", "--sweep-s", "0.5", "--yes", "--no-figure"])
    assert result.exit_code == 0, result.output
    printed = text(result)
    assert "measures 7 of 13 points and predicts the other 6 from the fitted skin model" in printed
    assert "point(s) 1, 3, 6, 7, 8, 9 were not measured" in printed and "predicted" in printed
    cal = load_calibration(out)
    assert cal.measured.tolist() == [False, True, False, True, True, False, False, False, False] + [True] * 4
    assert cal.fit is not None and cal.fit.law == "layered"


def test_calibrate_help_explains_points():
    result = runner.invoke(app, ["calibrate", "--help"], env={"COLUMNS": "200"})
    assert result.exit_code == 0
    assert "--points" in text(result) and "predict H at the others" in text(result)
