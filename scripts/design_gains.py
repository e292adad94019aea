#!/usr/bin/env python
"""Where the design's information lies: one trial's expected gain per method and level.

For a set of hypotheses (a MODEL, not data) and the design's parameter draws, prints the
expected information of one trial about the hypothesis (``ExperimentDesign.conditions``,
answered among all nine locations), averaged over the locations, per method and level,
then summed per location. Switching parts of the design off shows what the information
rests on: ``--spread 0 --draws 1`` (the shipped parameters only), ``--spread 1`` (the
free parameters' whole ranges, the default), ``--population NAME`` (every hypothesis with
one hypothesis' parameters: the readouts alone).

    python scripts/design_gains.py --hypotheses level-reliability,intensity --spread 0 --draws 1
    python scripts/design_gains.py --hypotheses level-reliability,intensity --spread 1 --draws 4
    python scripts/design_gains.py --hypotheses level-reliability,intensity --population intensity --spread 0.1
"""

from __future__ import annotations

import argparse
import collections

from vibrofocus.simulation.design import DesignSettings, design_experiment

LEVELS = (0.0, -5.0, -10.0, -15.0, -20.0, -25.0, -30.0, -40.0)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--hypotheses", default="level-reliability,intensity", help="comma separated")
    ap.add_argument("--spread", type=float, default=1.0, help="parameter_spread (fraction of each range)")
    ap.add_argument("--draws", type=int, default=4, help="parameter sets per hypothesis")
    ap.add_argument("--population", default=None, help="one hypothesis' parameters for every hypothesis")
    args = ap.parse_args()
    d = design_experiment(DesignSettings(hypotheses=tuple(args.hypotheses.split(",")), levels_db=LEVELS, budget=4,
                                         n_parameter_draws=args.draws, parameter_spread=args.spread,
                                         population=args.population))
    gain = collections.defaultdict(float)
    by_location = collections.defaultdict(float)
    n_loc = len({c["location"] for c in d.conditions})
    for c in d.conditions:
        gain[(c["method"], c["level_db"])] += c["gain_nats"] / n_loc
        by_location[c["location"]] += c["gain_nats"]
    methods = sorted({m for m, _ in gain})
    print(f"{args.hypotheses}; spread {args.spread:g}, {args.draws} parameter sets, population "
          f"{args.population or 'each its own'} (nats per trial, mean over locations)")
    print("| level (dB) | " + " | ".join(methods) + " |\n|---" + "|---" * len(methods) + "|")
    for lvl in LEVELS:
        print(f"| {lvl:+g} | " + " | ".join(f"{gain[(m, lvl)]:.4f}" for m in methods) + " |")
    print("per location (sum over methods and levels): "
          + ", ".join(f"{k}: {v:.2f}" for k, v in sorted(by_location.items())))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
