"""Rigs: one interface for the simulated forearm and real hardware, one safety layer."""

from .base import Rig
from .config import AudioRigConfig, NidaqRigConfig, RigConfig, load_rig_config, parse_rig_config
from .device_lock import DeviceLock, LockKey
from .devices import (DeviceBusyError, DeviceError, SharedOutputError, StoppedError, XrunError, list_audio_devices,
                      list_nidaq_devices)
from .factory import RIG_KINDS, load_layout, make_rig
from .hardware import HardwareRig
from .onset import CLOCKS, DeviceOnset, register_clock
from .force import ForceCurve, StrapReading, StrapSensors, check_straps, evaluate_straps, has_strap_sensors
from .safety import EnergyBudget, SafetyLimits, check_drive
from .vibrometer import Vibrometer

# AudioRig and NidaqRig are imported lazily (make_rig, or vibrofocus.rigs.audio / .nidaq)
# so importing vibrofocus does not load PortAudio or the NI driver.
__all__ = [
    "Rig", "HardwareRig", "DeviceOnset", "CLOCKS", "register_clock", "SafetyLimits", "EnergyBudget", "check_drive", "make_rig", "load_layout", "RIG_KINDS",
    "DeviceLock", "LockKey", "DeviceBusyError", "StoppedError", "SharedOutputError", "XrunError",
    "RigConfig", "AudioRigConfig", "NidaqRigConfig", "load_rig_config", "parse_rig_config",
    "Vibrometer", "ForceCurve", "StrapSensors", "StrapReading", "check_straps", "evaluate_straps", "has_strap_sensors",
    "DeviceError", "list_audio_devices", "list_nidaq_devices",
]


def __getattr__(name: str):
    # The simulated rig loads the arm's physics (vibrofocus.skin): on first use only, so
    # that importing the rigs loads no model.
    if name == "SimulatedForearm":
        from .simulated import SimulatedForearm

        return SimulatedForearm
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
