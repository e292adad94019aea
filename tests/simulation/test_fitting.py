"""vibrofocus.simulation.fitting on a tiny bank: the objective, the search, adopt, fit files."""

import dataclasses
import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from vibrofocus.errors import ValidationError
from vibrofocus.simulation import fitting
from vibrofocus.simulation.bank import default_bank
from vibrofocus.simulation.fitting import adoption
from vibrofocus.simulation.hypotheses import available_hypotheses, hypothesis_fits
from vibrofocus.simulation.paper import seed_statistics
from vibrofocus.simulation.perception import PerceptualModel

ROOT = Path(__file__).resolve().parents[2]
#: The tiny studies of these tests: 6 participants, 2 fit seeds, 2 held-out seeds.
N, FIT, HELD = 6, range(0, 2), range(2, 4)


@pytest.fixture(scope="module")
def tiny_bank():
    """The shipped bank's first 3 forearms."""
    b = default_bank()
    cut = {f.name: getattr(b, f.name)[:3] for f in dataclasses.fields(b)
           if isinstance(getattr(b, f.name), np.ndarray) and getattr(b, f.name).shape[:1] == (b.n_forearms,)}
    return dataclasses.replace(b, **cut)


@pytest.fixture(scope="module")
def tiny_stats(tiny_bank):
    return seed_statistics(None, FIT, n_participants=N, bank=tiny_bank)


def test_the_tiny_bank_keeps_three_forearms(tiny_bank):
    assert tiny_bank.n_forearms == 3 and tiny_bank.actuator_energy.shape[0] == 3


def test_a_weight_scales_exactly_its_own_term(tiny_stats):
    base = fitting.loss(tiny_stats)
    key, _, paper = next(t for t in fitting.targets() if t[0] == "s1_method_F")
    median = float(np.median([s[key] for s in tiny_stats]))
    term = math.log(max(median, 1e-3) / paper) ** 2
    np.testing.assert_allclose(fitting.loss(tiny_stats, {key: 3.0}) - base, 2.0 * term, rtol=1e-9, atol=1e-12)
    label = fitting.PATTERNS[0][0]
    share = np.mean([fitting.PATTERNS[0][1](s) for s in tiny_stats])
    np.testing.assert_allclose(fitting.loss(tiny_stats, {label: 0.0}) - base, -2.0 * (1 - share) ** 2, atol=1e-12)
    assert "loss" in fitting.residuals(tiny_stats).splitlines()[-1]


def test_weight_keys_are_the_statistics_and_the_findings():
    keys = fitting.weight_keys()
    assert keys[:len(fitting.targets())] == [k for k, _, _ in fitting.targets()]
    assert "s2_hit_n" in keys and all(label in keys for label, _ in fitting.PATTERNS)


def _search(tmp_path, tiny_bank, name, rng_seed, start=None, out=None):
    out = out or tmp_path / f"{name}-{rng_seed}.json"
    fitting.search(2, 2, out, start, rng_seed, {"s2_reduction": 8.0}, bank=tiny_bank, name=name,
                   fit_seeds=FIT, n_participants=N)
    return out


def test_search_writes_a_fit_that_read_fit_accepts_and_repeats_it(tmp_path, tiny_bank):
    lines = []
    a = _search(tmp_path, tiny_bank, "grid-peak", 7)
    b = fitting.search(2, 2, tmp_path / "again.json", None, 7, {"s2_reduction": 8.0}, bank=tiny_bank,
                       name="grid-peak", fit_seeds=FIT, n_participants=N, report=lines.append)
    assert a.read_bytes() == (tmp_path / "again.json").read_bytes()  # seeded: the same path
    fit = fitting.read_fit(a)
    assert fit["budget"] == {"n_eval": 2, "n_refine": 2, "rng_seed": 7, "within_ranges": True, "start": None}
    assert fit["fit_seeds"] == [0, 2] and fit["hypothesis"] == "grid-peak" and fit["bank_forearms"] == 3
    assert fitting.fit_model(fit) == b
    np.testing.assert_allclose(fit["loss"], fitting.loss(seed_statistics(b, FIT, n_participants=N, bank=tiny_bank,
                                                                          hypothesis="grid-peak"),
                                                         {"s2_reduction": 8.0}), rtol=1e-12)
    assert lines[0].startswith("start: loss") and lines[-1].startswith("best loss")
    # A second stage records the first's budget as its start.
    c = _search(tmp_path, tiny_bank, "grid-peak", 8, start=a)
    assert fitting.read_fit(c)["budget"]["start"] == fit["budget"]


def test_adopt_keeps_the_lowest_path_of_every_hypothesis_and_picks_the_default(tmp_path, tiny_bank):
    paths = [_search(tmp_path, tiny_bank, name, seed) for name in available_hypotheses() for seed in (1, 2)]
    out = tmp_path / "fits.json"
    doc = fitting.adopt(paths, ["grid-peak=9.9"], out=out, bank=tiny_bank, fit_seeds=FIT, held_out_seeds=HELD,
                        n_participants=N)
    assert json.loads(out.read_text()) == doc and out.read_text().endswith("}\n")
    assert list(doc["hypotheses"]) == list(available_hypotheses())
    assert doc["hypotheses"]["grid-peak"]["version"] == "9.9"
    for name, fit in doc["hypotheses"].items():
        assert len(fit["paths"]) == 2 and fit["loss_fit"] == min(p["loss_fit"] for p in fit["paths"])
        assert fit["held_out_seeds"] == [2, 4] and fit["bank_forearms"] == 3
        # Rounded to 3 digits, and only what differs from PerceptualModel()'s defaults.
        defaults = PerceptualModel().to_dict()
        for key, value in fit["model"].items():
            assert value != defaults[key]
            for v in np.ravel(value):
                assert v == float(f"{v:.3g}")
    held = {n: f["loss_held_out_search_weights"] for n, f in doc["hypotheses"].items()}
    assert doc["default"] == min(held, key=held.get)


# ------------------------------------------------------------------ issue 53, item 9
def _shipped_path_fit():
    return json.loads((ROOT / "scripts" / "fits" / "paths" / "grid-peak-2027-2028.json").read_text())


def _write(tmp_path, name, fit):
    path = tmp_path / name
    path.write_text(json.dumps(fit) if not isinstance(fit, str) else fit)
    return path


_DROP = object()


def _changed(**changes):
    """The shipped path's fit with ``a__b=value`` set (``_DROP``: removed)."""
    fit = _shipped_path_fit()
    for dotted, value in changes.items():
        *parents, last = dotted.split("__")
        where = fit
        for key in parents:
            where = where[key]
        if value is _DROP:
            del where[last]
        else:
            where[last] = value
    return fit


BAD_FITS = {
    "a string for a number": (_changed(model__grid_half_width_m="1; import os"), "grid_half_width_m: must be a finite"),
    "a JSON list": ([_shipped_path_fit()], "not a fit"),
    "no weights": (_changed(weights=_DROP), "missing 'weights'"),
    "an unknown model key": (_changed(model__no_such_parameter=1.0), "unknown perceptual model parameter"),
    "NaN": ('{"hypothesis": "grid-peak", "levels": "paper", "budget": {"n_eval": 0, "n_refine": 1, "rng_seed": 1, '
            '"start": null}, "weights": {}, "fit_seeds": [1000, 1064], "model": {"sl_ref_db": NaN}}',
            "sl_ref_db: must be a finite number"),
    "a boolean for a number": (_changed(model__bias_sd_m=True), "bias_sd_m: must be a finite number"),
    "a pair of one": (_changed(model__select_kappa=[0.5]), "select_kappa: must be a list of 2"),
    "an unknown hypothesis": (_changed(hypothesis="guess"), "hypothesis 'guess' is none of"),
    "no hypothesis": (_changed(hypothesis=None), "hypothesis None is none of"),
    "an unknown key": (_changed(comment="hi"), "unknown key(s) 'comment'"),
    "an unknown weight": (_changed(weights__typo=1.0), "unknown statistic 'typo'"),
    "a negative budget": (_changed(budget__n_refine=-1), "n_refine: must be a whole number"),
    "a budget loop too deep": (_changed(budget__start__start=json.loads(
        '{"n_eval": 0, "n_refine": 0, "rng_seed": 0, "start": ' * 60 + "null" + "}" * 60)), "more than 50 searches"),
    "seeds backwards": (_changed(fit_seeds=[1064, 1000]), "fit_seeds must be [first, stop]"),
    "not JSON": ("{'model': 1}", "not JSON"),
}


@pytest.fixture
def nothing_computed(monkeypatch):
    def no_work(*args, **kwargs):
        raise AssertionError("adopt simulated a study before refusing its input")

    monkeypatch.setattr(adoption, "seed_statistics", no_work)


@pytest.mark.parametrize("case", list(BAD_FITS))
def test_adopt_refuses_a_bad_fit_file_before_anything_is_computed_or_written(case, tmp_path, nothing_computed):
    fit, message = BAD_FITS[case]
    good = [ROOT / "scripts" / "fits" / "paths" / f"{name}-2031.json" for name in available_hypotheses()]
    bad = _write(tmp_path, "bad.json", fit)
    out = tmp_path / "fits.json"
    with pytest.raises(ValidationError, match="bad.json") as err:
        fitting.adopt(good[1:] + [bad], out=out)
    assert message in str(err.value) and "\n" not in str(err.value)
    assert not out.exists()


def test_adopt_refuses_a_set_that_leaves_out_a_hypothesis(tmp_path, nothing_computed):
    paths = [ROOT / "scripts" / "fits" / "paths" / f"{name}-2031.json" for name in available_hypotheses()]
    out = tmp_path / "fits.json"
    for left_out in range(len(paths)):
        with pytest.raises(ValidationError, match=f"no fit of the hypothesis\\(es\\) {available_hypotheses()[left_out]}"):
            fitting.adopt(paths[:left_out] + paths[left_out + 1:], out=out)
    with pytest.raises(ValidationError, match="no fit files"):
        fitting.adopt([], out=out)
    for bad in ("grid-peak", "guess=1", "grid-peak= "):
        with pytest.raises(ValidationError, match="version"):
            fitting.adopt(paths, [bad], out=out)
    assert not out.exists()


def test_the_script_says_one_line_and_leaves_the_shipped_fits_alone(tmp_path):
    shipped = fitting.FITS_FILE.read_bytes()
    bad = _write(tmp_path, "bad.json", BAD_FITS["a string for a number"][0])
    for args in ([str(bad)], [str(bad), "--out", str(tmp_path / "fits.json")]):
        res = subprocess.run([sys.executable, str(ROOT / "scripts" / "fit_participants.py"), "adopt", *args],
                             capture_output=True, text=True, timeout=300)
        assert res.returncode == 2, res.stderr
        assert res.stderr.startswith("error: ") and res.stderr.count("\n") == 1, res.stderr
        assert "grid_half_width_m: must be a finite number, not '1; import os'" in res.stderr
    assert fitting.FITS_FILE.read_bytes() == shipped and not (tmp_path / "fits.json").exists()


def test_every_shipped_fit_file_is_a_valid_fit():
    for path in sorted((ROOT / "scripts" / "fits").rglob("*.json")):
        if path.name.startswith("baseline-"):
            continue
        fit = fitting.read_fit(path)
        assert fitting.fit_model(fit).to_dict().keys() == PerceptualModel().to_dict().keys()
    assert set(hypothesis_fits()["hypotheses"]) == set(available_hypotheses())
