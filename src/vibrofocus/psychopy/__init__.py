"""vibrofocus in PsychoPy experiments: :class:`TapStimulus` (Coder) and a Builder component.

:class:`TapStimulus` plays a tap through a running ``vibrofocus serve-osc`` or an
in-process rig, with ``win.callOnFlip`` timing, and stores its onsets (host and device
clocks) in the experiment's data file. The Builder component
(:mod:`vibrofocus.psychopy.builder`, ``pip install 'vibrofocus[psychopy]'``) is registered
through PsychoPy's ``psychopy.experiment.components`` entry point and writes code that uses
it. Importing this package imports neither PsychoPy nor python-osc.
"""

from .tap import DATA_FIELDS, TapResult, TapStimulus

__all__ = ["TapStimulus", "TapResult", "DATA_FIELDS"]
