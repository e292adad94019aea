"""The participant's cue tone: the one sound that does not go through the safety layer.

A cue is a short tone in the participant's headphones before each stimulus. It is not a
drive, so it must never reach an actuator: :class:`CueTone` refuses any output device
that may be the actuator interface, by index and by the interface's name on every host
API (:func:`~vibrofocus.rigs.audio.same_audio_interface`), and refuses the devices that
only route to the system's mix (``default``, ``pulse``) while an audio rig is in use. It
plays in a stream of its own, never sounddevice's module-level stream, at a fixed low
level and length.
"""

from __future__ import annotations

import numpy as np

from ..errors import ValidationError

__all__ = ["CueTone"]

#: The tone: frequency (Hz), length (s), peak (digital full scale). Fixed on purpose.
CUE_HZ, CUE_S, CUE_PEAK = 1000.0, 0.1, 0.2


class CueTone:
    """A 1 kHz, 0.1 s cue on the participant's headphones, checked against the rig.

    Parameters
    ----------
    device : str or int
        The headphones' PortAudio output device (index or part of its name, as listed by
        ``vibrofocus devices``).
    rig : Rig, optional
        The study's rig. With an audio rig, a device that may be its interface is refused.

    Raises
    ------
    ValidationError
        If the device may be the interface that drives the actuators.
    DeviceError
        If there is no such device.
    """

    fs = 44_100

    def __init__(self, device: str | int, *, rig: object | None = None):
        from .audio import _sounddevice, resolve_audio_device, same_audio_interface

        sd = _sounddevice()
        self.index = resolve_audio_device(device, outputs=1)
        info = sd.query_devices(self.index)
        self.name = str(info["name"])
        # The device's own rate: a rate it does not run at would be resampled by the host
        # API, or refused (a JACK server at 48 kHz refuses 44.1 kHz streams).
        self.fs = int(round(float(info.get("default_samplerate") or self.fs)))
        rig_index = getattr(rig, "device_index", None)
        rig_name = getattr(rig, "device_name", None)
        if rig_index is not None and (self.index == rig_index or same_audio_interface(self.name, rig_name or "")):
            raise ValidationError(
                f"the cue device {device!r} ({self.name}) may be the audio interface that drives the actuators "
                f"({rig_name}, on any host API); name the participant's headphones on another interface instead "
                "(a cue must never reach an actuator)"
            )
        t = np.arange(int(CUE_S * self.fs)) / self.fs
        self.tone = (CUE_PEAK * np.sin(2 * np.pi * CUE_HZ * t) * np.hanning(t.size)).astype(np.float32)

    def __call__(self) -> None:
        """Play the tone; returns when it has played."""
        import threading

        from .audio import _sounddevice

        sd = _sounddevice()
        # A callback stream, as the rigs use: PortAudio's blocking writes crash on some
        # host APIs (JACK: a double free in its blocking-I/O ring buffer).
        block = np.concatenate([self.tone, np.zeros(int(0.05 * self.fs), np.float32)])  # the tone's end plays out
        pos = [0]
        done = threading.Event()

        def callback(outdata, frames, time_info, status):
            n = min(frames, len(block) - pos[0])
            outdata.fill(0)
            outdata[:n, 0] = block[pos[0]:pos[0] + n]
            pos[0] += n
            if pos[0] >= len(block):
                raise sd.CallbackStop

        with sd.OutputStream(samplerate=self.fs, device=self.index, channels=1, dtype="float32",
                             callback=callback, finished_callback=done.set):
            done.wait(len(block) / self.fs + 2.0)
