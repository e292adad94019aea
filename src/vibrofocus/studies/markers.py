"""Trial markers for other recordings: where the study engine says what happens when.

The engine calls :func:`send_marker` at each cue, stimulus onset and answer with the
event's own time (``time.monotonic()``, s). A sink added with :func:`sending_markers`
(e.g. :class:`vibrofocus.io.lsl.MarkerOutlet`, ``--lsl``) receives ``(marker, host_time_s)``
from every engine of the process, in whichever thread it runs (the web server runs
sessions in their own threads). A failing sink is logged once and never stops a study.
"""

from __future__ import annotations

import contextlib
import logging
import threading
from collections.abc import Callable, Iterator
from typing import Any

__all__ = ["MarkerSink", "sending_markers", "send_marker", "lsl_markers"]

log = logging.getLogger(__name__)

#: ``sink(marker, host_time_s)``: a dict of JSON-able fields and the event's time, s.
MarkerSink = Callable[[dict[str, Any], float], Any]
_SINKS: list[MarkerSink] = []
_LOCK = threading.Lock()
_FAILED: set[int] = set()


@contextlib.contextmanager
def sending_markers(sink: MarkerSink) -> Iterator[MarkerSink]:
    """Send every engine's markers to ``sink`` while the block runs.

    Parameters
    ----------
    sink : callable
        ``sink(marker, host_time_s)``.
    """
    with _LOCK:
        _SINKS.append(sink)
    try:
        yield sink
    finally:
        with _LOCK:
            _SINKS.remove(sink)


def send_marker(event: str, host_time_s: float, **fields: Any) -> None:
    """Give one marker to every sink (nothing happens without one).

    Parameters
    ----------
    event : str
        ``cue``, ``stimulus_onset`` or ``answer``.
    host_time_s : float
        When it happened, ``time.monotonic()``, s.
    **fields
        ``participant``, ``study``, ``session``, ``trial``, ``trial_index``, ``phase``,
        ``method``, ``target``, ``response`` (None before the answer); a stimulus onset's
        ``onset_device_s`` and ``onset_clock`` (the rig's device clock, None without one) and
        ``onset_latency_s`` (the output latency its time includes, None where unknown), ...
    """
    with _LOCK:
        sinks = list(_SINKS)
    if not sinks:
        return
    marker = {"event": event, **fields}
    for sink in sinks:
        try:
            sink(marker, host_time_s)
        except Exception as exc:  # noqa: BLE001 - a marker stream never stops a study
            if id(sink) not in _FAILED:
                _FAILED.add(id(sink))
                log.warning("a marker could not be sent (%s: %s); the study goes on", type(exc).__name__, exc)


@contextlib.contextmanager
def lsl_markers(enabled: bool = True, *, source_id: str | None = None, wait_s: float = 0.0) -> Iterator[Any]:
    """Open the LSL outlet ``vibrofocus-markers`` and send every engine's markers to it (``--lsl``).

    Parameters
    ----------
    enabled : bool
        False: do nothing (yields None), so a command can write ``with lsl_markers(lsl):``.
    source_id : str, optional
        The streams' source id (:func:`vibrofocus.io.lsl.stable_source_id` of the study
        database, or ``--lsl-source-id``); default: unique per process.
    wait_s : float
        Wait up to this long, s, for a recorder's inlet before the block runs (``--lsl-wait``):
        a recorder that is recovering the stream of a killed run is connected before the
        resumed run's first marker.

    Yields
    ------
    MarkerOutlet or None
    """
    if not enabled:
        yield None
        return
    from ..io.lsl import MarkerOutlet

    with MarkerOutlet(source_id=source_id) as outlet, sending_markers(outlet):
        if wait_s > 0 and not outlet.wait_for_consumers(float(wait_s)):
            log.warning("no LSL recorder connected to %s within %g s; the run goes on", outlet.source_id, wait_s)
        yield outlet
