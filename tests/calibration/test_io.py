import json

import h5py
import numpy as np
import pytest
import xarray as xr

from vibrofocus.calibration import SCHEMA_VERSION, load_calibration, save_calibration
from vibrofocus.errors import CalibrationFileError

from ._netcdf import rewrite_netcdf


@pytest.fixture(scope="module")
def saved(fir_calibration_file):
    return fir_calibration_file


def test_round_trip_is_identical(fir_calibration, saved):
    cal = fir_calibration[1]
    back = load_calibration(saved)
    for name in ("H", "freqs", "coherence", "drives", "recordings"):
        np.testing.assert_array_equal(getattr(back, name), getattr(cal, name), err_msg=name)
        assert getattr(back, name).dtype == getattr(cal, name).dtype, name
    for name in ("fs", "band", "participant_id", "method", "rig", "sweep", "created", "software_version",
                 "schema_version", "layout"):
        assert getattr(back, name) == getattr(cal, name), name
    assert back.layout.point_labels == cal.layout.point_labels
    q, qb = cal.quality, back.quality
    assert qb.issues == q.issues and qb.thresholds == q.thresholds
    for name in ("snr_db", "noise_rms_m", "band_gain", "low_coherence_share", "coherent_to_hz", "clipped", "repeats_used",
                 "dropouts", "polarity"):
        np.testing.assert_array_equal(getattr(qb, name), getattr(q, name), err_msg=name)


def test_the_file_is_self_describing_for_plain_readers(saved):
    with h5py.File(saved, "r") as f:  # plain HDF5, no vibrofocus
        assert f.attrs["file_kind"] == "vibrofocus calibration"
        assert f["H_real"].attrs["units"] == b"m/V" or f["H_real"].attrs["units"] == "m/V"
        assert f["H_real"].shape == (2049, 13, 4)
    with xr.open_dataset(saved, engine="h5netcdf") as ds:
        assert ds["H_imag"].dims == ("frequency", "point", "actuator")
        assert list(ds["point"].values[[0, 8, 9]]) == ["1", "9", "G1"]
        assert ds["point_x"].attrs["units"] == "m" and ds["frequency"].attrs["units"] == "Hz"
        assert json.loads(ds.attrs["sweep"])["kind"] == "exponential"
        assert int(ds.attrs["schema_version"]) == SCHEMA_VERSION


def test_quality_issues_survive_the_round_trip(layout, firs, tmp_path):
    from vibrofocus.calibration import calibrate

    from .firrig import FIRRig

    h = firs.copy()
    h[:, 3] *= -1
    cal = calibrate(FIRRig(h, layout), participant_id="P", method="h1", sweep_s=0.5, repeats=2)
    back = load_calibration(save_calibration(cal, tmp_path / "rev.nc"))
    assert [i.check for i in back.quality.issues] == ["reversed_actuator"]
    assert back.quality.issues[0].actuator == 3


def test_missing_file(tmp_path):
    with pytest.raises(CalibrationFileError, match="no such calibration file"):
        load_calibration(tmp_path / "nope.nc")


def test_truncated_file(saved, tmp_path):
    data = saved.read_bytes()
    bad = tmp_path / "truncated.nc"
    bad.write_bytes(data[: len(data) // 3])
    with pytest.raises(CalibrationFileError, match="truncated.nc: is truncated or corrupt"):
        load_calibration(bad)


@pytest.mark.parametrize("content, what", [(b"participant,study\n1,2\n", "starts with"), (b"", "empty")])
def test_foreign_non_hdf5_file(tmp_path, content, what):
    bad = tmp_path / "trials.csv"
    bad.write_bytes(content)
    with pytest.raises(CalibrationFileError, match=f"trials.csv: is not a netCDF4/HDF5 calibration file.*{what}"):
        load_calibration(bad)


def test_foreign_netcdf_file(tmp_path):
    other = tmp_path / "weather.nc"
    xr.Dataset({"t": ("x", np.arange(3.0))}, attrs={"title": "temperatures"}).to_netcdf(other, engine="h5netcdf")
    with pytest.raises(CalibrationFileError, match="weather.nc: is an HDF5/netCDF file but not a vibrofocus"):
        load_calibration(other)


@pytest.mark.parametrize("version, match", [(SCHEMA_VERSION + 1, "newer than this vibrofocus reads"),
                                            (0, "no vibrofocus release wrote")])
def test_unknown_schema_version(saved, tmp_path, version, match):
    def edit(ds):
        ds.attrs["schema_version"] = np.int32(version)
        return ds

    bad = rewrite_netcdf(saved, tmp_path / "v.nc", edit)
    with pytest.raises(CalibrationFileError, match=f"schema version {version}.*{match}"):
        load_calibration(bad)


def test_nan_in_stored_matrix_is_named_with_its_location(saved, tmp_path):
    def edit(ds):
        ds["H_imag"][100, 4, 2] = np.nan
        return ds

    bad = rewrite_netcdf(saved, tmp_path / "nan.nc", edit)
    f = np.fft.rfftfreq(4096, 1e-4)[100]
    with pytest.raises(CalibrationFileError, match=rf"H_imag holds 1 NaN/Inf.*{f:g} Hz, point 5, actuator A3"):
        load_calibration(bad)


def test_point_missing_from_the_data(saved, tmp_path):
    bad = rewrite_netcdf(saved, tmp_path / "missing.nc", lambda ds: ds.drop_sel(point="G2"))
    with pytest.raises(CalibrationFileError, match="point.s. G2 of the layout are missing from the data"):
        load_calibration(bad)


def test_point_moved(saved, tmp_path):
    def edit(ds):
        ds["point_x"][0] = ds["point_x"][0] + 1e-3
        return ds

    with pytest.raises(CalibrationFileError, match="point positions"):
        load_calibration(rewrite_netcdf(saved, tmp_path / "moved.nc", edit))


@pytest.mark.parametrize(
    "edit, match",
    [
        (lambda ds: ds.drop_vars("coherence"), "lacks the variable.s. coherence"),
        (lambda ds: ds.assign(H_real=ds["H_real"].transpose("point", "frequency", "actuator")),
         "H_real has dimensions"),
        (lambda ds: ds.isel(frequency=slice(0, -1)), "frequencies but n_fft=4096"),
        (lambda ds: ds.assign_attrs(band_high=6000.0), "invalid band"),
        (lambda ds: ds.assign_attrs(layout="{not json"), "unreadable description"),
        (lambda ds: ds.assign(coherence=ds["coherence"] * 2), r"outside \[0, 1\]"),
    ],
)
def test_inconsistent_contents_are_refused(saved, tmp_path, edit, match):
    with pytest.raises(CalibrationFileError, match=match):
        load_calibration(rewrite_netcdf(saved, tmp_path / "bad.nc", edit))


def test_save_into_a_missing_folder_is_refused(fir_calibration, tmp_path):
    from vibrofocus.errors import OutputError

    with pytest.raises(OutputError, match="does not exist"):
        save_calibration(fir_calibration[1], tmp_path / "no" / "P.nc")


def _set_attr(src, dst, name, value):
    """Copy the file and overwrite one global attribute in place with h5py."""
    import shutil

    shutil.copy(src, dst)
    with h5py.File(dst, "r+") as h5:
        h5.attrs[name] = value
    return dst


@pytest.mark.parametrize(
    "name, value, match",
    [
        ("fs", "ten kHz", "attribute fs"),
        ("n_fft", "many", "attribute n_fft"),
        ("band_low", "low", "attribute band_low"),
        ("band_high", np.array([1.0, 2.0]), "attribute band_high"),
        ("schema_version", 1.5, "schema_version"),
        ("rig", "[1, 2]", "attribute rig"),
        ("sweep", "[]", "unreadable description"),
    ],
)
def test_malformed_attributes_are_named_not_a_traceback(saved, tmp_path, name, value, match):
    bad = _set_attr(saved, tmp_path / "attr.nc", name, value)
    with pytest.raises(CalibrationFileError, match=match):
        load_calibration(bad)


def _data_offset(dset) -> int:
    # Contiguous data has one offset; chunked data (checksummed) starts at its first chunk.
    if dset.chunks is None:
        return int(dset.id.get_offset())
    return int(dset.id.get_chunk_info(0).byte_offset)


@pytest.mark.parametrize("variable", ["H_real", "H_imag", "coherence", "drive"])
def test_a_flipped_bit_in_stored_data_is_detected(saved, tmp_path, variable):
    # Flip the least significant bit of one float in the middle of the data: the value
    # stays finite and plausible, so only a checksum can tell the file is corrupt.
    with h5py.File(saved, "r") as h5:
        dset = h5[variable]
        offset = _data_offset(dset) + 8 * 1000
        assert dset.dtype == np.float64
    data = bytearray(saved.read_bytes())
    data[offset] ^= 0x01
    bad = tmp_path / "flipped.nc"
    bad.write_bytes(bytes(data))
    with pytest.raises(CalibrationFileError, match="corrupt"):
        load_calibration(bad)


def test_saved_arrays_carry_checksums(saved):
    with xr.open_dataset(saved, engine="h5netcdf") as ds:
        names = [name for name, var in ds.variables.items() if var.size > 1 and var.dtype.kind in "fiu"]
    with h5py.File(saved, "r") as h5:
        unchecked = [name for name in names if not h5[name].fletcher32]
    assert "H_real" in names and unchecked == []


def test_a_simulated_calibration_is_stored_in_steps_of_its_noise_and_half_the_size(simulated_calibration, tmp_path):
    # Issue 54, item 11: each simulated calibration took 16 MB, more than its float32
    # recordings alone (12 MB of noise that zlib hardly shrinks).
    from vibrofocus.io.calibration_nc import RECORDING_STEP_OF_NOISE

    cal = simulated_calibration[1]
    path = save_calibration(cal, tmp_path / "sim.nc")
    assert path.stat().st_size < 0.75 * cal.recordings.astype(np.float32).nbytes, path.stat().st_size
    back = load_calibration(path)
    for name in ("H", "coherence", "drives"):  # without loss: designs from the file are those from memory
        np.testing.assert_array_equal(getattr(back, name), getattr(cal, name), err_msg=name)
    step = np.nanmin(cal.quality.noise_rms_m) * RECORDING_STEP_OF_NOISE
    assert back.recordings.dtype == np.float32
    assert np.array_equal(np.isnan(back.recordings), np.isnan(cal.recordings)) and np.isnan(cal.recordings).any()
    error = np.nanmax(np.abs(back.recordings.astype(float) - cal.recordings))
    assert error <= 0.5 * step + 1e-6 * np.nanmax(np.abs(cal.recordings)), (error, step)
    # A plain netCDF reader unpacks it alike (CF scale_factor and _FillValue).
    with xr.open_dataset(path, engine="h5netcdf") as ds:
        np.testing.assert_allclose(ds["recording"].values, back.recordings, rtol=1e-6, atol=1e-6 * step)


def test_a_calibration_file_with_float32_recordings_still_loads(simulated_calibration, tmp_path):
    # Files written before the packing hold float32 recordings (and uncompressed H).
    cal = simulated_calibration[1]
    packed = save_calibration(cal, tmp_path / "packed.nc")

    def as_before(ds):
        ds["recording"] = ds["recording"].astype(np.float32)
        for var in ds.variables.values():
            var.encoding = {}
        return ds

    old = rewrite_netcdf(packed, tmp_path / "old.nc", as_before)
    with h5py.File(old, "r") as h5:
        assert h5["recording"].dtype == np.float32 and h5["H_real"].compression is None
    np.testing.assert_array_equal(load_calibration(old).recordings, load_calibration(packed).recordings)
