"""The OSC tests' tap designer: the inverse filter on the simulated rig's own model."""

from vibrofocus.realtime import TapDesigner
from vibrofocus.rendering import TransferMatrix
from vibrofocus.rigs import make_rig

#: A coarse model grid keeps the fixtures quick; the designer's own test checks the fine one.
PITCH_M = 5e-3


def simulated_designer(seed: int = 3):
    """A simulated rig and an inverse-filter :class:`TapDesigner` on its model (grid not prepared)."""
    rig = make_rig("simulated", seed=seed)
    tm = TransferMatrix.from_model(rig, rig.layout, rig.fs)
    return rig, TapDesigner(tm, rig, method="inverse", limit_v=rig.limits.peak_v, grid_pitch_m=PITCH_M)
