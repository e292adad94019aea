"""When a play started, on the host's clock and on the device's own: :class:`DeviceOnset`.

:meth:`Rig.play <vibrofocus.rigs.Rig.play>` returns one per play. The host time is
``time.monotonic()``, the clock of the study engine and of the LSL markers; the device
time is the clock the samples themselves run on, named by :data:`CLOCKS`:

- ``simulated_samples``: the simulated rig's sample clock, the samples it has played
  before this one divided by its rate. It counts played samples only, so it stands
  still between plays.
- ``portaudio_dac``: PortAudio's ``outputBufferDacTime`` of the stream's first callback,
  the time the drive's first sample reaches the converter, on the stream's clock
  (``Pa_GetStreamTime``). On ALSA, Core Audio, ASIO and WASAPI that clock runs on
  between streams. Through JACK (PortAudio's JACK host API) it is JACK's frame time
  since the stream was opened, divided by the rate, plus the playback latency: every
  play opens its own stream, so on JACK it starts again near zero at each play.
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
from dataclasses import dataclass

from ..errors import ValidationError

__all__ = ["DeviceOnset", "CLOCKS", "SIMULATED_CLOCK", "PORTAUDIO_CLOCK", "NIDAQ_CLOCK", "NIDAQ_SAMPLES_CLOCK"]

SIMULATED_CLOCK = "simulated_samples"
PORTAUDIO_CLOCK = "portaudio_dac"
NIDAQ_CLOCK = "nidaq_start_trigger"
NIDAQ_SAMPLES_CLOCK = "nidaq_samples"
#: Every device clock an onset may name, with what its seconds count.
CLOCKS: dict[str, str] = {
    SIMULATED_CLOCK: "the simulated rig's sample clock: samples played before this play / rate (stands still "
                     "between plays)",
    PORTAUDIO_CLOCK: "PortAudio's outputBufferDacTime of the first callback, on the stream's clock (through JACK: "
                     "frame time since the stream opened / rate, plus the playback latency)",
    NIDAQ_CLOCK: "the NI-DAQmx output task's start trigger timestamp, on the I/O device's timescale, seconds since "
                 "the Unix epoch",
    NIDAQ_SAMPLES_CLOCK: "the NI-DAQmx sample clock's count: samples the rig's completed output tasks generated "
                         "before this play / rate (stands still between plays)",
}


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
    """

    host_s: float
    device_s: float | None = None
    clock: str | None = None

    def __post_init__(self) -> None:
        if not math.isfinite(self.host_s):
            raise ValidationError(f"an onset's host time must be finite, got {self.host_s!r}")
        if (self.device_s is None) != (self.clock is None):
            raise ValidationError("an onset's device time and clock come together: give both or neither")
        if self.device_s is not None and not math.isfinite(self.device_s):
            raise ValidationError(f"an onset's device time must be finite, got {self.device_s!r}")
        if self.clock is not None and self.clock not in CLOCKS:
            raise ValidationError(f"unknown device clock {self.clock!r}; expected one of {', '.join(CLOCKS)}")
