"""STUB of psychopy.event: inert (not PsychoPy)."""

from . import _Inert


def __getattr__(name):
    return _Inert()
