import numpy as np
import pytest

from vibrofocus.calibration import default_settings, make_excitation
from vibrofocus.errors import ValidationError


def test_h1_sweep_covers_band_with_margin():
    s = default_settings("h1", 10_000.0, (10.0, 1000.0))
    assert s.kind == "exponential" and s.repeats == 8
    np.testing.assert_allclose([s.f_start, s.f_stop], [10 / np.sqrt(2), 1000 * np.sqrt(2)], rtol=1e-12)


def test_paper_sweep_is_one_linear_sweep_over_the_band():
    s = default_settings("paper", 10_000.0, (10.0, 1000.0))
    assert (s.kind, s.repeats, s.f_start, s.f_stop) == ("linear", 1, 10.0, 1000.0)


def test_excitation_starts_with_silence_then_holds_the_sweep_band():
    s = default_settings("h1", 10_000.0, (10.0, 1000.0), sweep_s=1.0, amplitude_v=3.0)
    x = make_excitation(s)
    assert x.shape == (s.n_drive,)
    assert np.all(x[: s.n_pre] == 0)
    assert np.abs(x).max() == pytest.approx(3.0, rel=1e-3)
    # The sweep's energy lies between its start and stop frequencies.
    spec = np.abs(np.fft.rfft(x)) ** 2
    f = np.fft.rfftfreq(x.size, 1e-4)
    inside = spec[(f >= s.f_start) & (f <= s.f_stop)].sum()
    assert inside / spec.sum() > 0.95
    # The start of a 1 s sweep at 7 Hz is only a few cycles, so some energy spills below.
    assert spec[f < s.f_start / 2].sum() / spec.sum() < 0.02
    assert spec[f > 2 * s.f_stop].sum() / spec.sum() < 1e-6


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"method": "mls"}, "method"),
        ({"repeats": 0}, "repeats"),
        ({"sweep_s": 0.1}, "too short"),
        ({"amplitude_v": -1.0}, "amplitude_v"),
        ({"band": (1000.0, 10.0)}, "band"),
    ],
)
def test_bad_settings_are_refused(kwargs, match):
    args = {"method": "h1", "fs": 10_000.0, "band": (10.0, 1000.0)}
    args.update(kwargs)
    with pytest.raises(ValidationError, match=match):
        default_settings(args.pop("method"), args.pop("fs"), args.pop("band"), **args)
