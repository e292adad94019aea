"""What every hardware rig (audio interface, NI-DAQmx) sets up from its config."""

from __future__ import annotations

from ..errors import ValidationError
from ..layout import ArrayLayout
from .base import Rig
from .config import RigConfig

__all__ = ["HardwareRig"]


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
        self.config = config
        self.vibrometer = config.vibrometer.build()
