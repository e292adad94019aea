"""serve-osc checks every location's tap against the rig's limits before it listens."""

from __future__ import annotations

import re

from vibrofocus.realtime import TapDesigner
from vibrofocus.realtime.limits import check_designs
from vibrofocus.rendering import TransferMatrix
from vibrofocus.rigs.safety import SafetyLimits, windowed_rms
from vibrofocus.skin import SimulatedForearm
from vibrofocus.studies.engine import check_stimulus


def test_the_locations_whose_taps_the_limits_refuse_are_named_at_start_with_a_level_that_fits():
    rig = SimulatedForearm(seed=2)
    designer = TapDesigner(TransferMatrix.from_model(rig, rig.layout, rig.fs), None, method="inverse",
                           limit_v=rig.limits.peak_v)
    assert check_designs(designer, rig) is None  # the default limits admit every tap
    rms = {k: float(windowed_rms(designer.drives_at(k) ** 2, int(rig.fs)).max()) for k in rig.layout.location_numbers}
    limit = sorted(rms.values())[len(rms) // 2]  # about half the taps are over it
    over = [k for k, v in rms.items() if v > limit * (1 + 1e-6)]
    assert over
    rig.limits = SafetyLimits(rms_v=limit)
    message = check_designs(designer, rig)
    assert message.startswith(f"the inverse taps at location(s) {', '.join(map(str, over))} break the limits")
    levels = dict(re.findall(r"/tap (\d+) (-[\d.]+)", message))
    assert sorted(int(k) for k in levels) == over
    for k, db in levels.items():
        check_stimulus(designer.drives_at(int(k)) * 10 ** (float(db) / 20), rig)  # the level named fits
