"""Every location's tap against the rig's limits, before ``serve-osc`` listens.

A design the safety layer would refuse at the tap is found at start, with the locations
named and the level (dB re the design, the ``/tap`` level argument) at which each one
fits, as a study finds its stimuli at planning
(:func:`vibrofocus.rigs.safety.check_on_rig`).
"""

from __future__ import annotations

import math
from typing import Any

from ..errors import SafetyError

__all__ = ["check_designs"]


def check_designs(designer: Any, rig: Any) -> str | None:
    """Check the tap at every layout location of ``designer``'s method against ``rig``'s limits.

    Parameters
    ----------
    designer : TapDesigner
        Its method's designs at the layout's locations.
    rig : Rig
        The rig that will play them.

    Returns
    -------
    str or None
        None when every tap fits; else one line naming every location whose tap a limit
        a drive has by itself refuses (peak, RMS over the short window, DC and slow
        content, the sustained limit played alone), the first one's reason, and the
        largest ``/tap`` level, dB re the design, at which each fits.
    """
    from ..rigs.safety import check_on_rig, plan_levels

    refused: dict[int, tuple[str, float | None]] = {}
    for location in designer.layout.location_numbers:
        drives = designer.drives_at(location)
        try:
            check_on_rig(drives, rig)
            continue
        except SafetyError as exc:
            reason = str(exc)
        scale = plan_levels([drives], rig.fs, rig.limits).scale_to_fit
        try:
            check_on_rig(drives * scale, rig)
            level = math.floor(200 * math.log10(scale)) / 10  # dB, rounded down to 0.1
        except SafetyError:
            level = None
        refused[int(location)] = (reason, level)
    if not refused:
        return None
    first = next(iter(refused))
    levels = ", ".join(f"/tap {k} {lv:g}" for k, (_, lv) in refused.items() if lv is not None)
    return (f"the {designer.method} taps at location(s) {', '.join(map(str, refused))} break the limits of the "
            f"{getattr(rig, 'kind', '')} rig at the design's level and will be refused (location {first}: "
            f"{refused[first][0]})" + (f"; these levels (dB re the design) fit: {levels}" if levels else "")
            + "; or choose another --method")
