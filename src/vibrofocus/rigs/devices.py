"""What hardware is present: audio devices (PortAudio) and NI-DAQmx devices.

Also home of :class:`DeviceError`, raised when a device fails during use (a stream
over- or underflow, a driver error, an unknown device name).
"""

from __future__ import annotations

from dataclasses import dataclass, field

from ..errors import SafetyError, VibrofocusError

__all__ = ["DeviceError", "DeviceBusyError", "StoppedError", "SharedOutputError", "XrunError", "DeviceListing", "list_audio_devices", "list_nidaq_devices"]


class DeviceError(VibrofocusError):
    """A device is missing or failed while playing or recording; outputs were set to zero."""


class DeviceBusyError(DeviceError):
    """Another job (in this process or another one) is using the device; nothing was played."""


class StoppedError(DeviceError):
    """A play or recording ended early because ``rig.stop()`` was called; the outputs are at zero.

    Parameters
    ----------
    what : {"play", "recording"}
        What was stopped; a stopped recording is discarded.
    """

    def __init__(self, what: str = "play") -> None:
        super().__init__(f"the {what} was stopped before it ended (rig.stop()); the outputs are at zero"
                         + ("; it is discarded" if what == "recording" else ""))


class XrunError(DeviceError):
    """The stream lost samples (an over- or underflow) while a drive played: the result is discarded.

    Parameters
    ----------
    onset : DeviceOnset or None
        The onset of the play it happened in (its ``xrun`` is True), where it began.
    message : str
        What was lost, while doing what.

    Attributes
    ----------
    onset : DeviceOnset or None
        When the stimulus that had the xrun began: a caller that presents it again
        (a study's trial) knows which one it was.
    """

    def __init__(self, onset, message: str) -> None:
        super().__init__(message)
        self.onset = onset


class SharedOutputError(DeviceError, SafetyError):
    """Another program feeds the rig's outputs (a JACK client on its playback ports).

    JACK adds every signal connected to a port, so the actuators would get the drive plus
    the other program's signal, past the rig's limits. The play was refused before it
    started, or stopped with the rig's outputs at zero; the rig disconnected the other
    program where it could (the message says so). Both a :class:`~vibrofocus.rigs.DeviceError` and a
    :class:`~vibrofocus.errors.SafetyError`.
    """


@dataclass
class DeviceListing:
    """Devices of one kind and a note when they cannot be listed.

    Attributes
    ----------
    devices : list of dict
        One dict per device (keys depend on the kind).
    note : str or None
        Why the list is empty or incomplete (driver not installed, ...).
    """

    devices: list[dict] = field(default_factory=list)
    note: str | None = None


def list_audio_devices() -> DeviceListing:
    """List PortAudio devices with their host API, channel counts and default rate."""
    try:
        import sounddevice as sd
    except OSError as exc:  # the PortAudio library itself is missing
        return DeviceListing(note=f"PortAudio is not installed ({exc}); install libportaudio2")
    hostapis = sd.query_hostapis()
    out = []
    for dev in sd.query_devices():
        out.append({
            "index": dev["index"],
            "name": dev["name"],
            "hostapi": hostapis[dev["hostapi"]]["name"],
            "inputs": dev["max_input_channels"],
            "outputs": dev["max_output_channels"],
            "default_samplerate": dev["default_samplerate"],
        })
    return DeviceListing(out, None if out else "PortAudio found no audio devices")


def list_nidaq_devices() -> DeviceListing:
    """List NI-DAQmx devices (name, product type, AO/AI channels) if the driver is present."""
    try:
        import nidaqmx.system
        from nidaqmx.errors import DaqNotFoundError, DaqNotSupportedError
    except ImportError:
        return DeviceListing(note="the nidaqmx Python package is not installed")
    try:
        system = nidaqmx.system.System.local()
        devices = list(system.devices)
    except (DaqNotFoundError, DaqNotSupportedError, OSError):
        return DeviceListing(note="the NI-DAQmx driver is not installed on this machine (install it from ni.com)")
    out = []
    for dev in devices:
        out.append({
            "name": dev.name,
            "product_type": dev.product_type,
            "ao": [c.name for c in dev.ao_physical_chans],
            "ai": [c.name for c in dev.ai_physical_chans],
        })
    return DeviceListing(out, None if out else "NI-DAQmx is installed but reports no devices")
