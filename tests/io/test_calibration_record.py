"""The calibration record (io.calibration_record): typed, frozen, checked in one place."""

import dataclasses
import hashlib

import numpy as np
import pytest

from vibrofocus.errors import CalibrationFileError, ValidationError
from vibrofocus.io import CalibrationFileRecord, read_calibration_file, write_calibration_file
from vibrofocus.io.calibration_nc import RECORD_KEYS
from vibrofocus.io.calibration_record import FitRecord, QualityRecord

N_FFT, FS, P, A = 16, 1000.0, 2, 1


def _parts(**changes):
    """The fields of a small valid h1 record (2 points, 1 actuator, 9 frequencies), with changes."""
    rng = np.random.default_rng(20261202)
    n_f = N_FFT // 2 + 1
    pa = np.zeros((P, A))
    quality = dict(issues=[], thresholds={}, snr_db=pa + 40.0, noise_rms_m=pa + 1e-9, band_gain=pa + 1e-6,
                   low_coherence_share=pa, coherent_to_hz=pa + 400.0, clipped=pa.astype(bool),
                   repeats_used=pa.astype(int) + 2, dropouts=pa.astype(int), polarity=np.ones(A, int))
    parts = dict(
        H=1e-6 * (rng.standard_normal((n_f, P, A)) + 1j * rng.standard_normal((n_f, P, A))),
        freqs=np.fft.rfftfreq(N_FFT, 1 / FS), coherence=np.full((n_f, P, A), 0.9),
        drives=rng.standard_normal((A, N_FFT)), recordings=rng.standard_normal((A, 2, P, N_FFT)),
        fs=FS, band=(50.0, 400.0), n_fft=N_FFT, method="h1", participant_id="P01",
        created="2026-01-01T00:00:00+00:00", software_version="0", schema_version=2, layout={},
        point_labels=["1", "G1"], point_kinds=["location", "guard"], actuator_names=["A1"],
        points_xy=np.array([[0.0, 0.0], [0.01, 0.0]]), actuators_xy=np.array([[0.0, 0.01]]),
        rig={"kind": "test"}, sweep={}, quality=quality)
    return parts | changes


def test_the_record_is_typed_frozen_and_keeps_the_dict_keys():
    rec = CalibrationFileRecord(**_parts())
    assert isinstance(rec.quality, QualityRecord) and rec.fit is None and np.isnan(rec.recorded_s)
    assert RECORD_KEYS == tuple(f.name for f in dataclasses.fields(CalibrationFileRecord))
    assert len(RECORD_KEYS) == 28
    with pytest.raises(dataclasses.FrozenInstanceError):
        rec.fs = 2000.0


@pytest.mark.parametrize("changes, match", [
    ({"band": (400.0, 50.0)}, "invalid band 400-50 Hz"),
    ({"fs": -1.0}, "invalid sample rate"),
    ({"n_fft": 32}, "9 frequencies but n_fft=32 needs 17"),
    ({"freqs": np.arange(9.0)}, r"not rfftfreq\(16"),
    ({"coherence": np.full((9, P, A), 1.5)}, r"coherence holds values outside \[0, 1\]"),
    ({"point_labels": ["1"]}, r"point_labels must have shape \(2,\)"),
    ({"recordings": np.zeros((A, 2, P, 4))}, "recordings are shorter than the drives"),
    ({"method": "magic"}, "method must be one of h1, paper, mimo"),
    ({"method": "mimo", "recordings": np.zeros((2, P, N_FFT))}, "a mimo calibration needs codes"),
    ({"measured": np.array([True, False])}, "no fitted skin model"),
])
def test_inconsistent_parts_are_refused_when_made(changes, match):
    with pytest.raises(ValidationError, match=match):
        CalibrationFileRecord(**_parts(**changes))


def test_a_plain_dict_is_made_a_record_and_an_unknown_key_is_named():
    rec = CalibrationFileRecord.from_mapping(_parts())
    assert rec.quality.snr_db.shape == (P, A)
    with pytest.raises(ValidationError, match="unknown calibration record key.s. wobble; valid: H, freqs"):
        CalibrationFileRecord.from_mapping(_parts(wobble=1))
    with pytest.raises(ValidationError, match="lacks the key.s. sweep"):
        CalibrationFileRecord.from_mapping({k: v for k, v in _parts().items() if k != "sweep"})


def test_the_file_of_a_record_and_of_its_dict_are_the_same_bytes(tmp_path):
    a = write_calibration_file(CalibrationFileRecord(**_parts()), tmp_path / "a.nc")
    b = write_calibration_file(_parts(), tmp_path / "b.nc")
    assert hashlib.sha256(a.read_bytes()).digest() == hashlib.sha256(b.read_bytes()).digest()
    back = read_calibration_file(a)
    assert isinstance(back, CalibrationFileRecord)
    np.testing.assert_array_equal(back.H, _parts()["H"])
    assert back.band == (50.0, 400.0) and back.n_fft == N_FFT and back.measured.all()


def test_the_reader_names_the_file_for_what_the_record_refuses(tmp_path):
    import h5py

    path = write_calibration_file(_parts(), tmp_path / "bad.nc")
    with h5py.File(path, "r+") as h5:
        h5.attrs["band_high"] = 600.0
    with pytest.raises(CalibrationFileError, match=r"bad.nc: invalid band 50-600 Hz .* fs/2 = 500 Hz"):
        read_calibration_file(path)


def test_a_fit_record_checks_its_shapes():
    fit = dict(names=["a", "b"], values=np.ones(2), std=None, log_covariance=np.eye(2), residual=np.zeros(P),
               band=(50, 400), fs=FS, fixed={}, info={})
    assert FitRecord(**fit).names == ("a", "b")
    with pytest.raises(ValidationError, match=r"fit log_covariance must have shape \(2, 2\)"):
        FitRecord(**fit | {"log_covariance": np.eye(3)})
    with pytest.raises(ValidationError, match=r"fit residual must have shape \(2,\)"):
        CalibrationFileRecord(**_parts(fit=fit | {"residual": np.zeros(3)}))
