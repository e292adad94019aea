"""Shared parameter descriptions, defined once and filled into docstrings.

A docstring names an entry as ``%(name)s`` on a line of its own (indented like the other
parameters) and its function is decorated with :func:`fill_doc`, as MNE-Python does. Only
``%(...)s`` placeholders whose name is in :data:`docdict` are replaced, so other ``%`` signs
in a docstring are left alone; an unknown name raises at import, so a typo cannot ship.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from typing import TypeVar

__all__ = ["docdict", "fill_doc"]

F = TypeVar("F", bound=Callable)

docdict: dict[str, str] = {
    "fs": """fs : float
    Sample rate, Hz.""",
    "band": """band : (float, float)
    Design band ``(low, high)``, Hz, inside ``(0, fs / 2]``.""",
    "H": """H : ndarray, complex, shape (n // 2 + 1, n_points, n_actuators)
    Transfer matrix on ``rfftfreq(n, 1 / fs)``, m/V.""",
    "layout": """layout : ArrayLayout
    The array: its actuators, locations and guard points (positions in m).""",
    "layout_default": """layout : ArrayLayout, optional
    Location coordinates (m); default the reference layout.""",
    "rig": """rig : Rig
    Where the drives play, through the rig's safety layer (the simulated forearm, an
    audio interface or NI-DAQmx: :func:`vibrofocus.rigs.make_rig`).""",
    "seed": """seed : int
    Participant seed (>= 0): the same seed always gives the same simulated participant.""",
    "taper_octaves": """taper_octaves : float
    Width of the raised-cosine roll-off beyond each band edge, octaves (0: a brick
    wall). The default 0.5 keeps the band's edges smooth in time.""",
    "sweep": """fs : float
    Sample rate, Hz.
f_start : float
    Start frequency, Hz (> 0).
f_stop : float
    Stop frequency, Hz (> f_start, at most fs / 2).
duration : float
    Length of the sweep, s.""",
    "sweep_fade_s": """fade_s : float
    Length of the raised-cosine fade-in and fade-out, s (0: none).""",
}

_PLACEHOLDER = re.compile(r"^(?P<indent>[ \t]*)%\((?P<name>\w+)\)s[ \t]*$", re.MULTILINE)


def fill_doc(func: F) -> F:
    """Replace the ``%(name)s`` lines of ``func``'s docstring with :data:`docdict` entries.

    Each entry is indented like its placeholder line.
    """
    doc = func.__doc__
    if not doc:
        return func

    def replace(match: re.Match) -> str:
        name, indent = match.group("name"), match.group("indent")
        if name not in docdict:
            raise KeyError(f"{func.__qualname__}: no shared description {name!r} in vibrofocus._docs.docdict")
        return "\n".join(indent + line if line else line for line in docdict[name].splitlines())

    func.__doc__ = _PLACEHOLDER.sub(replace, doc)
    return func
