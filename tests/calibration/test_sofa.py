"""Calibrations as SOFA GeneralTF-E files: sofar writes and verifies them, pyfar reads them."""

from __future__ import annotations

import json

import numpy as np
import pytest

from vibrofocus.calibration import export_sofa, import_sofa
from vibrofocus.errors import CalibrationFileError, ValidationError

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


# --------------------------------------------------------------------------- hostile files
def _edited(sofa_file, tmp_path, name="hostile.sofa"):
    import shutil

    _, path = sofa_file
    edited = tmp_path / name
    shutil.copy2(path, edited)
    return edited


@pytest.mark.parametrize("attribute, text, words", [
    ("SampleRate", '"abc"', r"GLOBAL_vibrofocusSampleRate must be a number \(Hz\), got str"),
    ("SampleRate", '{"a": 1}', r"GLOBAL_vibrofocusSampleRate must be a number \(Hz\), got dict"),
    ("SampleRate", "NaN", r"GLOBAL_vibrofocusSampleRate must be > 0 and finite, got nan"),
    ("SampleRate", "-5", r"GLOBAL_vibrofocusSampleRate must be > 0 and finite, got -5"),
    ("SampleRate", "not json", r"GLOBAL_vibrofocusSampleRate is not JSON"),
    ("Band", "5", r"GLOBAL_vibrofocusBand must be a pair \[low_hz, high_hz\], got 5"),
    ("Band", "[100]", r"GLOBAL_vibrofocusBand must be a pair \[low_hz, high_hz\], got \[100\]"),
    ("Band", "[400, 50]", r"GLOBAL_vibrofocusBand must satisfy 0 < low < high <= fs/2 = 5000 Hz, got \(400, 50\)"),
    ("PointLabels", "5", r"GLOBAL_vibrofocusPointLabels must be a list of 13 texts \(one per point\), got 5"),
    ("PointLabels", '["1", "2"]', r"GLOBAL_vibrofocusPointLabels must name the 13 points, got 2"),
    ("PointKinds", json.dumps(["spot"] * 13), r"GLOBAL_vibrofocusPointKinds must be one of 'location', 'guard'"),
    ("ActuatorNames", "[1, 2, 3, 4]", r"GLOBAL_vibrofocusActuatorNames must be a list of 4 texts"),
    ("ParticipantID", "[]", r"GLOBAL_vibrofocusParticipantID must be a text, got list"),
    ("Layout", "[" * 100_000 + "]" * 100_000, r"GLOBAL_vibrofocusLayout is nested more than 16 levels deep"),
    ("Layout", "[" * 100 + "]" * 100, r"GLOBAL_vibrofocusLayout is nested more than 16 levels deep"),
    ("Layout", "[]", r"GLOBAL_vibrofocusLayout must be a JSON object, got list"),
    ("Layout", '"' + "x" * 1_000_001 + '"', r"GLOBAL_vibrofocusLayout is 1,000,003 characters long"),
])
def test_every_description_attribute_is_checked_and_named(sofa_file, tmp_path, attribute, text, words):
    """Raw ValueError/TypeError/RecursionError on main, or NaN, -5 Hz, [100] and [400, 50] accepted."""
    import h5py

    edited = _edited(sofa_file, tmp_path)
    with h5py.File(edited, "r+") as f:  # netCDF global attribute GLOBAL_X is the HDF5 attribute X
        f.attrs[f"vibrofocus{attribute}"] = text
    with pytest.raises(CalibrationFileError, match="hostile.sofa: attribute " + words):
        import_sofa(edited)


def test_a_file_declaring_unwritten_arrays_is_refused_before_reading(sofa_file, tmp_path):
    """A 1.2 MB file declaring 2 x 10 GB of never-written data: 21 GB RSS and the OOM killer on main."""
    import h5py

    edited = _edited(sofa_file, tmp_path)
    with h5py.File(edited, "r+") as f:
        _, n_r, _, n_e = f["Data.Real"].shape
        del f["Data.Real"]
        f.create_dataset("Data.Real", shape=(1, n_r, 25_000_000, n_e), dtype="f8", chunks=(1, n_r, 1000, n_e))
    declared = n_r * 25_000_000 * n_e * 8
    with pytest.raises(CalibrationFileError, match=rf"variable Data.Real declares shape \(1, {n_r}, 25000000, "
                                                   rf"{n_e}\) \({declared:,} bytes\) but the file holds 0 bytes"):
        import_sofa(edited)


def test_compressed_filler_above_the_cap_is_refused_before_reading(sofa_file, tmp_path):
    """Zeros deflate a thousandfold: a file of under 1 MB declaring 580 MB of data (3.5 GB RSS on main
    for a 3.7 MB one)."""
    import zlib

    import h5py

    edited = _edited(sofa_file, tmp_path)
    chunk_n = 10_000
    with h5py.File(edited, "r+") as f:
        _, n_r, _, n_e = f["Data.Real"].shape
        zeros = zlib.compress(bytes(n_r * chunk_n * n_e * 8), 9)  # one compressed chunk, written 70 times
        for name in ("Data.Real", "Data.Imag"):
            del f[name]
            data = f.create_dataset(name, shape=(1, n_r, 70 * chunk_n, n_e), dtype="f8",
                                    chunks=(1, n_r, chunk_n, n_e), compression="gzip")
            for k in range(70):
                data.id.write_direct_chunk((0, 0, k * chunk_n, 0), zeros)
    size = edited.stat().st_size
    assert size < 2**20
    with pytest.raises(CalibrationFileError, match=rf"declare [\d,]+ bytes in all, more than a SOFA file of "
                                                   rf"{size:,} bytes may \(268,435,456 bytes"):
        import_sofa(edited)


def test_a_file_of_another_tool_without_descriptions_still_reads(sofa_file, tmp_path):
    import h5py

    cal, _ = sofa_file
    edited = _edited(sofa_file, tmp_path)
    with h5py.File(edited, "r+") as f:
        for name in [a for a in f.attrs if a.startswith("vibrofocus")]:
            del f.attrs[name]
    back = import_sofa(edited)
    assert back["layout"] is None and back["fs"] == 2 * cal.freqs[-1]
    assert back["band"] == (cal.freqs[0], cal.freqs[-1])


# --------------------------------------------------------------------------- units, dates, band, CLI
def _sofar_verify_for_writing(path):
    """sofar's strictest check: the convention as for writing a file (units in lower case and all)."""
    sofa = sofar.read_sofa(str(path), verify=True, verbose=False)
    sofa.verify(issue_handling="raise", mode="write")
    return sofa


def test_units_date_and_authorship_are_in_the_file(sofa_file, tmp_path):
    from datetime import datetime

    cal, _ = sofa_file
    path = export_sofa(cal, tmp_path / "who.sofa", author_contact="Ada Lovelace <ada@example.org>",
                       organization="Example Lab", license="CC-BY-4.0")
    sofa = _sofar_verify_for_writing(path)
    assert (sofa.Data_Real_Units, sofa.Data_Imag_Units) == ("metre/volt", "metre/volt")
    assert (sofa.N_Units, sofa.ReceiverPosition_Units, sofa.EmitterPosition_Units) == ("hertz", "metre", "metre")
    created = datetime.fromisoformat(cal.created)
    assert sofa.GLOBAL_DateCreated == created.strftime("%Y-%m-%d %H:%M:%S")  # the calibration's, not the export's
    assert sofa.GLOBAL_AuthorContact == "Ada Lovelace <ada@example.org>"
    assert (sofa.GLOBAL_Organization, sofa.GLOBAL_License) == ("Example Lab", "CC-BY-4.0")
    assert not hasattr(sofa, "Coherence")
    with pytest.raises(ValidationError, match="organization must be a text without control characters"):
        export_sofa(cal, tmp_path / "bad.sofa", organization="Lab\nname")
    assert not (tmp_path / "bad.sofa").exists()


def test_the_band_option_keeps_the_calibrated_band_with_its_coherence(sofa_file, tmp_path):
    cal, _ = sofa_file
    path = export_sofa(cal, tmp_path / "band.sofa", band_only=True)
    sofa = _sofar_verify_for_writing(path)
    inside = (cal.freqs >= cal.band[0]) & (cal.freqs <= cal.band[1])
    assert 2 <= inside.sum() < len(cal.freqs)
    np.testing.assert_array_equal(sofa.N, cal.freqs[inside])
    assert sofa.Coherence.shape == sofa.Data_Real.shape == (1, cal.layout.n_points, inside.sum(),
                                                            cal.layout.n_actuators)
    assert sofa.Coherence_Units == "1"
    back = import_sofa(path)
    assert np.max(np.abs(back["H"] - cal.H[inside])) <= 1e-12 * np.max(np.abs(cal.H))
    np.testing.assert_allclose(back["coherence"], cal.coherence[inside], rtol=0, atol=1e-15)
    assert tuple(back["band"]) == tuple(cal.band) and back["layout"] == cal.layout
    data, _, _ = pyfar.io.convert_sofa(sofar.read_sofa(str(path), verbose=False))
    np.testing.assert_allclose(data.frequencies, cal.freqs[inside], rtol=0, atol=1e-12)


def test_the_export_command_writes_a_sofa_file_from_a_calibration(fir_calibration_file, tmp_path):
    import shutil

    from typer.testing import CliRunner

    from vibrofocus.cli.main import app

    nc = tmp_path / "FIR.nc"
    shutil.copy(fir_calibration_file, nc)  # the fir calibration's file, saved once
    runner = CliRunner()
    out = tmp_path / "FIR.sofa"
    result = runner.invoke(app, ["export", str(nc), "--sofa", str(out), "--band-only", "--author", "Ada Lovelace",
                                 "--institution", "Example Lab", "--license", "CC0"])
    assert result.exit_code == 0, result.output
    assert "calibrated band" in result.output
    sofa = _sofar_verify_for_writing(out)
    assert (sofa.GLOBAL_AuthorContact, sofa.GLOBAL_Organization, sofa.GLOBAL_License) == (
        "Ada Lovelace", "Example Lab", "CC0")
    assert hasattr(sofa, "Coherence")
    sofa_out = ["--sofa", str(tmp_path / "x.sofa")]
    for args, words in (([*sofa_out, "--bids", str(tmp_path / "b")], "give one of --bids"),
                        ([], "give one of --bids"),
                        ([*sofa_out, "--metadata", str(nc)], "--metadata is a BIDS template")):
        result = runner.invoke(app, ["export", str(nc), *args])
        assert result.exit_code == 2 and result.output.count("error:") == 1 and words in result.output, result.output
    # The calibration itself is never the output.
    before = nc.read_bytes()
    result = runner.invoke(app, ["export", str(nc), "--sofa", str(nc)])
    assert result.exit_code == 2 and nc.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["FIR.nc", "FIR.sofa"]
