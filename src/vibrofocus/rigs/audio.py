"""The ``audio`` rig: a multichannel audio interface through sounddevice (PortAudio).

Many tactile labs drive their actuators from the line outputs of a multichannel audio
interface through a power amplifier and record the vibrometer decoder on one of its
inputs. This rig plays and records full-duplex in one PortAudio stream, so input and
output share the interface's sample clock.

Signal chain
------------
Drives are volts at the actuator. The interface puts out ``drive / amplifier_gain`` V,
i.e. a digital sample of ``drive / (amplifier_gain * volts_full_scale)``; an input sample
``s`` is ``s * input_volts_full_scale`` V at the input. When the device runs at another
rate than the rig's ``fs`` (most interfaces offer only 44.1/48/96 kHz), drives are
resampled up and recordings back down with :func:`scipy.signal.resample_poly`, a
linear-phase filter that adds no delay.

Latency
-------
The round trip from a digital output sample to the input sample that records it (the
converters' filters plus the driver's buffers) is not known in advance. When a loopback
is wired (a spare output cabled to a spare input), every recording plays a copy of its
strongest actuator drive on that output and the latency is the lag of the largest
cross-correlation between what was sent and what came back, in device samples; the
vibrometer recording is shifted by it. Without a loopback the rig uses
``latency_samples`` from the configuration, measured once at setup.

Host APIs that resample or mix behind the program's back (MME, DirectSound, WASAPI in
shared mode) do not keep one round trip from recording to recording, so on them a
loopback is required.

Streams
-------
The rig opens one full-duplex stream when it opens (not sounddevice's module-level
stream, which a cue tone could share) and keeps it running, writing silence, until it
closes (:mod:`vibrofocus.rigs.audio_stream`). A play or recording is scheduled into the
stream's callback at a frame index, the first buffer boundary after the drive is
converted; its onset is that frame on the device's clock, and the energy budget places
it at that frame's time at the outputs. Nothing is opened per play, and the stream runs
on after a drive, so its fade-out plays in full without padding. A play that took fewer
frames than it was given is refused. :meth:`AudioRig.stop`, from any thread, takes the
play off the callback, which writes silence from its next buffer: the outputs are
silent within one buffer plus the interface's buffered output latency
(:attr:`AudioRig.output_latency_s`). A recording buffer starts as zeros, never as
uninitialised memory. The stream's lost samples (xruns) during a play are flagged on its
onset (:attr:`~vibrofocus.rigs.DeviceOnset.xrun`) and refused with
:class:`~vibrofocus.rigs.XrunError`, which carries that onset.

Opening and closing the stream have deadlines; a server that stops answering (no
callback for :data:`~vibrofocus.rigs.audio_stream.STALL_S`) ends the play with
:class:`~vibrofocus.rigs.DeviceError`, and later plays are refused at once with what to
do: PortAudio cannot reconnect within the process (docs/hardware.md, "A hung or
restarted audio server").

Other programs on the interface
-------------------------------
A sound server mixes every program that plays to an output: a media player's signal
adds to the drive, past every limit of the rig. On JACK (and PipeWire's JACK) the rig
sees the connections of its playback ports (:mod:`vibrofocus.rigs.jack_guard`): its
running stream's own ports are connected there from its opening to its closing; a play
is refused before it starts when anything else is, and while it plays the rig looks
every :data:`POLL_S` and stops at zero when anything but its own stream feeds them;
either way it disconnects the other program and names it
(:class:`~vibrofocus.rigs.SharedOutputError`). Other host APIs give no way to see
other programs: ``vibrofocus devices --check`` says so (:func:`other_programs_report`),
and only a hardware limiter on the amplifier's input guards them.

Audio interfaces are AC-coupled, so this rig cannot read strap force sensors.
"""

from __future__ import annotations

import logging
import math
import re
import threading
import time
from fractions import Fraction

import numpy as np
import scipy.fft
import scipy.signal

from ..errors import SafetyError, ValidationError
from ..layout import ArrayLayout
from .config import AudioRigConfig
from .devices import DeviceError, SharedOutputError, StoppedError, XrunError
from .hardware import HardwareRig
from .onset import MAX_LATENCY_S, PORTAUDIO_CLOCK, DeviceOnset

__all__ = ["AudioRig", "resolve_audio_device", "audio_interface_words", "same_audio_interface",
           "default_output_risk", "audio_lock_keys", "other_programs_report"]

log = logging.getLogger(__name__)

#: A loopback whose normalised cross-correlation peak falls below this did not receive
#: the copy sent to it (cable unplugged, wrong channel).
MIN_LOOPBACK_CORRELATION = 0.5
#: Host APIs whose round trip changes between streams: a loopback is required there.
UNSTEADY_LATENCY_HOSTAPIS = ("mme", "directsound", "wasapi")
#: A recorded sample at or above this fraction of full scale counts as clipped.
CLIP_FRACTION = 0.999
#: The most inputs the rig's stream opens (every input of the interface, up to this many).
MAX_STREAM_INPUTS = 32
#: How often a waiting play looks whether it was stopped (and lets Ctrl-C in), s.
POLL_S = 0.02
#: The most a resampled drive may peak over the limit and be scaled back, not refused (fraction).
MAX_RESAMPLING_OVERSHOOT = 0.01
#: A play that has not ended this long after its block's length is given up, s.
STREAM_MARGIN_S = 2.0
#: A play is planned at the first buffer boundary at least this far ahead, s: the time to
#: convert a tap's drive for the device (a later start is placed where it played).
PLAN_MARGIN_S = 0.002
# Words that say how a device is reached, not which interface it is.
_GENERIC_WORDS = {
    "usb", "audio", "device", "devices", "output", "outputs", "input", "inputs", "speakers", "speaker",
    "headphones", "headphone", "line", "out", "in", "digital", "analog", "analogue", "asio", "wasapi", "mme",
    "directsound", "wdm", "ks", "driver", "hw", "the", "and", "of", "sound", "mapper", "primary", "microsoft",
    "playback", "capture", "stereo", "mono", "channels", "channel", "ch", "jack", "alsa", "core", "coreaudio",
}
# Devices that route to whatever the system mixes to: never a safe cue beside an audio rig.
_ROUTING_DEVICES = {"default", "sysdefault", "pulse", "pipewire", "dmix", "system"}
# Of those, the ones that mix through the system's sound server, whose round trip changes
# from stream to stream (JACK's "system" ports keep one: JACK is steady).
_MIXED_DEVICES = _ROUTING_DEVICES - {"system"}


def audio_interface_words(name: str) -> frozenset[str]:
    """The words that name an audio interface, whatever host API lists it.

    ``"Speakers (Focusrite USB Audio)"`` (MME), ``"Focusrite USB ASIO"`` and
    ``"Scarlett 2i2 USB: Audio (hw:1,0)"`` (ALSA) all give words that identify the
    interface ({"focusrite"}, {"scarlett", "2i2"}), leaving out host-API and generic words
    and ALSA's ``hw:`` numbers, and channel numbers (``"Out 1-2"``).
    """
    text = re.sub(r"\(hw:[^)]*\)", " ", name.lower())
    words = re.findall(r"[a-z0-9]+(?:[-_][a-z0-9]+)*", text)
    return frozenset(w for w in words if w not in _GENERIC_WORDS and not re.fullmatch(r"[0-9_-]+", w))


def same_audio_interface(a: str, b: str) -> bool:
    """Whether two device names may be the same interface (on any host API).

    Errs on the side of "the same": any shared identifying word, or a name that only
    routes to the system's mix (``default``, ``pulse``, ...), counts.
    """
    wa, wb = audio_interface_words(a), audio_interface_words(b)
    if wa & _ROUTING_DEVICES or wb & _ROUTING_DEVICES or not wa or not wb:
        return True
    return bool(wa & wb)


def default_output_risk(rig_device: str, default_device: str, *, same_index: bool = False) -> str | None:
    """Whether the system's default output may be the actuator interface.

    The participant page's beep plays on the browser's output, the system default,
    outside every check of the rig. Returns ``"same"`` when the default output is the
    interface (by index or by name), ``"routing"`` when it is a device that routes to the
    system's mix (``default``, ``pulse``, ...), which may reach it, and None otherwise.
    """
    default_words = audio_interface_words(default_device)
    if same_index:
        return "same"
    if default_words & _ROUTING_DEVICES or not default_words:
        return "routing"
    rig_words = audio_interface_words(rig_device)
    return "same" if rig_words and default_words & rig_words else None


def audio_lock_keys(name: str) -> list:
    """The device lock files of an audio interface, by the rule of :func:`same_audio_interface`.

    Two names that share an identifying word lock a common file (one per word), so every
    spelling of one interface is one lock. A name that only routes to the system's mix,
    or has no identifying word, is the same as any interface: it locks a file that every
    audio rig takes shared, exclusively.

    Parameters
    ----------
    name : str
        The device's name as its host API lists it.

    Returns
    -------
    list of LockKey
    """
    from .device_lock import LockKey

    words = audio_interface_words(name)
    if not words or words & _ROUTING_DEVICES:
        return [LockKey("audio-any")]
    return [LockKey("audio-any", shared=True)] + [LockKey(f"audio-word:{w}") for w in sorted(words)]


def other_programs_report(hostapi: str, device_name: str) -> str:
    """Whether the rig can see other programs that play to its interface, as one line.

    Parameters
    ----------
    hostapi : str
        The PortAudio host API's name.
    device_name : str
        The device's name as the host API lists it.

    Returns
    -------
    str
        What ``vibrofocus devices --check`` prints about it.
    """
    if "jack" in hostapi.lower():
        return ("other programs on the outputs: checked (JACK connections); a play is refused when another client "
                "is connected to the rig's playback ports, and stopped at zero when one connects while it plays; "
                "the rig disconnects it and names it")
    words = audio_interface_words(device_name)
    # Core Audio, and WASAPI in the shared mode PortAudio opens, mix every program on a device.
    mixers = (*UNSTEADY_LATENCY_HOSTAPIS, "core audio")
    mixed = bool(words & _ROUTING_DEVICES) or not words or any(h in hostapi.lower() for h in mixers)
    how = ("this device mixes other programs' sound into the outputs"
           if mixed else "other programs may play to this interface beside the rig")
    return (f"other programs on the outputs: NOT checked: {hostapi} gives no way to see who else plays to "
            f"{device_name}, and {how}, adding to the drives past the rig's limits; give the interface to the rig "
            "alone (exclusive mode, no system sounds) and put a limiter or mute on the amplifier's input "
            "(docs/hardware.md)")


def _problems(status) -> list[str]:
    """The samples-lost flags a stream reported, as people read them (empty: none)."""
    if not status:
        return []
    return [flag.replace("_", " ") for flag in ("input_overflow", "input_underflow", "output_overflow",
                                                 "output_underflow") if getattr(status, flag, False)]


def _sounddevice():
    try:
        import sounddevice as sd
    except OSError as exc:  # the PortAudio shared library is missing
        raise DeviceError(f"PortAudio is not installed ({exc}); install libportaudio2") from None
    return sd


def resolve_audio_device(name: str | int | None, hostapi: str | None = None, *, inputs: int = 0,
                         outputs: int = 0) -> int:
    """Find a PortAudio device by index or name and check it has enough channels.

    Parameters
    ----------
    name : str, int or None
        Device index, a case-insensitive substring of its name, or None for the default
        device (of ``hostapi`` when given).
    hostapi : str, optional
        Case-insensitive substring of the host API name ("JACK", "ASIO", ...).
    inputs, outputs : int
        Highest 1-based input / output channel the rig uses.

    Returns
    -------
    int
        The PortAudio device index.

    Raises
    ------
    DeviceError
        No such device, an ambiguous name, or too few channels; the message lists the
        devices there are.
    """
    sd = _sounddevice()
    devices = sd.query_devices()
    apis = sd.query_hostapis()

    def api_name(dev) -> str:
        return apis[dev["hostapi"]]["name"]

    listing = "; ".join(f"{d['index']}: {d['name']} ({api_name(d)})" for d in devices) or "none"
    pool = [d for d in devices if hostapi is None or hostapi.lower() in api_name(d).lower()]
    if hostapi is not None and not pool:
        raise DeviceError(f"no audio device on a host API matching {hostapi!r}; devices: {listing}")
    if name is None:
        if hostapi is None:
            idx = sd.default.device[1 if outputs else 0]
            if idx is None or idx < 0:
                raise DeviceError(f"there is no default audio device; name one of: {listing}")
        else:
            api = apis[pool[0]["hostapi"]]
            idx = api["default_output_device"] if outputs else api["default_input_device"]
            if idx is None or idx < 0:
                raise DeviceError(f"the host API {api['name']} has no default audio device; name one of: {listing}")
        dev = devices[idx]
    elif isinstance(name, int):
        matches = [d for d in pool if d["index"] == name]
        if not matches:
            raise DeviceError(f"no audio device with index {name}"
                              f"{' on ' + repr(hostapi) if hostapi else ''}; devices: {listing}")
        dev = matches[0]
    else:
        exact = [d for d in pool if d["name"].lower() == name.lower()]
        matches = exact or [d for d in pool if name.lower() in d["name"].lower()]
        if not matches:
            raise DeviceError(f"no audio device named like {name!r}; devices: {listing}")
        if len(matches) > 1:
            names = ", ".join(f"{d['index']}: {d['name']} ({api_name(d)})" for d in matches)
            raise DeviceError(f"audio device name {name!r} is ambiguous ({names}); give its index or a hostapi")
        dev = matches[0]
    if dev["max_output_channels"] < outputs or dev["max_input_channels"] < inputs:
        raise DeviceError(
            f"audio device {dev['index']}: {dev['name']} has {dev['max_output_channels']} outputs and "
            f"{dev['max_input_channels']} inputs; the rig uses output channels up to {outputs} and input "
            f"channels up to {inputs}"
        )
    return int(dev["index"])


class AudioRig(HardwareRig):
    """Actuators on the outputs of an audio interface, the vibrometer on one of its inputs.

    Parameters
    ----------
    config : AudioRigConfig
        Device, channel map, gain chain, vibrometer and limits.
    layout : ArrayLayout, optional
        The array; must have as many actuators as ``config.channels.actuators``.

    Attributes
    ----------
    device_index : int
        The PortAudio device.
    device_fs : float
        Rate the device runs at, Hz.
    last_latency_samples : int or None
        Round trip used to align the last recording, device samples.

    Notes
    -----
    A single-spot vibrometer: ``max_points_per_recording = 1``.
    """

    kind = "audio"
    config_class = AudioRigConfig

    def __init__(self, config: AudioRigConfig, layout: ArrayLayout | None = None):
        super().__init__(config, layout)
        self.device_fs = float(config.device.samplerate or config.fs)
        ratio = Fraction(self.device_fs / self.fs).limit_denominator(1000)
        if abs(float(ratio) - self.device_fs / self.fs) > 1e-9 * self.device_fs / self.fs:
            raise ValidationError(
                f"device samplerate {self.device_fs:g} Hz / rig fs {self.fs:g} Hz is not a simple ratio; "
                "choose rates with a ratio of small integers (e.g. 48000 / 10000 = 24/5)"
            )
        self._up, self._down = ratio.numerator, ratio.denominator
        ch = config.channels
        self._out_channels = list(ch.actuators) + ([ch.loopback_output] if ch.loopback_output else [])
        self._in_channels = [ch.vibrometer] + ([ch.loopback_input] if ch.loopback_input else [])
        self.device_index = resolve_audio_device(
            config.device.name, config.device.hostapi, inputs=max(self._in_channels), outputs=max(self._out_channels)
        )
        sd = _sounddevice()
        try:
            sd.check_output_settings(self.device_index, channels=max(self._out_channels), samplerate=self.device_fs)
            sd.check_input_settings(self.device_index, channels=max(self._in_channels), samplerate=self.device_fs)
        except sd.PortAudioError as exc:
            raise DeviceError(f"audio device {self.device_index} refuses {self.device_fs:g} Hz: {exc}; set "
                              "device.samplerate to a rate it supports") from None
        dev = sd.query_devices(self.device_index)
        self.device_name = str(dev["name"])
        self.hostapi_name = str(sd.query_hostapis(dev["hostapi"])["name"])
        # On JACK the rig watches who else feeds its playback ports (module docstring).
        self._jack_guard = None
        if "jack" in self.hostapi_name.lower():
            from .jack_guard import JackOutputGuard

            self._jack_guard = JackOutputGuard(self.device_name, self._out_channels)
        words = sorted(audio_interface_words(self.device_name)) or [self.device_name.lower()]
        try:
            self._lock_device("audio:" + "-".join(words), keys=audio_lock_keys(self.device_name))
        except BaseException:
            if self._jack_guard is not None:
                self._jack_guard.close()
            raise
        self.setup_report = [
            f"device {self.device_index}: {self.device_name} ({self.hostapi_name})",
            f"rate: device {self.device_fs:g} Hz, rig {self.fs:g} Hz (resampled {self._up}/{self._down})"
            if (self._up, self._down) != (1, 1) else f"rate: {self.fs:g} Hz",
            f"channels: actuators on outputs {', '.join(map(str, ch.actuators))}, vibrometer on input "
            f"{ch.vibrometer}" + (f", loopback output {ch.loopback_output} -> input {ch.loopback_input}"
                                  if ch.loopback_output else f", no loopback (latency {config.latency_samples} samples)"),
            f"output latency reported by the device: {1e3 * float(dev['default_low_output_latency']):.0f} ms",
            other_programs_report(self.hostapi_name, self.device_name),
        ]
        self.last_latency_samples: int | None = None
        self.last_clipped: np.ndarray | None = None
        self.last_dropout_mask: np.ndarray | None = None
        self._output_latency_s = 0.0
        # The running stream (module docstring, "Streams"), so stop() from any thread can
        # retire its play; the lock keeps that from racing a play being scheduled.
        self._stream = None
        self._stream_lock = threading.Lock()
        self._own_ports: dict[int, str] | None = None
        self._planned_frame: int | None = None
        # Every input opens with the stream, so a loopback capture may use any of them.
        self._n_in = max(max(self._in_channels), min(int(dev["max_input_channels"]), MAX_STREAM_INPUTS))
        try:
            self._open_stream()
        except BaseException:
            self.close()
            raise

    def close(self) -> None:
        """Stop, close the running stream (within its deadline), release the device, its lock and the JACK watch."""
        try:
            self.stop()
            stream, self._stream = self._stream, None
            if stream is not None:
                stream.close(settle_s=self._close_settle_s(stream))
        finally:
            try:
                super().close()
            finally:
                if self._jack_guard is not None:
                    self._close_guard()

    def _close_guard(self) -> None:
        # On a server that hangs, libjack's close waits for good: in a thread of its own,
        # abandoned after a deadline (it holds the client, which is then never collected,
        # so no collection at the process's exit waits on it either).
        from .audio_stream import CLOSE_DEADLINE_S, server_lost

        closer = threading.Thread(target=self._jack_guard.close, name="vibrofocus-jack-close", daemon=True)
        closer.start()
        closer.join(CLOSE_DEADLINE_S if server_lost() is None else 0.5)
        if closer.is_alive():
            log.error("the JACK connection watch did not close (the JACK server does not answer); abandoned")

    # ------------------------------------------------------------------ other programs
    @property
    def output_labels(self) -> dict[int, str]:
        """What each output channel the rig uses drives, ``{channel: "actuator 1"}`` (1-based)."""
        ch = self.config.channels
        labels = {c: f"actuator {i + 1}" for i, c in enumerate(ch.actuators)}
        if ch.loopback_output:
            labels.setdefault(ch.loopback_output, "the loopback output")
        return labels

    def check_outputs_alone(self) -> None:
        """Refuse when another program feeds the rig's outputs now; plays and disconnects nothing.

        What ``vibrofocus devices --check`` runs. On host APIs where other programs cannot
        be seen (every one but JACK) it does nothing: :func:`other_programs_report` says so.

        Raises
        ------
        SharedOutputError
            Another JACK client is connected to a playback port the rig uses.
        """
        if self._jack_guard is None:
            return
        from .jack_guard import shared_output_message

        feeds = self._jack_guard.feeds(self._own_ports)  # the rig's running stream is its own
        if feeds:
            raise SharedOutputError(shared_output_message(feeds, self.output_labels, when="check"))

    def _refuse_shared(self, own: dict[int, str] | None, when: str, halted: threading.Event | None = None) -> None:
        """Stop and disconnect when anything but the rig's own stream feeds its outputs (JACK only).

        ``own``: the stream's own ports once it has started (None before: then every
        connection is another program's). During a play, the stream's callback writes
        silence from its next buffer on (``halted``, as it does after :meth:`stop`), the
        other program is disconnected, and the stream is aborted (which returns only once
        JACK has played out what it had, several periods later).
        """
        guard = self._jack_guard
        feeds = guard.feeds(own)
        if not feeds:
            return
        from .jack_guard import shared_output_message

        if halted is not None:
            halted.set()
        failed = guard.disconnect(feeds)
        if when == "during":
            self._zero_outputs()
        message = shared_output_message(feeds, self.output_labels, when=when, failed=failed)
        (log.critical if failed else log.error)("%s", message)
        raise SharedOutputError(message)

    # ------------------------------------------------------------------ scaling
    @property
    def _digital_peak(self) -> float:
        # Digital level of the actuator limit (or the amplifier cap, if lower): the hard
        # ceiling of every sample sent.
        return self.max_amplifier_input_v / self.config.volts_full_scale

    def _to_device(self, drive: np.ndarray, n_tail: int) -> np.ndarray:
        """Checked actuator volts (n_act, n) -> device block (n_dev, n_out) float32."""
        total = np.pad(drive, ((0, 0), (0, n_tail)))
        digital = total / (self.config.amplifier_gain * self.config.volts_full_scale)
        if (self._up, self._down) != (1, 1):
            digital = scipy.signal.resample_poly(digital, self._up, self._down, axis=1)
        ceiling = self._digital_peak
        over = np.abs(digital).max(initial=0.0)
        if over > ceiling:
            # Resampling rebuilds the signal between the samples, and a drive whose samples
            # sit at the limit peaks a little above it there (0.03-0.2 % for the designs at
            # 10 -> 48 kHz). A uniform gain of under 1 % keeps the limit without distorting
            # the drive; a larger overshoot is a drive too sharp for the rate, refused.
            excess = over / ceiling - 1
            if excess > MAX_RESAMPLING_OVERSHOOT:
                raise SafetyError(
                    f"drive refused: resampled to the device's {self.device_fs:g} Hz it peaks {100 * excess:.2g} % over "
                    f"the limit between its samples (more than {100 * MAX_RESAMPLING_OVERSHOOT:g} %); it has content too "
                    "close to the rig's Nyquist frequency: band-limit it, or run the rig at the device's rate")
            log.debug("resampled drive peaks %.3g%% over the limit; scaled down by as much", 100 * excess)
            digital = digital * (ceiling / over)
        columns = [digital]
        if self.config.channels.loopback_output:
            strongest = int(np.argmax(np.sum(digital**2, axis=1)))
            columns.append(digital[strongest:strongest + 1])
        return np.ascontiguousarray(np.concatenate(columns).T, dtype=np.float32)

    def _from_device(self, recorded: np.ndarray, n_total: int) -> np.ndarray:
        """Aligned input samples (n_dev,) -> vibrometer volts at fs (n_total,)."""
        x = recorded.astype(float)
        if (self._up, self._down) != (1, 1):
            x = scipy.signal.resample_poly(x, self._down, self._up)
        if len(x) < n_total:
            x = np.pad(x, (0, n_total - len(x)))
        return x[:n_total] * self.config.input_volts_full_scale

    # ------------------------------------------------------------------ latency
    def _measure_latency(self, sent: np.ndarray, received: np.ndarray, max_lag: int) -> int:
        energy = float(np.dot(sent, sent))
        if energy == 0.0:
            # Nothing was sent to correlate with: keep the last or configured round trip.
            fallback = self.last_latency_samples if self.last_latency_samples is not None else (
                self.config.latency_samples or 0)
            return int(fallback)
        n = scipy.fft.next_fast_len(len(sent) + len(received), real=True)
        corr = scipy.fft.irfft(scipy.fft.rfft(received, n) * np.conj(scipy.fft.rfft(sent, n)), n)[: max_lag + 1]
        lag = int(np.argmax(corr))
        norm = np.sqrt(energy * float(np.dot(received, received)))
        quality = corr[lag] / norm if norm > 0 else 0.0
        if quality < MIN_LOOPBACK_CORRELATION:
            raise DeviceError(
                f"loopback input {self.config.channels.loopback_input} did not receive what output "
                f"{self.config.channels.loopback_output} sent (normalised correlation {quality:.2f} < "
                f"{MIN_LOOPBACK_CORRELATION}); check the loopback cable and channel numbers"
            )
        return lag

    # ------------------------------------------------------------------ backend
    def _check_status(self, status, what: str, onset: DeviceOnset | None = None) -> None:
        problems = _problems(status)
        if problems:
            log.error("audio stream reported %s while %s", ", ".join(problems), what)
            raise XrunError(
                onset, f"the audio stream reported {', '.join(problems)} while {what}: samples were lost, so the "
                "result is discarded (outputs are at zero); retry, close other programs, or raise the "
                "device's buffer size"
            )

    @property
    def output_latency_s(self) -> float:
        """Buffered output latency of the running stream, s (what a stop cannot recall).

        The larger of the host API's figure when the stream opened and the most the stream
        has measured since: how long after a callback the buffer it handed over ends playing
        (through JACK the host's figure is one period, the measured two to three).
        """
        stream = self._stream
        measured = stream.largest_ahead_s if stream is not None else 0.0
        return max(self._output_latency_s, measured)

    # ------------------------------------------------------------------ the running stream
    def _open_stream(self) -> None:
        """Open the rig's one stream and start it (silence until a play); within deadlines."""
        from .audio_stream import RunningStream

        sd = _sounddevice()
        guard = self._jack_guard
        # The output ports before the stream registers its own: the new ones are the rig's.
        before = guard.output_ports() if guard is not None else None
        stream = RunningStream(sd, self.device_index, self.device_fs, self._n_in, max(self._out_channels),
                               [c - 1 for c in self._out_channels], self.config.latency)
        try:
            self._own_ports = guard.own_ports(before, max(self._out_channels)) if guard is not None else None
            stream.start()
            if guard is not None:  # PortAudio connected each channel where the guard watches
                guard.check_routing(self._own_ports)
        except BaseException:
            stream.close(settle_s=self._close_settle_s(stream))
            raise
        self._output_latency_s = stream.output_latency_s
        self._stream = stream

    def _close_settle_s(self, stream) -> float:
        """How long a closing stream waits after its abort, s: on JACK, the graph round it causes.

        The server recomputes latencies at the end of the cycle after a connection changes,
        so three periods (PortAudio reports one as the JACK stream's output latency) and a
        margin for its notification thread; nothing on other host APIs.
        """
        if self._jack_guard is None:
            return 0.0
        return min(3.0 * stream.output_latency_s + 0.05, 1.0)

    def _running_stream(self, what: str):
        """The running stream, opened again if it died (a callback that stopped coming, a failed start)."""
        from .audio_stream import STALL_S, mark_lost, raise_if_lost

        raise_if_lost()
        stream = self._stream
        if stream is None:  # closed by an earlier failure to open
            self._open_stream()
            return self._stream
        if not stream.alive():
            # Its callback stopped coming: the server hung, stopped or restarted, and
            # PortAudio cannot reconnect within this process.
            mark_lost(f"the audio server stopped answering: the rig's stream got no callback for over {STALL_S:g} s "
                      f"before {what}")
            raise_if_lost()
        return stream

    def _clock(self) -> float:
        # The energy budget places a play at the time its first frame reaches the outputs:
        # the next buffer boundary after the drive's conversion, on the stream's frame axis.
        stream = self._stream
        if stream is None or not stream.alive():
            self._planned_frame = None
            return time.monotonic()
        frame, at_s = stream.plan(PLAN_MARGIN_S)
        self._planned_frame = frame
        return at_s

    def _run_stream(self, block: np.ndarray, record: bool, what: str) -> tuple[np.ndarray | None, object, DeviceOnset]:
        """Play ``block`` (n_frames, n_out) in the running stream from the planned frame; record if asked.

        Returns the recorded input (n_frames, n_in), zeros where nothing came, the
        stream's status flags over the block, and the onset of the block's first frame:
        ``time.monotonic()`` in the callback that wrote it, its ``outputBufferDacTime``
        (:data:`~vibrofocus.rigs.onset.PORTAUDIO_CLOCK`) and how far ahead of the callback
        that is (the latency).
        """
        from .audio_stream import Job, mark_lost, raise_if_lost

        sd = _sounddevice()
        stopped = self._stop_probe()  # the stop epoch of the play that called us (rigs.base)
        planned, self._planned_frame = self._planned_frame, None
        stream = self._running_stream(what)
        frame = planned if planned is not None else stream.plan(PLAN_MARGIN_S)[0]
        job = Job(block, frame, stopped, [c - 1 for c in self._in_channels] if record else None)
        own = self._own_ports
        guard = self._jack_guard
        try:
            if guard is not None:  # nothing but the rig's stream on its ports before the play
                self._refuse_shared(own, "before")
            with self._stream_lock:
                # Checked and scheduled under the lock stop() retires through: a stop before
                # this line is seen here, one after it finds the job to retire.
                if stopped():
                    raise StoppedError("recording" if record else "play")
                stream.schedule(job)
            deadline = time.monotonic() + (frame - stream.frame + job.total) / self.device_fs + STREAM_MARGIN_S
            while True:  # short waits: Ctrl-C, a stop and other programs' connections get in between them
                finished = job.done.wait(POLL_S)
                if stopped():
                    break
                if guard is not None:
                    self._refuse_shared(own, "during", job.halted)
                if finished:
                    break
                if stream.stalled() or time.monotonic() > deadline:
                    mark_lost(f"the audio interface stopped answering while {what} (no audio callback for "
                              f"{time.monotonic() - stream.last[0] if stream.last else 0:.1f} s): is the audio "
                              "server (JACK, the driver) still running?")
                    raise_if_lost()
        except sd.PortAudioError as exc:
            raise DeviceError(f"the audio interface failed while {what}: {exc}") from None
        finally:
            # Whatever ended the play (its end, an error, Ctrl-C), the callback writes
            # silence from its next buffer.
            stream.retire(job, wait=True)
        if job.actual_start is not None and job.actual_start > frame:
            # It reached the callback after its planned frame: the budget places it where it played.
            self.budget.delay_last((job.actual_start - frame) / self.device_fs)
        if stopped():
            raise StoppedError("recording" if record else "play")
        if job.error is not None:
            raise DeviceError(f"the audio callback failed while {what}: {job.error!r}") from job.error
        if job.pos < job.total:
            raise DeviceError(f"the audio interface took {job.pos} of the {job.total} frames while {what}; "
                              "the rest never played")
        host, dac, ahead = job.onset
        # How far ahead of the callback the first sample reaches the converter, by the
        # stream's own clock; where the host API gives no such times, the stream's latency.
        latency = ahead if math.isfinite(ahead) and 0.0 <= ahead <= MAX_LATENCY_S else self._output_latency_s
        latency = latency if math.isfinite(latency) and 0.0 <= latency <= MAX_LATENCY_S else None
        xrun = bool(_problems(job.status))
        onset = (DeviceOnset(host, dac, PORTAUDIO_CLOCK, latency_s=latency, xrun=xrun) if math.isfinite(dac)
                 else DeviceOnset(host, latency_s=latency, xrun=xrun))
        return job.recorded, job.status, onset

    def _play(self, drive: np.ndarray) -> DeviceOnset:
        # The stream runs on after the block: its fade-out plays in full, with no padding.
        _, status, onset = self._run_stream(self._to_device(drive, n_tail=0), record=False, what="playing")
        self._check_status(status, "playing", onset)
        return onset

    @property
    def unsteady_latency(self) -> bool:
        """Whether this device's round trip may change from stream to stream (then recordings need a loopback).

        Host APIs that resample or mix behind the program's back (MME, DirectSound, WASAPI
        shared), and ALSA devices that route through the system's mixer (``default``,
        ``pulse``, ``pipewire``, ``dmix``).
        """
        if any(h in self.hostapi_name.lower() for h in UNSTEADY_LATENCY_HOSTAPIS):
            return True
        return bool(audio_interface_words(self.device_name) & _MIXED_DEVICES)

    def _play_and_record(self, drive: np.ndarray, points_xy: np.ndarray | None, n_tail: int) -> np.ndarray:
        has_loopback = self.config.channels.loopback_output is not None
        if not has_loopback and self.unsteady_latency:
            # Checked here, not when the rig opens: a play-only rig (stimuli, no recordings)
            # does not need a steady round trip.
            raise DeviceError(
                f"{self.device_name} ({self.hostapi_name}) does not keep one round-trip latency from recording "
                "to recording, so latency_samples cannot align them; wire a loopback (channels.loopback_output "
                "and channels.loopback_input) or use ASIO, Core Audio, ALSA hw devices or JACK"
            )
        if not has_loopback and self.config.latency_samples is None:
            raise DeviceError(
                "the audio rig cannot align recordings: wire a loopback (channels.loopback_output and "
                "channels.loopback_input) or set latency_samples measured at setup"
            )
        n_total = drive.shape[1] + n_tail
        block = self._to_device(drive, n_tail)
        n_dev = len(block)
        max_lag = int(np.ceil(self.config.max_latency_s * self.device_fs))
        padded = np.concatenate([block, np.zeros((max_lag, block.shape[1]), np.float32)])
        for attempt in range(self.config.xrun_retries + 1):
            if attempt:  # every take plays the drive again: each counts against the budget
                self._admit(drive, "recording")
            recorded, status, _ = self._run_stream(padded, record=True, what="recording")
            try:
                self._check_status(status, "recording")
                break
            except DeviceError:
                if attempt == self.config.xrun_retries:
                    raise
                log.warning("recording %d of %d lost samples; taking it again", attempt + 1,
                            self.config.xrun_retries + 1)
        recorded = np.asarray(recorded, dtype=float)
        if has_loopback:
            lag = self._measure_latency(padded[:, -1].astype(float), recorded[:, 1], max_lag)
        else:
            lag = int(self.config.latency_samples)
            if lag > max_lag:
                raise DeviceError(f"latency_samples = {lag} is longer than max_latency_s allows ({max_lag})")
        self.last_latency_samples = lag
        vib = recorded[lag:lag + n_dev, 0]
        # A converter at full scale clipped the vibrometer signal: H from it would be wrong.
        self.last_clipped = np.array([bool(np.any(np.abs(vib) >= CLIP_FRACTION))])
        self.last_dropout_mask = np.zeros((1, n_total), dtype=bool)
        volts = self._from_device(vib, n_total)
        return self.vibrometer.to_displacement(volts, self.fs)[None, :]

    def _play_and_capture(self, drive: np.ndarray, input_channel: int) -> tuple[np.ndarray, float]:
        # One duplex stream that records only the loopback input, unaligned: where the
        # drive appears in it is the round trip of this stream.
        if input_channel > self._n_in:
            raise DeviceError(f"input {input_channel} is not among the {self._n_in} inputs of "
                              f"{self.device_name}")
        # The recording runs on past the drive, as long as the round trip may be.
        n_after = int(np.ceil(max(self._output_latency_s, 0.05) * self.device_fs)) + 4096
        block = self._to_device(drive, n_tail=0)
        block = np.concatenate([block, np.zeros((n_after, block.shape[1]), np.float32)])
        kept = self._in_channels
        self._in_channels = [input_channel]
        try:
            recorded, status, _ = self._run_stream(block, record=True, what=f"recording input {input_channel}")
        finally:
            self._in_channels = kept
        self._check_status(status, f"recording input {input_channel}")
        return np.asarray(recorded[:, 0], dtype=float), self.device_fs

    def _zero_outputs(self) -> None:
        # Emergency stop from any thread: the play leaves the callback, which writes
        # silence from its next buffer (it also sees the stop epoch itself, which Rig.stop
        # has moved before this runs); returns once that buffer has been written, or
        # after two buffers and 50 ms if the server does not answer.
        with self._stream_lock:
            stream = self._stream
            job = stream.job if stream is not None else None
            if job is not None:
                stream.retire(job)

    def describe(self) -> dict:
        """Settings to store beside a calibration (JSON-serialisable)."""
        out = super().describe()
        out.update(config=self.config.model_dump(mode="json"), device_index=self.device_index,
                   device_name=self.device_name, hostapi=self.hostapi_name, device_fs=self.device_fs, last_latency_samples=self.last_latency_samples,
                   vibrometer=self.vibrometer.describe())
        return out
