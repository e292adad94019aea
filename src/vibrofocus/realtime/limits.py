"""Every location's tap against the rig's limits, before ``serve-osc`` listens.

A design the safety layer would refuse at the tap is found at start, with the locations
named, as a study finds its stimuli at planning (:func:`vibrofocus.studies.engine.check_stimulus`).
"""

from __future__ import annotations

from typing import Any

from ..errors import SafetyError

__all__ = ["check_designs"]


def check_designs(designer: Any, rig: Any) -> None:
    """Check the tap at every layout location of ``designer``'s method against ``rig``'s limits.

    Parameters
    ----------
    designer : TapDesigner
        Its method's designs at the layout's locations.
    rig : Rig
        The rig that will play them.

    Raises
    ------
    SafetyError
        One or more locations' taps break a limit a drive has by itself (peak, RMS over
        the short window, DC and slow content, the sustained limit played alone); the
        message names every such location and the first one's reason.
    """
    from ..studies.engine import check_stimulus

    refused: dict[int, str] = {}
    for location in designer.layout.location_numbers:
        try:
            check_stimulus(designer.drives_at(location), rig)
        except SafetyError as exc:
            refused[int(location)] = str(exc)
    if refused:
        first = next(iter(refused))
        where = ", ".join(str(k) for k in refused)
        raise SafetyError(
            f"the {designer.method} taps at location(s) {where} break the limits of the {getattr(rig, 'kind', '')} "
            f"rig, so they would be refused at every tap (location {first}: {refused[first]}); choose another "
            "--method or check the calibration")
