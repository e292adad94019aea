"""Speed of ``vibrofocus design-experiment`` (issue 55): how fast a design can be iterated.

Prints, from one run:

- the cost of one Study 1 answer law on a grid of locations: the exact product-of-CDFs
  path of ``design.study1_probabilities`` against the general quadrature of
  ``likelihood.answer_probabilities`` (the same numbers to 2e-3, asserted), and the ratio;
- the time of a whole design with the defaults (3 methods x 9 locations x 6 levels = 162
  candidate conditions, every registered hypothesis, 6 parameter sets each), split into its
  answer laws, its tables and its greedy choice, and with the candidates cut to one level (27) for the
  ratio of the greedy part to the candidates' number, and with point answers too
  (``responses=("location", "point")``: twice the candidate blocks);
- the time of the identification check (P(correct) against N) in one process.

Run: ``python benchmarks/bench_design.py [--studies 100]``. One BLAS thread.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from threadpoolctl import threadpool_limits


def main() -> None:
    from vibrofocus.simulation import available_hypotheses, default_bank, hypothesis
    from vibrofocus.simulation.design import (DesignSettings, design_experiment, identification, paper_plan,
                                              study1_probabilities)
    from vibrofocus.simulation.likelihood import Stimuli, answer_law, answer_probabilities
    from vibrofocus.simulation.perception import Traits

    ap = argparse.ArgumentParser()
    ap.add_argument("--studies", type=int, default=100)
    args = ap.parse_args()
    bank = default_bank()
    names = available_hypotheses()
    with threadpool_limits(1):
        h = hypothesis(names[0])
        m = h.model()
        st = Stimuli.from_bank(bank, 0, -10.0)
        traits = Traits.draw(m, 1)
        law = answer_law(st.percepts(h, m, traits), np.tile(np.arange(27), 4), st.centre_xy, m, traits, study=1)
        t = time.perf_counter()
        slow = answer_probabilities(law, st.locations_xy)
        t_slow = time.perf_counter() - t
        t = time.perf_counter()
        for _ in range(20):
            fast = study1_probabilities(law, st.locations_xy)
        t_fast = (time.perf_counter() - t) / 20
        np.testing.assert_allclose(fast, slow, atol=2e-3)
        print(f"answer law of {law.weight.shape[0]} trials, 9 locations: quadrature {t_slow * 1e3:.1f} ms, "
              f"grid {t_fast * 1e3:.2f} ms, ratio {t_slow / t_fast:.0f}x")
        full = design_experiment(DesignSettings())
        n_lev = len(full.settings.levels_db)
        n_cand = len(bank.methods) * len(bank.locations_xy) * n_lev
        print(f"design, {n_cand} candidate conditions, {len(names)} hypotheses: {full.elapsed_s:.1f} s "
              f"(answer laws {full.timings['answer_laws_s']:.1f} s, tables {full.timings['tables_s']:.2f} s, "
              f"greedy {full.timings['greedy_s']:.1f} s)")
        one = design_experiment(DesignSettings(levels_db=(-10.0,)))
        print(f"design, {n_cand // n_lev} candidate conditions (one level): {one.elapsed_s:.1f} s (greedy "
              f"{one.timings['greedy_s']:.1f} s); {n_lev}x the candidates cost {full.elapsed_s / one.elapsed_s:.1f}x the "
              f"time, greedy {full.timings['greedy_s'] / max(one.timings['greedy_s'], 1e-9):.1f}x")
        pts = design_experiment(DesignSettings(responses=("location", "point")))
        print(f"design with point answers too (twice the candidate blocks): {pts.elapsed_s:.1f} s "
              f"(answer laws {pts.timings['answer_laws_s']:.1f} s, greedy {pts.timings['greedy_s']:.1f} s)")
        t = time.perf_counter()
        r = identification({"designed": full.blocks, "paper": paper_plan()}, list(names), n_participants=(6,),
                           n_studies=args.studies, local=True)
        print(f"identification check, 2 protocols x {len(names)} hypotheses, {args.studies} studies of N = 6: "
              f"{time.perf_counter() - t:.1f} s (score tables {r['tables_s']:.1f} s); P(correct) at N = 6: "
              f"designed {r['mean']['designed'][6]:.2f}, paper {r['mean']['paper'][6]:.2f}")


if __name__ == "__main__":
    main()
