"""Lab Streaming Layer markers: the ``vibrofocus-markers`` outlet (type ``Markers``) and its detail stream.

Each event goes out twice, with the same timestamp:

- on ``vibrofocus-markers`` (type ``Markers``) as a short **event code** from a small
  vocabulary (:func:`marker_code`: ``cue``, ``tap/<method>/<phase>/study<N>``, ``answer``),
  what an EEG pipeline makes its event types of (EEGLAB, ``mne.Annotations``);
- on ``vibrofocus-markers-detail`` (type ``MarkerDetails``) as one JSON record (``code``,
  ``event``, ``participant``, ``study``, ``trial``, ``method``, ``target``, ``response``,
  ...; a stimulus onset also carries ``onset_device_s``, ``onset_clock`` and
  ``onset_latency_s``).

Both are stamped with the time of the event itself on LSL's clock
(:func:`pylsl.local_clock`), not the time it was sent: the host's ``time.monotonic()`` of
the event is mapped onto LSL's clock with an offset measured when the outlet opens. An EEG,
EMG or motion-capture recording then has the stimulus onsets on its own time axis
(LabRecorder, ``pyxdf``).

The source id is what lets a recorder (LabRecorder's inlets, ``recover=True``) find the
stream again after its sender crashed: :func:`stable_source_id` derives one from the study
database, so a run that is killed and resumed keeps one stream.

Needs the optional extra ``vibrofocus[lsl]`` (pylsl, whose wheels bundle liblsl).
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import socket
import threading
import time
import uuid
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from .._validation import shorten
from ..errors import ValidationError
from .jsonsafe import json_safe

__all__ = ["STREAM_NAME", "STREAM_TYPE", "DETAIL_STREAM_NAME", "DETAIL_STREAM_TYPE", "CODES", "MarkerOutlet",
           "clock_offset", "import_pylsl", "marker_code", "stable_source_id", "check_source_id"]

#: Name and type of the marker stream (event codes).
STREAM_NAME = "vibrofocus-markers"
STREAM_TYPE = "Markers"
#: Name and type of the detail stream (one JSON record per marker, same timestamps).
DETAIL_STREAM_NAME = "vibrofocus-markers-detail"
DETAIL_STREAM_TYPE = "MarkerDetails"

#: The event codes, with what each marks (``<method>``: the rendering method, ``<phase>``:
#: ``main`` or ``training``, ``<N>``: the study, 1 or 2).
CODES: dict[str, str] = {
    "cue": "the cue (beep) of a trial",
    "tap/<method>/<phase>/study<N>": "the stimulus onset: the drive's first sample at the actuators (the detail "
                                     "record's replay is true for a trial presented again: resumed, or after a pause)",
    "tap/<method>": "a live tap's onset (serve-osc --lsl; no phase or study)",
    "dry/<method>/<phase>/study<N>": "a dry run's stimulus onset (nothing is played)",
    "tap/<method>/<phase>/threshold": "a threshold block's stimulus onset (dry/... in a dry run)",
    "answer": "the participant's answer (the locations are in the detail stream)",
}

#: How long :meth:`MarkerOutlet.wait_for_consumers` waits for the detail stream's inlet
#: once the code stream has one, s.
DETAIL_GRACE_S = 5.0
#: How long after its last marker :meth:`MarkerOutlet.close` keeps the outlets open while an
#: inlet is connected, s. liblsl has no flush: an outlet destroyed right after a push drops
#: what its sending thread had not yet written (a process that pushed its last marker and
#: closed at once lost it in 1 of 12 runs on a loaded 2-core machine, and a burst of 50
#: pushed just before closing nearly always: 394 of 400 lost over 8 runs; with this wait, none).
CLOSE_LINGER_S = 0.5

_TOKEN = re.compile(r"[^A-Za-z0-9_.+-]+")
#: Where the source ids this process derived from a file came from (:func:`stable_source_id`),
#: for the streams' ``source_id_from``.
_DERIVED: dict[str, str] = {}
_SOURCE_ID = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.:+-]{0,99}")


def _token(value: Any) -> str:
    """One part of an event code: no '/' or spaces (MNE splits tags at '/')."""
    return _TOKEN.sub("_", str(value)).strip("_")[:40] or "_"


def marker_code(marker: Mapping[str, Any]) -> str:
    """The short event code of a marker (:data:`CODES`).

    ``cue`` and ``answer`` as they are; a stimulus onset (``event`` ``stimulus_onset`` or
    ``tap``) as ``tap/<method>``, then ``/<phase>`` and ``/study<N>`` where the marker has
    them, ``/threshold`` in place of ``/study<N>`` for a threshold block's (``task``
    ``threshold``) (``dry/...`` when ``played`` is false); any other event by its name; a marker with
    its own ``code`` keeps it.

    Parameters
    ----------
    marker : mapping
        The marker's fields (``event``, ``method``, ``phase``, ``study``, ``played``, ...).

    Returns
    -------
    str
    """
    if marker.get("code"):
        return str(marker["code"])
    event = str(marker.get("event", "marker"))
    if event not in ("stimulus_onset", "tap"):
        return _token(event)
    parts = ["dry" if marker.get("played") is False else "tap", _token(marker.get("method", "unknown"))]
    if marker.get("phase") is not None:
        parts.append(_token(marker["phase"]))
    if marker.get("task") == "threshold":  # a threshold block's tap: not a localization trial
        parts.append("threshold")
    elif marker.get("study") is not None:
        parts.append(f"study{_token(marker['study'])}")
    return "/".join(parts)


def check_source_id(source_id: Any, name: str = "--lsl-source-id") -> str:
    """A source id a recorder can find again: 1-100 letters, digits and ``_ . : + -``.

    Parameters
    ----------
    source_id : str
        The id.
    name : str
        How errors name it.

    Returns
    -------
    str

    Raises
    ------
    ValidationError
    """
    if not isinstance(source_id, str) or not _SOURCE_ID.fullmatch(source_id):
        raise ValidationError(f"{name} must be 1-100 letters, digits or '_.:+-', starting with a letter or digit, "
                              f"got {shorten(source_id)}")
    return source_id


def stable_source_id(database: str | os.PathLike[str], study: int | None = None) -> str:
    """The source id of a study database's marker stream: the same in every run on this machine.

    ``vibrofocus-<16 hex digits>`` (``-study<N>`` added for one study): a hash of this
    machine's name and the database's resolved path, so a run that is killed and resumed
    on the same database sends on the same stream, which a recorder's inlet recovers.

    Parameters
    ----------
    database : path
        The study database.
    study : int, optional
        The study the process runs, when it runs one.

    Returns
    -------
    str
    """
    path = Path(os.fspath(database)).expanduser().resolve()
    where = f"{socket.gethostname()}\0{path}"
    digest = hashlib.sha256(where.encode("utf-8", "surrogateescape")).hexdigest()[:16]
    source_id = f"vibrofocus-{digest}" + (f"-study{int(study)}" if study is not None else "")
    _DERIVED[source_id] = f"a hash of this machine's name and the file {path}"
    return source_id


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


def _describe(info: Any, *, channel: tuple[str, str], source: str, detail: str | None) -> None:
    """The stream's metadata: channel, acquisition/software block, vocabulary."""
    from importlib.metadata import PackageNotFoundError, version

    try:  # as vibrofocus.__version__ (io imports nothing above it)
        __version__ = version("vibrofocus")
    except PackageNotFoundError:
        __version__ = "0.0.0+unknown"
    desc = info.desc()
    ch = desc.append_child("channels").append_child("channel")
    ch.append_child_value("label", channel[0])
    ch.append_child_value("type", channel[1])
    # XDF's meta-data conventions: who made the stream and with what.
    acq = desc.append_child("acquisition")
    acq.append_child_value("manufacturer", "vibrofocus")
    acq.append_child_value("model", "vibrofocus study engine")
    acq.append_child_value("software", "vibrofocus")
    acq.append_child_value("version", __version__)
    acq.append_child_value("compensated_lag", "0")
    own = desc.append_child("vibrofocus")
    own.append_child_value("source_id_from", source)
    own.append_child_value("timestamps", "each event's own time on LSL's clock; stimulus onsets at the device's "
                                         "output (host time + the rig's output latency, where it knows it)")
    if detail is not None:
        own.append_child_value("detail_stream", detail)
    codes = own.append_child("codes")
    for code, meaning in CODES.items():
        entry = codes.append_child("code")
        entry.append_child_value("name", code)
        entry.append_child_value("meaning", meaning)


class MarkerOutlet:
    """LSL outlets sending event codes, and their JSON detail, stamped with their events' own times.

    Parameters
    ----------
    source_id : str, optional
        LSL source id of the code stream (the detail stream's is this plus ``-detail``),
        so that a recorder can tell apart two vibrofocus processes and find the same one
        again after a crash (:func:`stable_source_id`). Default: unique per outlet.
    name : str
        Name of the code stream (default :data:`STREAM_NAME`).
    detail : bool
        Also open the detail stream (:data:`DETAIL_STREAM_NAME`, or ``name`` + ``-detail``).

    Attributes
    ----------
    offset_s : float
        LSL clock minus host ``time.monotonic()``, s, measured when the outlet opened.
    source_id : str
        The code stream's source id.
    """

    def __init__(self, *, source_id: str | None = None, name: str = STREAM_NAME, detail: bool = True) -> None:
        pylsl = import_pylsl()
        given = source_id is not None
        self.source_id = (check_source_id(source_id, "source_id") if given
                          else f"vibrofocus-{os.getpid()}-{uuid.uuid4().hex[:8]}")
        detail_name = (DETAIL_STREAM_NAME if name == STREAM_NAME else f"{name}-detail") if detail else None
        origin = (_DERIVED.get(self.source_id, "given (--lsl-source-id)") if given
                  else "random (this process)")
        info = pylsl.StreamInfo(name, STREAM_TYPE, 1, pylsl.IRREGULAR_RATE, pylsl.cf_string, self.source_id)
        _describe(info, channel=("code", "Marker"), source=origin, detail=detail_name)
        self._outlet = pylsl.StreamOutlet(info)
        self._detail = None
        if detail_name is not None:
            dinfo = pylsl.StreamInfo(detail_name, DETAIL_STREAM_TYPE, 1, pylsl.IRREGULAR_RATE, pylsl.cf_string,
                                     f"{self.source_id}-detail")
            _describe(dinfo, channel=("detail", "JSON"), source=origin, detail=None)
            self._detail = pylsl.StreamOutlet(dinfo)
        self._pylsl = pylsl
        self.offset_s = clock_offset(pylsl.local_clock)
        self._lock = threading.Lock()
        self._last_push: float | None = None  # time.monotonic() of the last marker sent

    def lsl_time(self, host_time_s: float) -> float:
        """A host ``time.monotonic()`` time on LSL's clock, s."""
        return float(host_time_s) + self.offset_s

    def push(self, marker: Mapping[str, Any], host_time_s: float) -> float:
        """Send one marker stamped with its event's host time, mapped to LSL's clock.

        The code stream gets :func:`marker_code` of it, the detail stream the whole
        record as JSON (with ``code``), both with the same timestamp.

        Parameters
        ----------
        marker : mapping
            JSON-able fields (NaN/Inf become null); ``event`` names the event.
        host_time_s : float
            When the event happened, ``time.monotonic()``, s.

        Returns
        -------
        float
            The LSL timestamp sent, s.
        """
        stamp = self.lsl_time(host_time_s)
        code = marker_code(marker)
        text = json.dumps(json_safe({**marker, "code": code}), sort_keys=True)
        with self._lock:
            self._outlet.push_sample([code], stamp)
            if self._detail is not None:
                self._detail.push_sample([text], stamp)
            self._last_push = time.monotonic()
        return stamp

    def __call__(self, marker: Mapping[str, Any], host_time_s: float) -> float:
        return self.push(marker, host_time_s)

    def have_consumers(self) -> bool:
        """Whether some inlet is connected to the code stream."""
        return bool(self._outlet.have_consumers())

    def wait_for_consumers(self, timeout_s: float) -> bool:
        """Wait up to ``timeout_s`` for an inlet on the code stream; whether one is connected.

        Once it is, the detail stream gets up to :data:`DETAIL_GRACE_S` more (within
        ``timeout_s``) for its own inlet: a recorder connects to the streams it records one
        after the other, and one that records the codes alone is not waited for long.
        """
        deadline = time.monotonic() + float(timeout_s)
        if not self._outlet.wait_for_consumers(float(timeout_s)):
            return False
        if self._detail is not None:
            self._detail.wait_for_consumers(max(0.0, min(DETAIL_GRACE_S, deadline - time.monotonic())))
        return True

    def close(self) -> None:
        """Close the outlets (the streams disappear from the network).

        While an inlet is connected, the outlets stay open until :data:`CLOSE_LINGER_S`
        after the last marker, so that a recorder receives the markers sent just before.
        """
        with self._lock:
            outlets = [o for o in (self._outlet, self._detail) if o is not None]
            left = 0.0 if self._last_push is None else self._last_push + CLOSE_LINGER_S - time.monotonic()
            if left > 0 and any(o.have_consumers() for o in outlets):
                time.sleep(left)
            self._outlet = None
            self._detail = None

    def __enter__(self) -> "MarkerOutlet":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
