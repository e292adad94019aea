"""Turn a rig name (``--rig simulated|audio|nidaq``) into a rig object."""

from __future__ import annotations

from .._validation import check_choice
from ..layout import ArrayLayout
from .base import Rig

__all__ = ["RIG_KINDS", "make_rig"]

RIG_KINDS = ("simulated", "audio", "nidaq")


def make_rig(
    kind: str = "simulated", *, config: object | None = None, seed: int | None = None,
    layout: ArrayLayout | None = None,
) -> Rig:
    """Build a rig by name.

    Parameters
    ----------
    kind : {"simulated", "audio", "nidaq"}
        Which backend.
    config : path or config object, optional
        Hardware settings (devices, channels, amplifier gain, vibrometer); ignored by the
        simulated rig.
    seed : int, optional
        Participant seed of the simulated forearm (default 0).
    layout : ArrayLayout, optional
        The array; default the reference setup.
    """
    check_choice(kind, "rig", RIG_KINDS)
    if kind == "simulated":
        from ..skin import SimulatedForearm  # imported here: the model is not needed for hardware

        return SimulatedForearm(seed=0 if seed is None else seed, layout=layout)
    raise NotImplementedError(f"the {kind} rig is not available yet")
