"""Real time: taps asked live by other programs (Open Sound Control) and the rig's measured
onset latency.

:mod:`.osc` imports python-osc (the optional extra ``vibrofocus[osc]``) only when a
server handles its first datagram.
"""

from .designer import GRID_PITCH_M, CalibratedArea, TapDesigner
from .latency import LatencyReport, click_drive, latency_figure, measure_latency, onset_s
from .osc import ADDRESSES, OscTapServer, TapRecord

__all__ = ["TapDesigner", "CalibratedArea", "GRID_PITCH_M", "OscTapServer", "TapRecord", "ADDRESSES",
           "LatencyReport", "click_drive", "onset_s", "measure_latency", "latency_figure"]
