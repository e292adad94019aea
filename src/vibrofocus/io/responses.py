"""A stored response: the chosen locations as text, ascending, separated by spaces (``"4 5"``).

The one writer (:func:`format_response`) and the one reader
(:func:`parse_response_text`) of the ``response`` column of the trials file and the
study database. Answers as typed by a participant (keypad digits, design rules) are
checked by :func:`vibrofocus.studies.parse_response` before they are stored.
"""

from __future__ import annotations

from collections.abc import Iterable

from .._validation import integer_text, shorten
from ..errors import ValidationError

__all__ = ["format_response", "parse_response_text"]


def format_response(locations: Iterable[int]) -> str:
    """Locations as the export writes them: ascending, separated by spaces (``"4 5"``).

    Parameters
    ----------
    locations : iterable of int
        Selected locations, 1-based.

    Returns
    -------
    str
    """
    return " ".join(str(int(x)) for x in sorted(locations))


def parse_response_text(text: str, *, n_locations: int | None = None, name: str = "response") -> tuple[int, ...]:
    """Read a stored response (``"4 5"``; commas are accepted as separators too).

    The same text names a block's allowed answers (the trials file's ``allowed`` column:
    ``name="allowed"``).

    Parameters
    ----------
    text : str
        The ``response`` field of a trials file or study database row.
    n_locations : int, optional
        Number of locations; when given, every location must be in ``1..n_locations``.
    name : str
        The column, for messages (default ``"response"``).

    Returns
    -------
    tuple of int
        The locations, ascending.

    Raises
    ------
    ValidationError
        Empty, not a list of integers, a location out of range, or one named twice;
        the message starts with ``name`` and quotes ``text``.
    """
    tokens = text.replace(",", " ").split()
    if not tokens:
        raise ValidationError(f"{name} is empty: no location was " + ("chosen" if name == "response" else "named"))
    numbers = []
    for token in tokens:
        value = integer_text(token)
        if value is None:
            raise ValidationError(f"{name} {shorten(text)} is not a list of location numbers separated by spaces")
        if n_locations is not None and not 1 <= value <= n_locations:
            raise ValidationError(f"{name} {shorten(text)} names location {value}, outside 1..{n_locations}")
        numbers.append(value)
    if len(set(numbers)) != len(numbers):
        raise ValidationError(f"{name} {shorten(text)} names the same location more than once")
    return tuple(sorted(numbers))
