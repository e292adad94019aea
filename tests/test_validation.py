"""The validation helpers: each names the argument and says what was expected."""

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from vibrofocus._validation import (
    as_array,
    check_band,
    check_choice,
    check_finite,
    check_in_range,
    check_index,
    check_positive,
    check_shape,
)
from vibrofocus.errors import ValidationError, VibrofocusError


def test_validation_error_is_a_value_error_and_a_vibrofocus_error():
    assert issubclass(ValidationError, ValueError) and issubclass(ValidationError, VibrofocusError)


def test_as_array_conversions_and_refusals():
    out = as_array([1, 2, 3], "x")
    assert out.dtype == np.float64
    assert as_array([1.0, 2.0], "z", dtype="complex").dtype == np.complex128
    with pytest.raises(ValidationError, match="x must be real-valued"):
        as_array([1j], "x")
    with pytest.raises(ValidationError, match="x must be numeric"):
        as_array(["a"], "x")
    with pytest.raises(ValidationError, match="x must be array-like|x must be numeric"):
        as_array([[1, 2], [3]], "x")
    with pytest.raises(ValidationError, match=r"x must have 2 dimension\(s\), got 1 with shape \(3,\)"):
        as_array([1, 2, 3], "x", ndim=2)
    with pytest.raises(ValidationError, match=r"x must have shape \(any, 2\), got \(3, 3\)"):
        as_array(np.zeros((3, 3)), "x", shape=(None, 2))
    assert np.isnan(as_array([np.nan], "x", finite=False)[0])


def test_check_finite_reports_count_and_first_index():
    a = np.zeros((3, 4))
    a[1, 2] = np.inf
    a[2, 0] = np.nan
    with pytest.raises(ValidationError, match=r"a contains 2 non-finite value\(s\) \(NaN or Inf\); first at index \(1, 2\)"):
        check_finite(a, "a")


def test_scalars():
    assert check_positive(2, "fs") == 2.0
    assert check_positive(0, "gap", allow_zero=True) == 0.0
    for bad in (0, -1, np.nan, np.inf):
        with pytest.raises(ValidationError, match="fs must be > 0 and finite"):
            check_positive(bad, "fs")
    with pytest.raises(ValidationError, match="fs must be a number"):
        check_positive("fast", "fs")
    assert check_in_range(0.5, "p", 0, 1) == 0.5
    with pytest.raises(ValidationError, match=r"p must lie in \(0, 1\), got 1"):
        check_in_range(1, "p", 0, 1, inclusive=False)
    assert check_choice("a", "mode", ("a", "b")) == "a"
    with pytest.raises(ValidationError, match="mode must be one of 'a', 'b'; got 'c'"):
        check_choice("c", "mode", ("a", "b"))
    assert check_index(np.int64(2), "i", 3) == 2
    with pytest.raises(ValidationError, match=r"i=3 is outside the 3 points \(valid: 0..2\)"):
        check_index(3, "i", 3, what="points")
    with pytest.raises(ValidationError, match="i must be an integer index"):
        check_index(True, "i", 3)
    check_shape(np.zeros((2, 5)), "m", (2, None))
    with pytest.raises(ValidationError, match=r"m must have shape \(2, any\)"):
        check_shape(np.zeros((3, 5)), "m", (2, None))


@settings(max_examples=50, deadline=None, derandomize=True)
@given(low=st.floats(-100, 6000, allow_nan=False), high=st.floats(-100, 6000, allow_nan=False))
def test_check_band_accepts_exactly_the_valid_bands(low, high):
    fs = 10_000.0
    valid = 0 < low < high <= fs / 2
    if valid:
        assert check_band((low, high), fs) == (low, high)
    else:
        with pytest.raises(ValidationError, match=r"band must satisfy 0 < low < high <= fs/2 = 5000 Hz"):
            check_band((low, high), fs)


def test_check_band_shape():
    with pytest.raises(ValidationError, match="band must be a pair"):
        check_band((10.0,), 1000.0)
    with pytest.raises(ValidationError, match="band must be a pair"):
        check_band(None, 1000.0)


# --------------------------------------------------------------------------- issue 31
def test_shorten_bounds_what_a_message_echoes():
    from vibrofocus._validation import shorten

    assert shorten("abc") == "'abc'"
    long = shorten("x" * 4_000_000)
    assert len(long) < 120 and "4000002 characters" in long


def test_check_memory_against_what_the_machine_has():
    from vibrofocus._validation import available_memory_bytes, check_memory

    free = available_memory_bytes()
    if free is None:
        pytest.skip("this system does not tell its available memory")
    check_memory(1024, "a small job")
    with pytest.raises(ValidationError, match=r"--n-samples 1e20 needs about .* GiB"):
        check_memory(4 * free, "--n-samples 1e20")


def test_check_declared_size_against_the_stored_bytes_and_a_limit():
    from vibrofocus._validation import MAX_EXPANSION, check_declared_size

    assert check_declared_size((3, 4), 8, "x", stored_bytes=96) == 96
    assert check_declared_size((10**6,), 4, "z", stored_bytes=4 * 10**6 // MAX_EXPANSION + 1, compressed=True) == 4 * 10**6
    with pytest.raises(ValidationError, match=r"y declares shape \(1000, 1000\) \(8,000,000 bytes\) but the file holds "
                                              r"96 bytes of it"):
        check_declared_size((1000, 1000), 8, "y", stored_bytes=96)
    with pytest.raises(ValidationError, match=r"holds 100 compressed bytes"):
        check_declared_size((10**6,), 8, "z", stored_bytes=100, compressed=True)
    with pytest.raises(ValidationError, match=r"w declares a negative length: shape \(-1, 3\)"):
        check_declared_size((-1, 3), 8, "w")
    with pytest.raises(ValidationError, match=r"more than 4 x the file \(1,000 bytes\); refused before reading"):
        check_declared_size((200,), 8, "v", limit_bytes=1000, limit_reason="4 x the file")
    with pytest.raises(ValidationError, match=r"needs about .* GiB"):  # no overflow: Python integers
        check_declared_size((2**40, 2**40), 8, "u")


@pytest.mark.parametrize("text", ["\u0663", "\uff15", "1\u0660", "\u00b2"])
def test_integer_text_reads_ascii_digits_only(text):
    from vibrofocus._validation import integer_text

    assert integer_text(text) is None
    assert integer_text(" 7 ") == 7
