"""What every hardware rig (audio interface, NI-DAQmx) sets up from its config."""

from __future__ import annotations

import atexit
import logging
import weakref

import numpy as np

from ..errors import SafetyError, ValidationError
from ..layout import ArrayLayout
from .base import Rig
from .config import RigConfig
from .device_lock import DeviceLock, LockKey

__all__ = ["HardwareRig", "check_amplifier_input"]

log = logging.getLogger(__name__)

# Every hardware rig not yet closed: at the interpreter's exit each gets a last zero
# write, whatever thread was still playing (a daemon thread dies mid-play at exit, and an
# NI output holds its last value after the process is gone).
_OPEN_RIGS: "weakref.WeakSet[HardwareRig]" = weakref.WeakSet()


@atexit.register
def _zero_open_rigs() -> None:
    for rig in list(_OPEN_RIGS):
        try:
            rig.close()
        except Exception as exc:  # noqa: BLE001 - the others must still be zeroed
            log.critical("the last zero write of a %s rig at exit failed (%s): switch the amplifier off",
                         rig.kind, exc)


class HardwareRig(Rig):
    """A rig built from a validated :class:`~vibrofocus.rigs.config.RigConfig`.

    Checks that the config is of the backend's own kind and maps as many actuator
    channels as the layout has actuators, then takes the sample rate, the safety limits
    (at the actuator, amplifier gain included) and the vibrometer from the config.

    Parameters
    ----------
    config : RigConfig
        Of the subclass's ``config_class``.
    layout : ArrayLayout, optional
        The array; default the reference setup.
    """

    #: The config class this backend accepts.
    config_class: type[RigConfig] = RigConfig
    #: A single-spot vibrometer: the operator aims it at one point per recording.
    max_points_per_recording = 1
    #: A physical device: one job at a time (Rig.reserve), and one rig per device (DeviceLock).
    one_job_at_a_time = True

    def __init__(self, config: RigConfig, layout: ArrayLayout | None = None):
        if not isinstance(config, self.config_class):
            raise ValidationError(f"config must be a {self.config_class.__name__}, got {type(config).__name__}")
        layout = layout if layout is not None else ArrayLayout.reference()
        if layout.n_actuators != config.n_actuators:
            raise ValidationError(
                f"the rig config maps {config.n_actuators} actuator channel(s) but the layout has "
                f"{layout.n_actuators} actuators"
            )
        super().__init__(layout, fs=config.fs, limits=config.limits.build())
        # The limits come from the file; replacing them on the open rig would also drop
        # the energy budget's history (Rig.limits).
        self._limits_frozen = True
        self.config = config
        self.vibrometer = config.vibrometer.build()
        self.device_lock: DeviceLock | None = None
        #: What the checks at setup found, one line each (``vibrofocus devices --check``).
        self.setup_report: list[str] = []

    def limits_report(self) -> list[str]:
        """The limits this rig enforces, one line each, as people read them."""
        cfg, lim = self.config, self.limits
        return [
            f"amplifier: gain {cfg.amplifier_gain:g} V/V; at most {self.max_amplifier_input_v:g} V into it "
            f"(cap amplifier_input_max_v = {cfg.amplifier_input_max_v:g} V)",
            f"limits at the actuator: {lim.peak_v:g} V peak, {lim.rms_v:g} V RMS over any {lim.rms_window_s:g} s "
            f"(across plays), drives up to {lim.max_duration_s:g} s, {1e3 * lim.fade_s:g} ms fades",
        ]

    def _lock_device(self, device_id: str, keys: "list[LockKey] | None" = None) -> None:
        """Take the device for this rig until :meth:`close` (subclasses call it once they know the device).

        ``keys``: the lock files that stand for the device, when one device has several names
        (:class:`~vibrofocus.rigs.device_lock.LockKey`); default one, named after ``device_id``.
        """
        self.device_lock = DeviceLock(device_id, owner=f"a {self.kind} rig", keys=keys).acquire()
        _OPEN_RIGS.add(self)

    def close(self) -> None:
        """Release the device (outputs left at zero) and its lock."""
        try:
            super().close()
        finally:
            _OPEN_RIGS.discard(self)
            if self.device_lock is not None:
                self.device_lock.release()

    @property
    def max_amplifier_input_v(self) -> float:
        """The most any sample may put into the amplifier, V: the actuator limit over the gain, capped."""
        return min(self.config.output_peak_v, self.config.amplifier_input_max_v)

    def _check_output_level(self, drive: np.ndarray) -> None:
        check_amplifier_input(drive, self.config)


def check_amplifier_input(drive: np.ndarray, config: RigConfig) -> None:
    """Refuse a drive that needs more than ``amplifier_input_max_v`` into the amplifier.

    Independent of the limits at the actuator (a wrong gain must not get through).
    Used by every hardware rig before a play, and by ``play --dry-run`` from the config
    file alone, before the interface is there.

    Parameters
    ----------
    drive : ndarray, shape (n_actuators, n_samples)
        Volts at the actuators, V.
    config : RigConfig
    """
    volts = float(np.abs(drive).max(initial=0.0)) / config.amplifier_gain
    cap = config.amplifier_input_max_v
    if volts > cap * (1 + 1e-9):
        raise SafetyError(
            f"drive refused: it needs {volts:.4g} V into the amplifier, over amplifier_input_max_v = {cap:g} V"
        )
