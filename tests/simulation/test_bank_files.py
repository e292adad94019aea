"""Feature-bank files that lie: every array checked on load, headers before any data (issue 38)."""

from __future__ import annotations

import io
import zipfile

import numpy as np
import pytest

from vibrofocus.errors import ValidationError
from vibrofocus.simulation.bank import DEFAULT_BANK, FeatureBank


@pytest.fixture(scope="module")
def arrays():
    from importlib import resources

    with resources.as_file(resources.files("vibrofocus.simulation").joinpath(DEFAULT_BANK)) as path:
        return dict(np.load(path))


def _edit(arrays, **changes):
    out = {k: np.array(v, copy=True) for k, v in arrays.items()}
    for key, edit in changes.items():
        out[key] = edit(out[key])
    return out


def _nan_at_start(a):
    a.flat[0] = np.nan
    return a


def _inf_somewhere(a):
    a[1, 2, 3, 4] = np.inf
    return a


CASES = {
    "all NaN energies": (dict(energy=lambda e: np.full_like(e, np.nan)), r"energy contains 130680 non-finite"),
    "an Inf energy": (dict(energy=_inf_somewhere), r"energy contains 1 non-finite value\(s\) .* \(1, 2, 3, 4\)"),
    "negative energies": (dict(energy=lambda e: -e), r"energy must be >= 0; it holds 130680 negative"),
    "negative actuator energy": (dict(actuator_energy=lambda e: e - 1.0), r"actuator_energy must be >= 0"),
    "duplicate methods": (dict(methods=lambda m: np.array(["funneling", "funneling", "inverse"])),
                          r"methods must be 3 distinct names"),
    "unregistered method": (dict(methods=lambda m: np.array(["funneling", "inverse", "magic"])),
                            r"method\(s\) 'magic' are not registered \(registered: funneling, inverse"),
    "NaN positions": (dict(points_xy=_nan_at_start), r"points_xy contains 1 non-finite value\(s\)"),
    "mismatched shape": (dict(energy=lambda e: e[..., :100]), r"points_xy must have shape \(100, 2\), got \(121, 2\)"),
    "zero forearms": (dict(energy=lambda e: e[:0], actuator_energy=lambda e: e[:0], forearm_seeds=lambda s: s[:0]),
                      r"energy has shape \(0, 3, 9, 121\), no forearm"),
    "seeds of another bank": (dict(forearm_seeds=lambda s: s[:5]), r"forearm_seeds must have shape \(40,\)"),
    "text energies": (dict(energy=lambda e: e.astype(str)), r"energy has dtype <U\d+, expected numbers"),
}


@pytest.mark.parametrize("case", list(CASES))
def test_a_bank_that_lies_is_refused_by_name(arrays, tmp_path, case):
    """On main each of these loaded (and power printed a table) or ended as 'unexpected ... a bug'."""
    changes, words = CASES[case]
    path = tmp_path / "bank.npz"
    np.savez(path, **_edit(arrays, **changes))
    with pytest.raises(ValidationError, match=rf"feature bank {path}: {words}"):
        FeatureBank.load(path)


def test_the_shipped_bank_passes_its_own_checks(arrays, tmp_path):
    path = tmp_path / "bank.npz"
    np.savez_compressed(path, **arrays)
    bank = FeatureBank.load(path)
    np.testing.assert_array_equal(bank.energy, arrays["energy"].astype(float))
    assert bank.methods == ("funneling", "inverse", "combination") and bank.n_forearms == 40


def test_a_header_declaring_12_gib_is_refused_before_reading(arrays, tmp_path):
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    path = tmp_path / "bank.npz"
    head = io.BytesIO()
    np.lib.format.write_array_header_1_0(head, {"descr": "<f4", "fortran_order": False,
                                                "shape": (40, 3, 9, 121 * 24_600)})
    with zipfile.ZipFile(buf) as zin, zipfile.ZipFile(path, "w") as zout:
        for info in zin.infolist():
            data = zin.read(info)
            if info.filename == "energy.npy":
                data = head.getvalue() + data[len(head.getvalue()):]
            zout.writestr(info.filename, data)
    with pytest.raises(ValidationError, match=r"the header of energy.npy claims shape \(40, 3, 9, 2976600\) "
                                              r"\(12,858,912,000 bytes of float32\) but the file holds"):
        FeatureBank.load(path)


def test_compressed_filler_above_the_cap_is_refused_before_reading(arrays, tmp_path):
    """Zeros deflate a thousandfold: 300 MB of energies in a file of under 1 MB."""
    n_p = 2_800_000
    path = tmp_path / "bank.npz"
    np.savez_compressed(path, **_edit(arrays, energy=lambda e: np.zeros((1, 3, 9, n_p), np.float32),
                                      actuator_energy=lambda e: e[:1], forearm_seeds=lambda s: s[:1],
                                      points_xy=lambda p: np.zeros((n_p, 2))))
    assert path.stat().st_size < 2**20
    with pytest.raises(ValidationError, match=r"its arrays declare [\d,]+ bytes in all, more than a feature bank"):
        FeatureBank.load(path)
