"""Real time: taps asked live by other programs (Open Sound Control) and the rig's measured
onset latency; the log of live taps (:mod:`.taplog`).

:mod:`.osc` imports python-osc (the optional extra ``vibrofocus[osc]``) only when a
server handles its first datagram.
"""

from .designer import GRID_PITCH_M, CalibratedArea, TapDesigner
from .latency import LatencyReport, click_drive, latency_figure, measure_latency, onset_s
from .osc import ADDRESSES, LEVEL_DB_RANGE, PLAYED_FIELDS, OscTapServer, TapRecord
from .taplog import TAP_LOG_COLUMNS, TapLog, read_tap_log

__all__ = ["TapDesigner", "CalibratedArea", "GRID_PITCH_M", "OscTapServer", "TapRecord", "ADDRESSES",
           "LEVEL_DB_RANGE", "PLAYED_FIELDS", "TapLog", "TAP_LOG_COLUMNS", "read_tap_log",
           "LatencyReport", "click_drive", "onset_s", "measure_latency", "latency_figure"]
