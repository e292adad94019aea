"""Real time: taps asked live by other programs (Open Sound Control) and the rig's measured
onset latency.

:mod:`.osc` imports python-osc (the optional extra ``vibrofocus[osc]``) only when a
server handles its first datagram.
"""

from .designer import GRID_PITCH_M, CalibratedArea, TapDesigner
from .osc import ADDRESSES, OscTapServer, TapRecord

__all__ = ["TapDesigner", "CalibratedArea", "GRID_PITCH_M", "OscTapServer", "TapRecord", "ADDRESSES"]
