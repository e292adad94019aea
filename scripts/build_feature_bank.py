"""Build the feature bank shipped with vibrofocus (src/vibrofocus/simulation/data/feature_bank.npz).

Calibrates N simulated forearms (simulated participants sim-001.. of simulate-study
--seed SEED), renders the 27 study stimuli on each and stores their felt energies on the
perceptual model's skin grid. Usage:

    PYTHONPATH=src python scripts/build_feature_bank.py --n 60 --seed 0

``--integration-ms W`` builds a bank whose felt intensities integrate over the W ms window
of largest energy instead of the whole stimulus (``PerceptualModel.integration_s``; an
explored alternative, not the model's default); write it elsewhere with ``--out``.

``--levels paper|equal-peak`` is the level rule of the stimuli (a study protocol's; default
the paper's), stored in the bank.

``--methods a,b,...`` renders other registered methods too (for example
``funneling,inverse,combination,minimax``), for ``vibrofocus power --bank FILE --methods
inverse,minimax``; write such a bank elsewhere with ``--out``.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from vibrofocus.defaults import STUDY_METHODS
from vibrofocus.simulation.bank import DEFAULT_BANK, build_feature_bank
from vibrofocus.simulation.perception import PerceptualModel

if __name__ == "__main__":
    ap = argparse.ArgumentParser()
    ap.add_argument("--n", type=int, default=60)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path, default=Path(__file__).parents[1] / "src/vibrofocus/simulation" / DEFAULT_BANK)
    ap.add_argument("--integration-ms", type=float, default=None,
                    help="felt intensity over the W ms window of largest energy (default: the whole stimulus)")
    ap.add_argument("--methods", default=",".join(STUDY_METHODS),
                    help="registered methods, comma separated (default the studies' three)")
    ap.add_argument("--levels", default="paper", choices=("paper", "equal-peak"),
                    help="level rule of the stimuli, as a study protocol's (default the paper's; stored in the bank)")
    args = ap.parse_args()
    methods = tuple(m.strip() for m in args.methods.split(",") if m.strip())
    shipped = Path(__file__).parents[1] / "src/vibrofocus/simulation" / DEFAULT_BANK
    if methods != STUDY_METHODS and args.out.resolve() == shipped.resolve():
        ap.error("a bank with other methods than the studies' three goes elsewhere: give --out")
    model = PerceptualModel(integration_s=None if args.integration_ms is None else args.integration_ms * 1e-3)
    t0 = time.perf_counter()
    bank = build_feature_bank(args.n, seed=args.seed, model=model, methods=methods, levels=args.levels,
                              progress=lambda k, n: print(f"forearm {k}/{n}", flush=True))
    bank.save(args.out)
    print(f"wrote {args.out} ({bank.energy.shape}) in {time.perf_counter() - t0:.0f} s")
