"""STUB of psychopy.visual: a window that shows nothing (not PsychoPy)."""

from . import _Inert, core

FRAME_S = 1 / 60


class Window:
    """flip() runs the callOnFlip callbacks, then advances the simulated clock one frame."""

    def __init__(self, *args, **kwargs):
        self._on_flip = []
        self._monitorFrameRate = 60.0
        self.winHandle = _Inert()
        self.frames = 0

    def callOnFlip(self, function, *args, **kwargs):
        self._on_flip.append((function, args, kwargs))

    def timeOnFlip(self, obj, attr):
        self.callOnFlip(setattr, obj, attr, core.NOW[0])

    def getFutureFlipTime(self, targetTime=0, clock=None):
        if clock is None or isinstance(clock, str):
            return core.NOW[0]
        return clock.getTime()

    def getActualFrameRate(self, *args, **kwargs):
        return 60.0

    def flip(self, clearBuffer=True):
        callbacks, self._on_flip = self._on_flip, []
        for function, args, kwargs in callbacks:
            function(*args, **kwargs)
        self.frames += 1
        core.NOW[0] += FRAME_S
        return core.NOW[0]

    def close(self):
        pass

    def __getattr__(self, name):
        if name.startswith("__"):
            raise AttributeError(name)
        return _Inert()


class TextStim:
    def __init__(self, win=None, text="", **kwargs):
        self.text = text

    def draw(self):
        pass

    def setAutoDraw(self, value):
        pass


def __getattr__(name):
    return _Inert()
