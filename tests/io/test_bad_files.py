"""Readers against files that lie: npy headers checked before any data is read, implausible H refused."""

from __future__ import annotations

import contextlib
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
    from vibrofocus.rigs import SimulatedForearm

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


# --------------------------------------------------------------------------- data from outside the file
def _recreate(f, name, make):
    """Replace dataset ``name`` by ``make(shape, dtype, data)``, keeping its attributes and dimensions."""
    old = f[name]
    data, attrs = old[()], {k: v for k, v in old.attrs.items() if k not in ("DIMENSION_LIST", "REFERENCE_LIST")}
    dims = [[scale.name for scale in dim.values()] for dim in old.dims]
    del f[name]
    new = make(data.shape, data.dtype, data)
    if new is None:  # a link: nothing to attach
        return
    for key, value in attrs.items():
        new.attrs[key] = value
    for i, names in enumerate(dims):
        for scale in names:
            new.dims[i].attach_scale(f[scale])


@pytest.mark.parametrize("kind, words", [
    ("fifo", r"point_measured keeps its data outside the file \(HDF5 external storage in .*pipe\)"),
    ("dev_zero", r"point_measured keeps its data outside the file \(HDF5 external storage in /dev/zero\)"),
    ("other_file", r"point_measured keeps its data outside the file \(HDF5 external storage in .*secret.bin\)"),
    ("virtual", r"point_measured is an HDF5 virtual dataset \(its data come from other files\)"),
    ("external_link", r"point_measured is an HDF5 external link \(to '/x' in the file '.*other.h5'\)"),
    ("soft_link", r"point_measured is an HDF5 soft link \(to '/point_kind'\)"),
])
def test_data_from_outside_the_file_is_refused_before_anything_is_read(tmp_path, calibration_file, kind, words):
    """Issue 53 item 7: external storage on a FIFO blocked for ever in HDF5's open of it (a C call Ctrl-C
    cannot stop), /dev/zero or any readable file became the flags, a virtual dataset or a link read another
    file's data. Each is refused from the header, and the FIFO is never opened."""
    import os
    import threading

    import h5py

    from vibrofocus.calibration import load_calibration

    edited = tmp_path / "edited.nc"
    shutil.copy2(calibration_file, edited)
    fifo, other, secret = tmp_path / "pipe", tmp_path / "other.h5", tmp_path / "secret.bin"
    os.mkfifo(fifo)
    opened, stop = [], threading.Event()

    def feed() -> None:  # a writer that connects only if the reader opens the FIFO; then it gives zeros
        while not stop.is_set():
            try:
                fd = os.open(fifo, os.O_WRONLY | os.O_NONBLOCK)
            except OSError:  # ENXIO: no reader yet
                stop.wait(0.01)
                continue
            opened.append(True)
            with contextlib.suppress(OSError):
                os.set_blocking(fd, True)
                os.write(fd, bytes(1 << 16))
            os.close(fd)
            return

    def make(shape, dtype, data):
        n = data.nbytes
        if kind == "fifo":
            return f.create_dataset("point_measured", shape, dtype, external=[(str(fifo), 0, n)])
        if kind == "dev_zero":
            return f.create_dataset("point_measured", shape, dtype, external=[("/dev/zero", 0, n)])
        if kind == "other_file":
            secret.write_bytes(np.ones(shape, dtype).tobytes())
            return f.create_dataset("point_measured", shape, dtype, external=[(str(secret), 0, n)])
        with h5py.File(other, "w") as g:
            g["x"] = data
        if kind == "virtual":
            layout = h5py.VirtualLayout(shape, dtype)
            layout[...] = h5py.VirtualSource(str(other), "x", shape)
            return f.create_virtual_dataset("point_measured", layout)
        f["point_measured"] = h5py.ExternalLink(str(other), "/x") if kind == "external_link" else \
            h5py.SoftLink("/point_kind")
        return None

    with h5py.File(edited, "r+") as f:
        assert "point_measured" in f
        _recreate(f, "point_measured", make)
    feeder = threading.Thread(target=feed, daemon=True)
    feeder.start()
    try:
        with pytest.raises(CalibrationFileError, match=rf"edited.nc: {words}; a calibration file must hold its "
                                                       "own data, so it was refused before reading"):
            load_calibration(edited)
    finally:
        stop.set()
        feeder.join(5)
    assert opened == []


def test_a_link_or_outside_storage_deep_in_a_group_is_refused(tmp_path):
    """The walk covers every group (SOFA and netCDF files may have them) and survives a loop of hard links."""
    import h5py

    from vibrofocus.io._headers import check_hdf5_sizes

    path = tmp_path / "deep.h5"
    with h5py.File(path, "w") as f:
        inner = f.create_group("a/b")
        inner["loop"] = f["a"]  # a hard link back up: visited once
        f["ok"] = np.zeros(3)
    assert check_hdf5_sizes(path, "a SOFA file")[0] == {"ok": (3,)}
    with h5py.File(path, "r+") as f:
        f["a/b"].create_dataset("v", (4,), "f8", external=[("/dev/zero", 0, 32)])
    with pytest.raises(ValidationError, match=r"a/b/v keeps its data outside the file .*; a SOFA file must hold"):
        check_hdf5_sizes(path, "a SOFA file")
