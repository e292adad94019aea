"""STUB of psychopy.logging: inert (not PsychoPy)."""

from . import _Inert


def __getattr__(name):
    return _Inert()
