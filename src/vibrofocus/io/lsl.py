"""Lab Streaming Layer markers: one ``vibrofocus-markers`` outlet of type ``Markers``.

Each marker is one JSON string (a plain record: ``event``, ``participant``, ``study``,
``trial``, ``method``, ``target``, ``response``, ...; a stimulus onset also carries
``onset_device_s`` and ``onset_clock``, the onset on the rig's own clock) stamped with the time of the event
itself on LSL's clock (:func:`pylsl.local_clock`), not the time it was sent: the host's
``time.monotonic()`` of the event is mapped onto LSL's clock with an offset measured when
the outlet opens. An EEG, EMG or motion-capture recording then has the stimulus onsets on
its own time axis (LabRecorder, ``pyxdf``).

Needs the optional extra ``vibrofocus[lsl]`` (pylsl, whose wheels bundle liblsl).
"""

from __future__ import annotations

import json
import os
import threading
import time
import uuid
from collections.abc import Callable, Mapping
from typing import Any

from ..errors import ValidationError
from .jsonsafe import json_safe

__all__ = ["STREAM_NAME", "STREAM_TYPE", "MarkerOutlet", "clock_offset", "import_pylsl"]

#: Name and type of the marker stream.
STREAM_NAME = "vibrofocus-markers"
STREAM_TYPE = "Markers"


def import_pylsl() -> Any:
    """pylsl, or ValidationError saying how to install it."""
    try:
        import pylsl
    except ImportError as exc:  # also a liblsl that cannot be loaded
        raise ValidationError(f"--lsl needs pylsl: pip install 'vibrofocus[lsl]' ({exc})") from None
    return pylsl


def clock_offset(lsl_clock: Callable[[], float], host_clock: Callable[[], float] = time.monotonic,
                 *, tries: int = 25) -> float:
    """Offset from the host clock to LSL's clock, s: ``lsl_time = host_time + offset``.

    Each try reads the host clock, LSL's clock, the host clock again; the try with the
    shortest bracket gives the offset (its error is at most half that bracket).

    Parameters
    ----------
    lsl_clock, host_clock : callable
        Clocks returning seconds.
    tries : int
        Number of brackets.
    """
    best = (float("inf"), 0.0)
    for _ in range(tries):
        before = host_clock()
        lsl = lsl_clock()
        after = host_clock()
        best = min(best, (after - before, lsl - (before + after) / 2))
    return best[1]


class MarkerOutlet:
    """An LSL outlet that sends JSON markers stamped with their events' own times.

    Parameters
    ----------
    source_id : str, optional
        LSL source id (default: unique per outlet), so that a recorder can tell apart
        two vibrofocus processes and reconnect to the same one.
    name : str
        Stream name (default :data:`STREAM_NAME`).

    Attributes
    ----------
    offset_s : float
        LSL clock minus host ``time.monotonic()``, s, measured when the outlet opened.
    """

    def __init__(self, *, source_id: str | None = None, name: str = STREAM_NAME) -> None:
        pylsl = import_pylsl()
        self.source_id = source_id or f"vibrofocus-{os.getpid()}-{uuid.uuid4().hex[:8]}"
        info = pylsl.StreamInfo(name, STREAM_TYPE, 1, pylsl.IRREGULAR_RATE, pylsl.cf_string, self.source_id)
        channel = info.desc().append_child("channels").append_child("channel")
        channel.append_child_value("label", "marker")
        channel.append_child_value("type", "JSON")
        self._outlet = pylsl.StreamOutlet(info)
        self._pylsl = pylsl
        self.offset_s = clock_offset(pylsl.local_clock)
        self._lock = threading.Lock()

    def lsl_time(self, host_time_s: float) -> float:
        """A host ``time.monotonic()`` time on LSL's clock, s."""
        return float(host_time_s) + self.offset_s

    def push(self, marker: Mapping[str, Any], host_time_s: float) -> float:
        """Send one marker stamped with its event's host time, mapped to LSL's clock.

        Parameters
        ----------
        marker : mapping
            JSON-able fields (NaN/Inf become null).
        host_time_s : float
            When the event happened, ``time.monotonic()``, s.

        Returns
        -------
        float
            The LSL timestamp sent, s.
        """
        stamp = self.lsl_time(host_time_s)
        text = json.dumps(json_safe(dict(marker)), sort_keys=True)
        with self._lock:
            self._outlet.push_sample([text], stamp)
        return stamp

    def __call__(self, marker: Mapping[str, Any], host_time_s: float) -> float:
        return self.push(marker, host_time_s)

    def have_consumers(self) -> bool:
        """Whether some inlet is connected."""
        return bool(self._outlet.have_consumers())

    def wait_for_consumers(self, timeout_s: float) -> bool:
        """Wait up to ``timeout_s`` for an inlet; whether one is connected."""
        return bool(self._outlet.wait_for_consumers(timeout_s))

    def close(self) -> None:
        """Close the outlet (the stream disappears from the network)."""
        self._outlet = None

    def __enter__(self) -> "MarkerOutlet":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
