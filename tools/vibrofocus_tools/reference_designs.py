"""Save the drives of every built-in rendering method, for a regression test of ``render``.

Renders each built-in method on a fixed simulated calibration (participant 0, seeded,
a short h1 calibration) and on its bare transfer matrix with a few non-default options,
and writes the drives to ``tests/rendering/data/reference_designs.npz``. Run it once,
before a change to the rendering code, and commit the file: ``tests/rendering/
test_reference_designs.py`` then checks that the changed code gives the same drives to
1e-12 (relative to each design's peak).

Run: ``python scripts/save_reference_designs.py [--out PATH]`` (:func:`save`).
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from .markers import ROOT

#: Window of the designs, samples (short: the file stays small).
N_SAMPLES = 2048
#: Target locations designed for (1-based): every method at each, the array cases at the last.
LOCATIONS = (1, 5)
#: Options of the bare-array cases, keyed by a case name (method, keyword arguments).
ARRAY_CASES = {
    "inverse-all-tikhonov": ("inverse", {"control": "all", "regularization": "tikhonov"}),
    "inverse-exact": ("inverse", {"exact_target": True, "guard_weight": 0.5}),
    "combination-weighted": ("combination", {"exact_target": False, "funneling_law": "energy"}),
    "contrast-locations": ("contrast", {"control": "locations", "acc_reg": 1e-2}),
    "constrained-min": ("constrained", {"min_contrast_db": -6.0}),
}
OUT = ROOT / "tests" / "rendering" / "data" / "reference_designs.npz"


def simulated_calibration():
    """The fixed calibration every reference design is rendered on."""
    from vibrofocus.calibration import calibrate
    from vibrofocus.rigs import SimulatedForearm

    rig = SimulatedForearm(seed=3)
    return calibrate(rig, participant_id="REF", method="h1", sweep_s=1.0, repeats=2)


def reference_designs(cal) -> dict[str, np.ndarray]:
    """Drives of every case, keyed ``"<source>/<case>/<location>"``."""
    from vibrofocus import render
    from vibrofocus.defaults import METHODS

    H = cal.transfer_for(N_SAMPLES)
    out: dict[str, np.ndarray] = {}
    for location in LOCATIONS:
        for method in METHODS:
            out[f"calibration/{method}/{location}"] = render(
                method, cal, cal.fs, cal.layout, location, n_samples=N_SAMPLES).drives
    for case, (method, options) in ARRAY_CASES.items():
        out[f"array/{case}/{LOCATIONS[-1]}"] = render(
            method, H, cal.fs, cal.layout, LOCATIONS[-1], calibrated_band=cal.band, **options).drives
    return out


def save(out: str | os.PathLike = OUT) -> str:
    """Render every case and write the drives to ``out`` (``.npz``, atomically); returns a line saying so."""
    from vibrofocus.io import atomic_path

    out = Path(out)
    cal = simulated_calibration()
    designs = reference_designs(cal)
    meta = {"fs": cal.fs, "band": list(cal.band), "locations": list(LOCATIONS), "n_samples": N_SAMPLES,
            "array_cases": {k: [m, o] for k, (m, o) in ARRAY_CASES.items()}}
    out.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(out, what="reference designs") as tmp:
        with open(tmp, "wb") as fh:
            np.savez_compressed(fh, meta=np.array(json.dumps(meta)), **designs)
    return f"{len(designs)} designs written to {out} ({out.stat().st_size / 1e3:.0f} kB)"
