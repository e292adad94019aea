"""Hardware rig configuration: pydantic models loaded from a TOML or JSON file.

A rig file says which device to open, which channels carry the actuators and the
vibrometer, how the analog chain scales (interface volts at full scale, amplifier gain),
how the vibrometer decoder reads out and which safety limits hold **at the actuator**.
The device output range follows from the limits and the gain: an actuator limit of
``peak_v`` needs ``peak_v / amplifier_gain`` volts at the interface, which must fit in
what the interface can put out (otherwise the drive would clip and the file is refused).

Example (``examples/rigs/audio.toml``)::

    kind = "audio"
    fs = 10000.0
    amplifier_gain = 10.0          # V/V (20 dB)
    volts_full_scale = 1.0         # V peak at the interface output for a digital 1.0 (measured)
    [device]
    name = "loopback"
    hostapi = "JACK"
    [channels]
    actuators = [1, 2, 3, 4]
    vibrometer = 1
    [vibrometer]
    decoder = "velocity"
    sensitivity = 0.005            # (m/s)/V, i.e. 5 mm/s/V

Channel numbers of audio interfaces are 1-based, as printed on the interface; NI
channels are physical channel names (``"ao0"`` or ``"Dev1/ao0"``).
"""

from __future__ import annotations

import json
import re
import tomllib
from pathlib import Path
from typing import Annotated, Any, Literal, Union

import pydantic
from pydantic import BaseModel, ConfigDict, Field, PositiveFloat, field_validator, model_validator

from ..errors import ValidationError
from .safety import (DURATION_S_CEILING, MAX_FADE_S, MIN_FADE_S, PEAK_V_CEILING, RMS_V_CEILING,
                     SUSTAINED_RMS_V_CEILING, SafetyLimits, written_ceiling)

__all__ = [
    "RigConfig",
    "AudioRigConfig",
    "NidaqRigConfig",
    "VibrometerConfig",
    "ForceSensorsConfig",
    "LimitsConfig",
    "load_rig_config",
    "parse_rig_config",
]


class _Model(BaseModel):
    # Unknown keys are refused: a misspelt "amplifer_gain" must not silently fall back to
    # a default that changes the voltage at the actuator.
    # NaN and infinities are refused everywhere: "amplifier_gain = inf" is a typo, not a gain.
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)


class VibrometerConfig(_Model):
    """Laser Doppler vibrometer decoder.

    Attributes
    ----------
    decoder : {"velocity", "displacement"}
        What the decoder's analog output is proportional to.
    sensitivity : float
        Decoder scale per volt in SI units: (m/s)/V for a velocity decoder (5 mm/s/V is
        0.005), m/V for a displacement decoder (1 µm/V is 1e-6).
    highpass_hz : float or None
        Corner of the zero-phase high-pass applied when turning volts into displacement,
        Hz; keeps the integration of velocity from drifting. Keep it well below the
        calibrated band (default 3 Hz for a band starting at 10 Hz). None disables it.
    """

    decoder: Literal["velocity", "displacement"]
    sensitivity: PositiveFloat
    highpass_hz: PositiveFloat | None = 3.0

    def build(self):
        """Return the :class:`~vibrofocus.rigs.vibrometer.Vibrometer` this describes."""
        from .vibrometer import Vibrometer

        return Vibrometer(self.decoder, self.sensitivity, highpass_hz=self.highpass_hz)


class ForceCurveConfig(_Model):
    """Calibration table of a force-sensing resistor: volts at the input -> newtons.

    Interpolated piecewise-linearly (see :class:`~vibrofocus.rigs.force.ForceCurve`).
    """

    volts: list[float] = Field(min_length=2)
    newtons: list[float] = Field(min_length=2)

    @model_validator(mode="after")
    def _check_table(self) -> "ForceCurveConfig":
        from .force import ForceCurve

        try:
            ForceCurve(self.volts, self.newtons)
        except ValidationError as exc:
            raise ValueError(str(exc)) from None
        return self


class ForceSensorsConfig(_Model):
    """Force-sensing resistors on the straps, read through analog inputs.

    Attributes
    ----------
    channels : list of str
        One analog input per strap (NI physical channel names).
    names : list of str, optional
        Strap labels; default ``strap 1..n``.
    curve : ForceCurveConfig, optional
        Volts -> newtons table; default the divider model of
        :meth:`~vibrofocus.rigs.force.ForceCurve.default`.
    target_n, tolerance_n : float
        The strap tension asked for before calibration and the accepted deviation, N.
    averaging_s : float
        How long a reading averages, s.
    """

    channels: list[str] = Field(min_length=1)
    names: list[str] | None = None
    curve: ForceCurveConfig | None = None
    target_n: PositiveFloat = 1.0
    tolerance_n: PositiveFloat = 0.25
    averaging_s: PositiveFloat = 0.25

    @model_validator(mode="after")
    def _check_names(self) -> "ForceSensorsConfig":
        if self.names is not None and len(self.names) != len(self.channels):
            raise ValueError(f"names has {len(self.names)} entries but channels has {len(self.channels)}")
        if len(set(self.channels)) != len(self.channels):
            raise ValueError(f"channels must be distinct, got {self.channels}")
        return self

    def build(self):
        """Return the :class:`~vibrofocus.rigs.force.StrapSensors` this describes."""
        from .force import ForceCurve, StrapSensors

        curve = ForceCurve(self.curve.volts, self.curve.newtons) if self.curve else ForceCurve.default()
        names = self.names or [f"strap {i + 1}" for i in range(len(self.channels))]
        return StrapSensors(names=tuple(names), curve=curve, target_n=self.target_n, tolerance_n=self.tolerance_n)


class LimitsConfig(_Model):
    """Safety limits at the actuator terminals (see :class:`~vibrofocus.rigs.safety.SafetyLimits`).

    Each has a hard ceiling no file can raise: ``peak_v`` <= 20 V, ``rms_v`` <= 5.66 V
    (sqrt(32) = 5.65685 V, twice the assumed 2 W rating in power; 5.66 is taken as it), ``sustained_rms_v`` <= 4 V over
    ``sustained_window_s`` in [10, 600] s, ``max_duration_s`` <= 60 s, and ``fade_s`` in
    [0.1 ms, 50 ms].
    """

    peak_v: float = Field(SafetyLimits.peak_v, gt=0, le=PEAK_V_CEILING)
    rms_v: float = Field(SafetyLimits.rms_v, gt=0, le=written_ceiling(RMS_V_CEILING))  # 5.66 as the docs write it
    max_duration_s: float = Field(SafetyLimits.max_duration_s, gt=0, le=DURATION_S_CEILING)
    fade_s: float = Field(SafetyLimits.fade_s, ge=MIN_FADE_S, le=MAX_FADE_S)
    sustained_rms_v: float = Field(SafetyLimits.sustained_rms_v, gt=0, le=SUSTAINED_RMS_V_CEILING)
    sustained_window_s: float = Field(SafetyLimits.sustained_window_s, ge=10.0, le=600.0)

    def build(self) -> SafetyLimits:
        return SafetyLimits(peak_v=self.peak_v, rms_v=self.rms_v, max_duration_s=self.max_duration_s, fade_s=self.fade_s,
                            sustained_rms_v=self.sustained_rms_v, sustained_window_s=self.sustained_window_s)


class RigConfig(_Model):
    """Settings common to every hardware rig; load files with :func:`load_rig_config`.

    Attributes
    ----------
    kind : {"audio", "nidaq"}
        Which backend; picks :class:`AudioRigConfig` or :class:`NidaqRigConfig`.
    fs : float
        Sample rate of drives and recordings, Hz.
    amplifier_gain : float
        Voltage gain of the power amplifier between the interface and the actuators, V/V
        (10 for 20 dB), in (0, 1000]. Drives are actuator volts; the interface puts out
        drive / gain.
    amplifier_input_max_v : float
        Independent cap on the voltage into the amplifier, V, in (0, 10]; default 1 V
        (the reference setup's 1 V into a 20 dB amplifier). No sample sent to the
        interface exceeds it, whatever the gain says, and it is the NI output range. A
        config whose ``limits.peak_v / amplifier_gain`` exceeds it is refused, so a gain
        entered as 1 instead of 10 cannot put 10 V into the amplifier.
    vibrometer : VibrometerConfig
    limits : LimitsConfig
        Safety limits at the actuator.
    """

    kind: str
    fs: float = Field(10_000.0, gt=0, le=1e6)
    amplifier_gain: float = Field(10.0, gt=0, le=1000)
    amplifier_input_max_v: float = Field(1.0, gt=0, le=10)
    vibrometer: VibrometerConfig
    limits: LimitsConfig = LimitsConfig()

    def _refuse_peak_over(self, ceiling_v: float, name: str, where: str, advice: str) -> None:
        """Refuse a ``limits.peak_v`` that needs more than ``ceiling_v`` at the interface."""
        need = self.output_peak_v
        if need > ceiling_v * (1 + 1e-9):
            raise ValueError(
                f"limits.peak_v = {self.limits.peak_v:g} V at the actuator needs {need:g} V {where} "
                f"(amplifier_gain = {self.amplifier_gain:g}), more than {name} = {ceiling_v:g} V. {advice} "
                f"limits.peak_v to at most {ceiling_v * self.amplifier_gain:g} V"
            )

    @model_validator(mode="after")
    def _check_amplifier_cap(self) -> "RigConfig":
        self._refuse_peak_over(self.amplifier_input_max_v, "amplifier_input_max_v", "into the amplifier",
                               "Check amplifier_gain (10 for 20 dB); if it is right, lower")
        return self

    @property
    def n_actuators(self) -> int:
        return len(self.channels.actuators)  # type: ignore[attr-defined]

    @property
    def output_peak_v(self) -> float:
        """Largest voltage the interface is ever asked for: the actuator limit over the gain, V."""
        return self.limits.peak_v / self.amplifier_gain

    @classmethod
    def from_file(cls, path: str | Path) -> "AudioRigConfig | NidaqRigConfig":
        """Same as :func:`load_rig_config`."""
        return load_rig_config(path)


class AudioDeviceConfig(_Model):
    """Which PortAudio device to open.

    Attributes
    ----------
    name : str or int, optional
        Device index or a case-insensitive substring of its name (as listed by
        ``vibrofocus devices``); default the system default device.
    hostapi : str, optional
        Substring of the host API name ("ASIO", "Core Audio", "JACK", "ALSA") to choose
        among devices of the same name.
    samplerate : float, optional
        Rate to run the device at, Hz, when it cannot run at the rig's ``fs`` (most audio
        interfaces run at 44.1/48/96 kHz); drives and recordings are resampled.
    """

    name: str | int | None = None
    hostapi: str | None = None
    samplerate: PositiveFloat | None = None


class AudioChannelsConfig(_Model):
    """Channel map of an audio interface, 1-based as printed on the interface.

    Attributes
    ----------
    actuators : list of int
        Output channel of each actuator, in actuator order.
    vibrometer : int
        Input channel wired to the vibrometer decoder.
    loopback_output, loopback_input : int, optional
        A spare output wired straight back to a spare input. On every recording the rig
        plays a copy of the strongest actuator drive on ``loopback_output`` and finds the
        round-trip latency by cross-correlating what ``loopback_input`` received.
    """

    actuators: list[Annotated[int, Field(ge=1)]] = Field(min_length=1)
    vibrometer: int = Field(ge=1)
    loopback_output: int | None = Field(None, ge=1)
    loopback_input: int | None = Field(None, ge=1)

    @model_validator(mode="after")
    def _check(self) -> "AudioChannelsConfig":
        if len(set(self.actuators)) != len(self.actuators):
            raise ValueError(f"actuators must use distinct output channels, got {self.actuators}")
        if (self.loopback_output is None) != (self.loopback_input is None):
            raise ValueError("loopback_output and loopback_input go together: set both or neither")
        if self.loopback_output is not None and self.loopback_output in self.actuators:
            raise ValueError(f"loopback_output {self.loopback_output} is also an actuator output")
        if self.loopback_input is not None and self.loopback_input == self.vibrometer:
            raise ValueError(f"loopback_input {self.loopback_input} is also the vibrometer input")
        return self


class AudioRigConfig(RigConfig):
    """A multichannel audio interface through sounddevice (PortAudio).

    Attributes
    ----------
    device : AudioDeviceConfig
    channels : AudioChannelsConfig
    volts_full_scale : float
        Output voltage for a digital sample of 1.0, V peak. Required, and measured, not
        read off a data sheet: professional interfaces put out several volts at digital
        full scale (their output trims and level switches change it), and every limit
        into the amplifier is only as right as this number. Measure it with
        ``vibrofocus devices --check --tone`` and a voltmeter (docs/hardware.md,
        first-day checklist).
    input_volts_full_scale : float
        Input voltage that reads as a digital 1.0, V.
    latency_samples : int, optional
        Round trip output -> input in device samples, measured once at setup; used when
        no loopback channel is wired (the loopback measurement wins when there is one).
    max_latency_s : float
        Longest round trip searched for, s; the recording runs this much longer.
    xrun_retries : int
        A recording during which the stream lost samples (an input overflow or output
        underflow) is discarded and taken again up to this many times before the rig
        raises. A participant stimulus (``play``) is never repeated. Every take counts
        against the energy budget.
    latency : {"low", "high"} or float
        Output latency PortAudio opens streams with (its suggested latency, or seconds):
        what a stop cannot recall. Default "low"; the setup report prints the latency
        each stream really got.
    """

    kind: Literal["audio"]
    device: AudioDeviceConfig = AudioDeviceConfig()
    channels: AudioChannelsConfig
    volts_full_scale: PositiveFloat
    input_volts_full_scale: PositiveFloat = 1.0
    latency_samples: int | None = Field(None, ge=0)
    max_latency_s: PositiveFloat = 0.25
    xrun_retries: int = Field(2, ge=0, le=10)
    latency: Literal["low", "high"] | Annotated[float, Field(gt=0, le=1.0)] = "low"

    @model_validator(mode="before")
    @classmethod
    def _no_force_sensors(cls, data: Any) -> Any:
        if isinstance(data, dict) and "force_sensors" in data:
            raise ValueError(
                "force_sensors: audio interfaces are AC-coupled and cannot read the steady voltage of "
                "force-sensing resistors; read the straps with an nidaq rig"
            )
        return data

    @model_validator(mode="after")
    def _check_level(self) -> "AudioRigConfig":
        self._refuse_peak_over(self.volts_full_scale, "volts_full_scale", "at the interface",
                               "Drives would clip: raise amplifier_gain, or lower")
        return self


class NidaqChannelsConfig(_Model):
    """NI-DAQmx physical channels (``"ao0"`` or ``"Dev1/ao0"``).

    Attributes
    ----------
    actuators : list of str
        Analog output of each actuator, in actuator order.
    vibrometer : str
        Analog input wired to the vibrometer decoder.
    """

    actuators: list[str] = Field(min_length=1)
    vibrometer: str

    @field_validator("actuators")
    @classmethod
    def _distinct(cls, value: list[str]) -> list[str]:
        if len(set(value)) != len(value):
            raise ValueError(f"actuators must use distinct analog outputs, got {value}")
        for ch in value:
            if "ao" not in ch.rsplit("/", 1)[-1]:
                raise ValueError(f"actuator channel {ch!r} is not an analog output (expected a name like 'ao0')")
        return value

    @field_validator("vibrometer")
    @classmethod
    def _is_ai(cls, value: str) -> str:
        if "ai" not in value.rsplit("/", 1)[-1]:
            raise ValueError(f"vibrometer channel {value!r} is not an analog input (expected a name like 'ai0')")
        return value


class NidaqRigConfig(RigConfig):
    """An NI-DAQmx device: analog outputs for the actuators, analog inputs for the sensors.

    Attributes
    ----------
    device : str
        Device name in NI MAX, e.g. ``"Dev1"``; prefixes channel names given without one.
    channels : NidaqChannelsConfig
    ao_max_v : float
        Largest output voltage the AO channels support, V (10 on most devices).
    ai_range_v : float
        Vibrometer input range, ±V.
    terminal_config : {"default", "rse", "nrse", "diff", "pseudo_diff"}
        Input terminal configuration of the analog inputs.
    latency_samples : int
        Known input delay in samples (the anti-aliasing filter delay of delta-sigma
        devices such as the NI 4431; 0 for SAR multifunction devices); removed from
        every recording.
    force_sensors : ForceSensorsConfig, optional
    """

    kind: Literal["nidaq"]
    device: str = "Dev1"
    channels: NidaqChannelsConfig
    ao_max_v: PositiveFloat = 10.0
    ai_range_v: PositiveFloat = 10.0
    terminal_config: Literal["default", "rse", "nrse", "diff", "pseudo_diff"] = "default"
    latency_samples: int = Field(0, ge=0)
    force_sensors: ForceSensorsConfig | None = None

    @model_validator(mode="after")
    def _check_level(self) -> "NidaqRigConfig":
        if self.amplifier_input_max_v > self.ao_max_v:
            raise ValueError(
                f"amplifier_input_max_v = {self.amplifier_input_max_v:g} V is more than the analog outputs can "
                f"put out (ao_max_v = {self.ao_max_v:g} V); it is also their range"
            )
        return self

    @model_validator(mode="after")
    def _one_device(self) -> "NidaqRigConfig":
        # Input and output are synchronised through one timebase and one start trigger:
        # one device, or the modules of one CompactDAQ chassis (cDAQ1Mod1, cDAQ1Mod2),
        # whose triggers are routed through the chassis backplane.
        devices = sorted({self.physical(ch).split("/")[0] for ch in self._all_channels()})
        chassis = {_chassis_of(d) for d in devices}
        if len(devices) > 1 and (len(chassis) > 1 or None in chassis):
            raise ValueError(
                f"channels are on {len(devices)} devices ({', '.join(devices)}): actuators and vibrometer must be "
                f"on one device, or on modules of one CompactDAQ chassis (cDAQ1Mod1, cDAQ1Mod2), to be "
                f"sample-synchronous; put them all on {self.device}"
            )
        return self

    def _all_channels(self) -> list[str]:
        names = list(self.channels.actuators) + [self.channels.vibrometer]
        if self.force_sensors:
            names += list(self.force_sensors.channels)
        return names

    def physical(self, channel: str) -> str:
        """Full physical channel name, ``"Dev1/ao0"`` for ``"ao0"``."""
        return channel if "/" in channel else f"{self.device}/{channel}"

    @property
    def timing_device(self) -> str:
        """The device whose timebase and triggers the tasks share: the chassis of cDAQ modules, else the device."""
        first = self.physical(self.channels.actuators[0]).split("/")[0]
        return _chassis_of(first) or first


def _chassis_of(device: str) -> str | None:
    """The CompactDAQ chassis of a module name (``"cDAQ1"`` for ``"cDAQ1Mod2"``), else None."""
    match = re.fullmatch(r"(.+?)Mod\d+", device)
    return match.group(1) if match else None


_ANY_CONFIG = pydantic.TypeAdapter(
    Annotated[Union[AudioRigConfig, NidaqRigConfig], Field(discriminator="kind")]
)


def _format_errors(exc: pydantic.ValidationError) -> str:
    parts = []
    for err in exc.errors():
        # The first loc entry of a discriminated union is the tag ("audio"); drop it.
        loc = [str(p) for p in err["loc"]]
        if loc and loc[0] in ("audio", "nidaq"):
            loc = loc[1:]
        where = ".".join(loc)
        msg = err["msg"].removeprefix("Value error, ")
        if err["type"] == "extra_forbidden":
            msg = "unknown setting (check the spelling)"
        elif err["type"] == "missing" and loc == ["volts_full_scale"]:
            msg = ("required: the interface's output in V peak at digital full scale. Measure it: set "
                   "volts_full_scale = 1.0 for now, then `vibrofocus devices --check FILE --tone` plays a known "
                   "low digital level whatever the value; read it with a voltmeter, amplifier off "
                   "(docs/hardware.md, first-day checklist)")
        elif err["type"] == "union_tag_invalid":
            where, msg = "kind", f"must be 'audio' or 'nidaq', got {err['ctx']['tag']!r}"
        parts.append(f"{where}: {msg}" if loc or err["type"] == "union_tag_invalid" else msg)
    return "; ".join(parts)


def parse_rig_config(data: Any, *, source: str = "rig config") -> AudioRigConfig | NidaqRigConfig:
    """Validate a mapping (as read from a file) into the config of its ``kind``.

    Parameters
    ----------
    data : dict or RigConfig
        Settings as read from a TOML/JSON file; a config passes through.
    source : str
        Where the settings came from, for the error messages.

    Returns
    -------
    AudioRigConfig or NidaqRigConfig

    Raises
    ------
    ValidationError
        Naming each bad setting by its dotted path.
    """
    if isinstance(data, RigConfig):
        return data  # type: ignore[return-value]
    if not isinstance(data, dict):
        raise ValidationError(f"{source}: must be a table of settings, got {type(data).__name__}")
    if "kind" not in data:
        raise ValidationError(f"{source}: kind is missing; set kind = \"audio\" or kind = \"nidaq\"")
    try:
        return _ANY_CONFIG.validate_python(data)
    except pydantic.ValidationError as exc:
        raise ValidationError(f"{source}: {_format_errors(exc)}") from None


def load_rig_config(path: str | Path) -> AudioRigConfig | NidaqRigConfig:
    """Read a rig configuration file (``.toml`` or ``.json``).

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    AudioRigConfig or NidaqRigConfig
        Chosen by the file's ``kind``.

    Raises
    ------
    ValidationError
        Missing or unreadable file, syntax error (with its line), unknown or bad setting.
    """
    p = Path(path)
    if not p.is_file():
        raise ValidationError(f"rig config {p}: no such file")
    suffix = p.suffix.lower()
    try:
        text = p.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise ValidationError(f"rig config {p}: cannot read it ({exc})") from None
    if suffix == ".toml":
        try:
            data = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise ValidationError(f"rig config {p}: not valid TOML ({exc})") from None
    elif suffix == ".json":
        try:
            data = json.loads(text)
        except json.JSONDecodeError as exc:
            raise ValidationError(f"rig config {p}: not valid JSON ({exc})") from None
    else:
        raise ValidationError(f"rig config {p}: unknown file type {suffix or '(none)'!r}; use .toml or .json")
    return parse_rig_config(data, source=f"rig config {p}")
