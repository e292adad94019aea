"""Rigs: one interface for the simulated forearm and real hardware, one safety layer."""

from .base import Rig
from .factory import RIG_KINDS, make_rig
from .safety import SafetyLimits, check_drive

__all__ = ["Rig", "SafetyLimits", "check_drive", "make_rig", "RIG_KINDS"]
