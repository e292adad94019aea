"""STUB of psychopy.locale_setup: inert (not PsychoPy)."""

from . import _Inert


def __getattr__(name):
    return _Inert()
