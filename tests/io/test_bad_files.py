"""Readers against files that lie: npy headers checked before any data is read, implausible H refused."""

from __future__ import annotations

import io
import shutil
import zipfile

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from vibrofocus.errors import CalibrationFileError, ValidationError
from vibrofocus.io import read_drives

FS = 10_000.0


def _npy_header(shape: tuple[int, ...], descr: str = "<f8") -> bytes:
    b = io.BytesIO()
    np.lib.format.write_array_header_1_0(b, {"descr": descr, "fortran_order": False, "shape": shape})
    return b.getvalue()


def _npz(path, drives_bytes: bytes, fs=FS, compression=zipfile.ZIP_STORED):
    fs_npy = io.BytesIO()
    np.save(fs_npy, np.float64(fs))
    with zipfile.ZipFile(path, "w", compression=compression) as z:
        z.writestr("drives.npy", drives_bytes)
        z.writestr("fs.npy", fs_npy.getvalue())
    return path


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(n_act=st.integers(1, 10**6), n=st.integers(1, 10**12), held=st.integers(0, 4096),
       compressed=st.booleans())
def test_a_header_claiming_other_than_the_data_is_refused_before_reading(tmp_path_factory, n_act, n, held,
                                                                         compressed):
    claimed = n_act * n * 8
    if claimed == held:  # an honest header: covered below
        return
    path = tmp_path_factory.mktemp("lie") / "d.npz"
    _npz(path, _npy_header((n_act, n)) + bytes(held),
         compression=zipfile.ZIP_DEFLATED if compressed else zipfile.ZIP_STORED)
    with pytest.raises(ValidationError, match=r"claims shape .* but the file holds"):
        read_drives(path)


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(n_act=st.integers(1, 6), n=st.integers(1, 2000), seed=st.integers(0, 2**32 - 1))
def test_an_honest_file_reads_back_exactly(tmp_path_factory, n_act, n, seed):
    drives = np.random.default_rng(seed).uniform(-5, 5, (n_act, n))
    path = tmp_path_factory.mktemp("ok") / "d.npz"
    np.savez_compressed(path, drives=drives, fs=np.float64(FS))
    got, fs = read_drives(path, max_duration_s=1.0)
    np.testing.assert_array_equal(got, drives)
    assert fs == FS


def test_the_duration_is_checked_from_the_header(tmp_path):
    n = 40_001  # 4.0001 s at 10 kHz
    path = _npz(tmp_path / "d.npz", _npy_header((2, n)) + bytes(2 * n * 8), compression=zipfile.ZIP_DEFLATED)
    with pytest.raises(ValidationError, match=r"4\.0001 s, longer than the rig's limit of 4 s"):
        read_drives(path, max_duration_s=4.0)
    assert read_drives(path, max_duration_s=5.0)[0].shape == (2, n)


@pytest.mark.parametrize("make, words", [
    (lambda p: p.mkdir(), "it is a folder"),
    (lambda p: _npz(p, _npy_header((2, 3), "|O") + bytes(48)), "not a readable .npz"),
    (lambda p: _npz(p, _npy_header((2, 3), "|b1") + bytes(6)), "dtype bool"),
])
def test_folders_objects_and_booleans_are_named(tmp_path, make, words):
    path = tmp_path / "d.npz"
    make(path)
    with pytest.raises(ValidationError, match=words):
        read_drives(path)


# --------------------------------------------------------------------------- calibration plausibility
@pytest.fixture(scope="module")
def calibration_file(tmp_path_factory):
    from vibrofocus.calibration import calibrate, save_calibration
    from vibrofocus.skin import SimulatedForearm

    cal = calibrate(SimulatedForearm(seed=3), participant_id="P03", repeats=4, sweep_s=1.0)
    return save_calibration(cal, tmp_path_factory.mktemp("cal") / "P03.nc")


@pytest.mark.parametrize("factor, words", [(1e8, "above 0.001 m/V"), (1e-8, "no actuator moved the skin")])
def test_a_scaled_transfer_matrix_is_refused_and_the_original_loads(tmp_path, calibration_file, factor, words):
    import h5py

    from vibrofocus.calibration import load_calibration
    from vibrofocus.defaults import H_MAX_M_PER_V, H_MIN_PEAK_M_PER_V

    original = load_calibration(calibration_file)
    peak = np.abs(original.H).max()
    # The bounds are far from a real measurement on both sides.
    assert H_MIN_PEAK_M_PER_V * 1e3 < peak < H_MAX_M_PER_V / 1e3
    edited = tmp_path / "edited.nc"
    shutil.copy2(calibration_file, edited)
    with h5py.File(edited, "r+") as f:
        for name in ("H_real", "H_imag"):
            f[name][...] = f[name][...] * factor
    with pytest.raises(CalibrationFileError, match=words):
        load_calibration(edited)


def test_one_implausible_value_is_named_with_its_place(tmp_path, calibration_file):
    import h5py

    from vibrofocus.calibration import load_calibration

    edited = tmp_path / "one.nc"
    shutil.copy2(calibration_file, edited)
    with h5py.File(edited, "r+") as f:
        freqs = f["frequency"][...]
        f["H_imag"][57, 10, 3] = -2e-3
    with pytest.raises(CalibrationFileError, match=rf"0.002 m/V at {freqs[57]:g} Hz, point G2, actuator A4 "
                                                   r"\(1 value\(s\)"):
        load_calibration(edited)


# --------------------------------------------------------------------------- declared but unwritten variables
def _attach(f, dataset, dims):
    for i, dim in enumerate(dims):
        dataset.dims[i].attach_scale(f[dim])


@pytest.mark.parametrize("kind", ["hdf5_extra", "hdf5_extra_5e9", "netcdf_extra"])
def test_an_extra_unwritten_variable_is_never_read(tmp_path, calibration_file, kind):
    """738 bytes of header declared GBs that ``ds.load()`` read (2.1 GB RSS, or 37 GiB asked)."""
    import h5netcdf
    import h5py

    from vibrofocus.calibration import load_calibration

    edited = tmp_path / "extra.nc"
    shutil.copy2(calibration_file, edited)
    if kind == "netcdf_extra":  # a well-formed netCDF variable: ignored, the calibration loads
        with h5netcdf.File(edited, "a") as f:
            f.dimensions["extra_dim"] = 5_000_000_000
            f.create_variable("extra", ("extra_dim",), "f8", chunks=(1_000_000,))  # 37 GiB once read
        cal = load_calibration(edited)
        np.testing.assert_array_equal(cal.H, load_calibration(calibration_file).H)
        return
    with h5py.File(edited, "r+") as f:  # plain HDF5: no netCDF dimensions, so the reader invents some
        if kind == "hdf5_extra":
            f.create_dataset("extra", shape=(2049, 13, 4, 2500), dtype="f8")
        else:
            f.create_dataset("extra", shape=(5_000_000_000,), dtype="f8", chunks=(1_000_000,))
    with pytest.raises(CalibrationFileError, match=r"extra.nc: variable frequency reads as shape .* but its HDF5 "
                                                   r"header declares \(2049,\).* datasets this schema does not "
                                                   r"name: extra"):
        load_calibration(edited)


@pytest.mark.parametrize("compressed_zeros", [False, True])
def test_a_known_variable_declared_larger_than_the_file_is_refused_before_reading(tmp_path, calibration_file,
                                                                                  compressed_zeros):
    """The recording declared 300 times longer: unwritten (reads as fill values), or written as zeros
    that deflate a thousandfold; either way GBs from a few MB of file."""
    import h5py

    from vibrofocus.calibration import load_calibration

    edited = tmp_path / "long.nc"
    shutil.copy2(calibration_file, edited)
    with h5py.File(edited, "r+") as f:
        take, point, n = f["recording"].shape
        n *= 300
        del f["recording"], f["record_sample"]
        scale = f.create_dataset("record_sample", shape=(n,), dtype="f4")
        scale.make_scale("This is a netCDF dimension but not a netCDF variable.%10d" % n)
        rec = f.create_dataset("recording", shape=(take, point, n), dtype="f4", chunks=(1, 1, n // 300),
                               compression="gzip")
        if compressed_zeros:
            rec[...] = 0.0
        _attach(f, rec, ("take", "point", "record_sample"))
    declared = take * point * n * 4
    words = (rf"more than a calibration file of {edited.stat().st_size:,} bytes may" if compressed_zeros else
             rf"variable recording declares shape \({take}, {point}, {n}\) \({declared:,} bytes\) but the file holds 0 "
             "compressed bytes of it")
    with pytest.raises(CalibrationFileError, match=words):
        load_calibration(edited)
