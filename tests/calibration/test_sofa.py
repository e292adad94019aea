"""Calibrations as SOFA GeneralTF-E files: sofar writes and verifies them, pyfar reads them."""

from __future__ import annotations

import json

import numpy as np
import pytest

from vibrofocus.calibration import export_sofa, import_sofa
from vibrofocus.errors import CalibrationFileError

sofar = pytest.importorskip("sofar")
pyfar = pytest.importorskip("pyfar")


@pytest.fixture(scope="module")
def sofa_file(fir_calibration, tmp_path_factory):
    _, cal = fir_calibration
    return cal, export_sofa(cal, tmp_path_factory.mktemp("sofa") / "FIR.sofa")


def test_the_round_trip_keeps_the_transfer_matrix_and_the_layout(sofa_file):
    cal, path = sofa_file
    back = import_sofa(path)
    assert back["H"].shape == cal.H.shape == (len(cal.freqs), cal.layout.n_points, cal.layout.n_actuators)
    assert np.max(np.abs(back["H"] - cal.H)) <= 1e-12 * np.max(np.abs(cal.H))
    np.testing.assert_allclose(back["freqs"], cal.freqs, rtol=0, atol=1e-12)
    assert back["layout"] == cal.layout
    assert (back["fs"], tuple(back["band"]), back["participant_id"]) == (cal.fs, tuple(cal.band), "FIR")


def test_sofar_verifies_the_file_and_finds_receivers_and_emitters_with_positions(sofa_file):
    cal, path = sofa_file
    sofa = sofar.read_sofa(str(path), verify=True, verbose=False)
    sofa.verify(issue_handling="raise")  # raises on any error of the convention
    assert sofa.GLOBAL_SOFAConventions == "GeneralTF-E"
    assert sofa.Data_Real.shape == (1, cal.layout.n_points, len(cal.freqs), cal.layout.n_actuators)
    np.testing.assert_array_equal(sofa.ReceiverPosition[:, :2], cal.layout.points_xy)
    np.testing.assert_array_equal(sofa.EmitterPosition[:, :2], cal.layout.actuators_xy)
    assert json.loads(sofa.GLOBAL_vibrofocusPointLabels) == list(cal.layout.point_labels)


def test_pyfar_reads_the_same_transfer_functions(sofa_file):
    cal, path = sofa_file
    data, sources, receivers = pyfar.io.convert_sofa(sofar.read_sofa(str(path), verbose=False))
    assert isinstance(data, pyfar.FrequencyData)
    assert data.cshape == (cal.layout.n_actuators, 1, cal.layout.n_points)  # (E, M, R)
    np.testing.assert_allclose(data.frequencies, cal.freqs, rtol=0, atol=1e-12)
    # pyfar's (E, M, R, N) against H (N, R, E)
    assert np.max(np.abs(data.freq[:, 0].transpose(2, 1, 0) - cal.H)) <= 1e-12 * np.max(np.abs(cal.H))
    np.testing.assert_allclose(receivers.cartesian[:, :2], cal.layout.points_xy, atol=1e-12)


def test_a_sofa_file_of_another_convention_or_broken_is_refused_by_name(tmp_path):
    other = sofar.Sofa("GeneralTF")
    other.N = np.array([0.0, 100.0])
    other.Data_Real = np.zeros((1, 1, 2))
    other.Data_Imag = np.zeros((1, 1, 2))
    sofar.write_sofa(str(tmp_path / "other.sofa"), other)
    with pytest.raises(CalibrationFileError, match="other.sofa: is a SOFA GeneralTF file"):
        import_sofa(tmp_path / "other.sofa")
    (tmp_path / "junk.sofa").write_bytes(b"not a sofa file")
    with pytest.raises(CalibrationFileError, match="junk.sofa: is not a readable SOFA file"):
        import_sofa(tmp_path / "junk.sofa")
    with pytest.raises(CalibrationFileError, match="no such SOFA file"):
        import_sofa(tmp_path / "none.sofa")
