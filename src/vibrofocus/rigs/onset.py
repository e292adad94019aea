"""When a play started, on the host's clock and on the device's own: :class:`DeviceOnset`.

:meth:`Rig.play <vibrofocus.rigs.Rig.play>` returns one per play. The host time is
``time.monotonic()``, the clock of the study engine and of the LSL markers; the device
time is the clock the samples themselves run on, named by :data:`CLOCKS`:

- ``simulated_samples``: the simulated rig's sample clock, the samples it has played
  before this one divided by its rate. It counts played samples only, so it stands
  still between plays.
- ``portaudio_dac``: PortAudio's ``outputBufferDacTime`` of the stream's first callback,
  the time the drive's first sample reaches the converter, on the stream's clock
  (``Pa_GetStreamTime``). The audio rig runs one stream from its opening to its closing,
  so the clock runs on between plays. Through JACK (PortAudio's JACK host API) it is
  JACK's frame time since the stream was opened, divided by the rate, plus the playback
  latency.
- ``nidaq_start_trigger``: the start trigger's timestamp of the NI-DAQmx output task
  (``StartTrigger.timestamp_val``, on the I/O device's timescale), as seconds since
  the Unix epoch. Only devices with timestamps give it (TSN-synchronised devices, such
  as the cDAQ-9185/9189).
- ``nidaq_samples``: on the other NI devices, the sample clock's count: the samples the
  rig's output tasks generated before this play (``OutStream.total_samp_per_chan_generated``
  of each completed play, summed) divided by the rate. Like the simulated clock, it
  stands still between plays.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Any

from .._validation import shorten
from ..errors import ValidationError

__all__ = ["DeviceOnset", "CLOCKS", "SIMULATED_CLOCK", "PORTAUDIO_CLOCK", "NIDAQ_CLOCK", "NIDAQ_SAMPLES_CLOCK",
           "register_clock", "check_onset"]

SIMULATED_CLOCK = "simulated_samples"
PORTAUDIO_CLOCK = "portaudio_dac"
NIDAQ_CLOCK = "nidaq_start_trigger"
NIDAQ_SAMPLES_CLOCK = "nidaq_samples"
#: Every device clock an onset may name, with what its seconds count.
CLOCKS: dict[str, str] = {
    SIMULATED_CLOCK: "the simulated rig's sample clock: samples played before this play / rate (stands still "
                     "between plays)",
    PORTAUDIO_CLOCK: "PortAudio's outputBufferDacTime of the play's first sample, on the stream's clock (through "
                     "JACK: frame time since the stream opened / rate, plus the playback latency)",
    NIDAQ_CLOCK: "the NI-DAQmx output task's start trigger timestamp, on the I/O device's timescale, seconds since "
                 "the Unix epoch",
    NIDAQ_SAMPLES_CLOCK: "the NI-DAQmx sample clock's count: samples the rig's completed output tasks generated "
                         "before this play / rate (stands still between plays)",
}


#: Longest output latency an onset may state, s (audio interfaces buffer tens of ms).
MAX_LATENCY_S = 2.0

_CLOCK_NAME = re.compile(r"[a-z][a-z0-9_]{0,39}")


def register_clock(name: str, meaning: str) -> None:
    """Name the device clock of a lab's own rig backend, so its onsets can be stored.

    Parameters
    ----------
    name : str
        1-40 characters: lower-case letters, digits and ``_``, starting with a letter
        (like the built-in names of :data:`CLOCKS`).
    meaning : str
        What its seconds count, as :data:`CLOCKS` says for the built-in clocks (it goes
        into the BIDS sidecar of every export).

    Raises
    ------
    ValidationError
        A malformed name, an empty meaning, or a built-in clock's name with another
        meaning.
    """
    if not isinstance(name, str) or not _CLOCK_NAME.fullmatch(name):
        raise ValidationError(f"a clock's name is 1-40 lower-case letters, digits or '_', starting with a letter, "
                              f"got {shorten(name)}")
    if not isinstance(meaning, str) or not meaning.strip():
        raise ValidationError(f"say what clock {name!r} counts (meaning), got {shorten(meaning)}")
    if CLOCKS.get(name, meaning) != meaning:
        raise ValidationError(f"clock {name!r} is already named, as {CLOCKS[name]!r}; choose another name")
    CLOCKS[name] = meaning


def check_onset(host_s: Any, device_s: Any, clock: Any, *, names: tuple[str, str, str] = ("host_s", "device_s", "clock"),
                host_required: bool = True) -> tuple[float | None, float | None, str | None]:
    """The one rule for an onset, wherever it is made or stored: finite seconds, a device
    time only with its clock, and a clock of :data:`CLOCKS` (:func:`register_clock` adds
    a lab's own).

    Parameters
    ----------
    host_s, device_s : float or None
        Seconds on the host's and on the device's clock.
    clock : str or None
        The device clock's name.
    names : (str, str, str)
        How errors name the three (the caller's argument names).
    host_required : bool
        Whether ``host_s`` may be None.

    Returns
    -------
    (float or None, float or None, str or None)

    Raises
    ------
    ValidationError
    """
    times = []
    for value, name, required in ((host_s, names[0], host_required), (device_s, names[1], False)):
        if value is None and not required:
            times.append(None)
            continue
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise ValidationError(f"{name} must be a finite number of seconds{'' if required else ' or None'}, "
                                  f"got {shorten(value)}")
        times.append(float(value))
    if (device_s is None) != (clock is None):
        raise ValidationError(f"{names[1]} and {names[2]} come together: give both or neither")
    if clock is not None and (not isinstance(clock, str) or clock not in CLOCKS):
        raise ValidationError(f"unknown device clock {shorten(clock)} for {names[2]}; expected one of "
                              f"{', '.join(CLOCKS)}, or a lab's own named with vibrofocus.rigs.register_clock")
    return times[0], times[1], clock


@dataclass(frozen=True)
class DeviceOnset:
    """The onset of one play: on the host's clock and, where the rig has one, on the device's.

    Attributes
    ----------
    host_s : float
        ``time.monotonic()`` when the backend handed the first samples to the device, s.
    device_s : float or None
        The first sample on the device's own clock, s; None when the rig has no device
        clock (or the device gives no time).
    clock : str or None
        The device clock's name, a key of :data:`CLOCKS`; None with ``device_s``.
    latency_s : float or None
        How long after ``host_s`` the first sample leaves the device's output, s, where the
        rig knows it (the audio rig: PortAudio's ``outputBufferDacTime - currentTime`` of
        the first callback; the simulated rig: 0); None where it does not. The LSL onset
        marker is stamped at ``host_s + latency_s``.
    xrun : bool
        Whether the device lost samples (an over- or underflow) while this play ran: the
        stimulus was not presented as designed. The audio rig raises
        :class:`~vibrofocus.rigs.devices.XrunError` for it, which carries this onset.
    """

    host_s: float
    device_s: float | None = None
    clock: str | None = None
    latency_s: float | None = None
    xrun: bool = False

    def __post_init__(self) -> None:
        check_onset(self.host_s, self.device_s, self.clock,
                    names=("an onset's host time", "an onset's device time", "its clock"))
        lat = self.latency_s
        if lat is not None and (isinstance(lat, bool) or not isinstance(lat, (int, float))
                                or not math.isfinite(lat) or not 0.0 <= lat <= MAX_LATENCY_S):
            raise ValidationError(f"an onset's latency must be None or 0-{MAX_LATENCY_S:g} s, got {shorten(lat)}")

    @property
    def output_host_s(self) -> float:
        """When the first sample left the device, on the host's clock, s (``host_s`` plus the
        latency where it is known)."""
        return self.host_s + (self.latency_s or 0.0)
