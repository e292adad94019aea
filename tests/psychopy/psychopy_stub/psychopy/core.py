"""STUB of psychopy.core: clocks on a simulated frame time (not PsychoPy)."""

import sys

from . import _Inert

#: Simulated seconds since start; the stub Window's flip() advances it.
NOW = [0.0]


def getTime():
    return NOW[0]


def wait(secs, hogCPUperiod=0.2):
    NOW[0] += float(secs)


def quit():
    sys.exit(0)


def setPilotModeFromArgs():
    return False


class Clock:
    def __init__(self, format="float"):
        self._start = NOW[0]
        self.format = format

    def getTime(self, format="float"):
        return NOW[0] - self._start

    def reset(self, newT=0.0):
        self._start = NOW[0] + newT

    def addTime(self, t):
        self._start -= t

    def getLastResetTime(self):
        return self._start


CountdownTimer = Clock
monotonicClock = Clock()


def __getattr__(name):
    return _Inert()
