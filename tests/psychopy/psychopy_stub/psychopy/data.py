"""STUB of psychopy.data: an experiment handler writing a CSV, a plain staircase (not PsychoPy)."""

import csv
import os
import types

from . import _Inert, core


def getDateStr(format="%Y-%m-%d_%Hh%M.%S.%f", fractionalSecondDigits=3):
    return "2026-01-01_00h00.00.000"


utils = types.SimpleNamespace(parsePipeSyntax=lambda key: (key.split("|")[0], []))


class Routine:
    def __init__(self, name="", components=(), **kwargs):
        self.name, self.components = name, list(components)
        self.status = None

    def __getattr__(self, name):
        if name.startswith("__"):
            raise AttributeError(name)
        return _Inert()


class ExperimentHandler:
    """Rows of ``addData`` values, one per ``nextEntry``; ``saveAsWideText`` writes them as CSV."""

    def __init__(self, name="", version="", extraInfo=None, dataFileName="data", **kwargs):
        self.name, self.extraInfo, self.dataFileName = name, dict(extraInfo or {}), dataFileName
        self.rows, self._row, self.loops = [], {}, []
        self.status = None
        self.currentRoutine = None

    def addData(self, name, value, row=None, priority=None):
        self._row[name] = value

    def timestampOnFlip(self, win, name, format=float):
        win.callOnFlip(self.addData, name, core.NOW[0])

    def addLoop(self, loop):
        self.loops.append(loop)

    def loopEnded(self, loop):
        pass

    def nextEntry(self):
        for loop in self.loops:
            for key, value in getattr(loop, "_this_row", {}).items():
                self._row.setdefault(key, value)
        self.rows.append(self._row)
        self._row = {}

    def saveAsWideText(self, fileName, delim=",", **kwargs):
        if not fileName.endswith(".csv"):
            fileName += ".csv"
        os.makedirs(os.path.dirname(os.path.abspath(fileName)), exist_ok=True)
        names = list(dict.fromkeys(k for row in self.rows for k in row))
        with open(fileName, "w", newline="", encoding="utf-8") as fh:
            writer = csv.DictWriter(fh, names)
            writer.writeheader()
            writer.writerows(self.rows)
        return fileName

    def saveAsPickle(self, fileName, fileCollisionMethod="rename"):
        pass

    def close(self):
        pass

    def abort(self):
        pass

    def __getattr__(self, name):
        if name.startswith("__"):
            raise AttributeError(name)
        return _Inert()


class StairHandler:
    """A plain nUp/nDown staircase with linear steps (``stepType='lin'``)."""

    def __init__(self, startVal, nReversals=None, stepSizes=4, nTrials=0, nUp=1, nDown=3, extraInfo=None,
                 method="2AFC", stepType="db", minVal=None, maxVal=None, originPath=None, name="", **kwargs):
        if stepType != "lin":
            raise NotImplementedError("the stub's StairHandler takes linear steps only")
        self.name, self.startVal = name, startVal
        self.stepSizes = list(stepSizes) if isinstance(stepSizes, (list, tuple)) else [stepSizes]
        self.nReversals, self.nTrials = nReversals or 0, nTrials
        self.nUp, self.nDown, self.minVal, self.maxVal = nUp, nDown, minVal, maxVal
        self.intensities, self.data, self.reversalIntensities = [], [], []
        self.otherData = {}
        self.thisTrialN = -1
        self.finished = False
        self._level, self._correct, self._wrong, self._direction = startVal, 0, 0, None
        self._this_row = {}

    def __iter__(self):
        return self

    def __next__(self):
        if self.finished or (len(self.intensities) >= self.nTrials
                             and len(self.reversalIntensities) >= self.nReversals):
            self.finished = True
            raise StopIteration
        self.thisTrialN += 1
        self.intensities.append(self._level)
        self._this_row = {f"{self.name}.thisTrialN": self.thisTrialN, f"{self.name}.intensity": self._level}
        return self._level

    next = __next__

    def addResponse(self, result, intensity=None):
        self.data.append(int(bool(result)))
        self._this_row[f"{self.name}.response"] = int(bool(result))
        step = self.stepSizes[min(len(self.reversalIntensities), len(self.stepSizes) - 1)]
        move = None
        if result:
            self._correct, self._wrong = self._correct + 1, 0
            if self._correct >= self.nDown:
                move, self._correct = "down", 0
        else:
            self._wrong, self._correct = self._wrong + 1, 0
            if self._wrong >= self.nUp:
                move, self._wrong = "up", 0
        if move is None:
            return
        if self._direction is not None and move != self._direction:
            self.reversalIntensities.append(self.intensities[-1])
        self._direction = move
        level = self._level + (step if move == "up" else -step)
        if self.minVal is not None:
            level = max(self.minVal, level)
        if self.maxVal is not None:
            level = min(self.maxVal, level)
        self._level = level

    def addOtherData(self, name, value):
        self.otherData.setdefault(name, []).append(value)
        self._this_row[name] = value

    def __getattr__(self, name):
        if name.startswith("__"):
            raise AttributeError(name)
        return _Inert()
