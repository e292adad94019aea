#!/usr/bin/env python
"""Fit the perceptual model of the simulated participants to the paper; write its tables.

Simulated participants are a MODEL, not data. The parameters marked *fitted* in
:class:`vibrofocus.simulation.perception.PerceptualModel` are fitted to the statistics of
de Vlam et al. (IEEE ToH 16(4), 2023) kept in ``simulation/data/psychophysics.json``
(``paper_statistics``): a seeded random search, then a local refinement, each candidate
judged on the same simulated 20-participant studies (seeds 1000.., fast path: feature
bank + vectorized statistics; common random numbers make candidates comparable). One
objective covers every statistic of the paper's Sec. III.B-C: squared log ratios of the
model's median F / chi2 / GG epsilon / reduction of selected points to the paper's,
hinge terms that keep the target-containing Study 2 tests at their null size, and
squared shortfalls of the share of studies that reproduce each post hoc pattern (only
funneling vs inverse in Study 1, with the inverse filter's error lower; the sphericity
violation; the inverse filter differing from both other methods at locations 1, 3 and 9;
fewer points with the inverse filter in Study 2) and the ranking of the locations (4, 5,
7, 8 best; 1 among the worst).

    PYTHONPATH=src python scripts/fit_participants.py search --out fit.json   # ~7 min on one core
    PYTHONPATH=src python scripts/fit_participants.py report [--fit fit.json]
    PYTHONPATH=src python scripts/fit_participants.py table [--seeds 20] [--check]

``search`` prints each improvement, then the paper beside the best model and the
residuals; its result goes into the defaults of ``PerceptualModel`` by hand (rounded).
``report`` prints the same for the defaults (or a fit file) on the table's seeds.
``table`` evaluates the defaults on seeds 0..N-1 and writes the side-by-side table between
the ``participants-table`` markers of ``docs/simulated-participants.md`` and its short
version into README.md (atomically); ``--check`` only compares.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from vibrofocus._atomic import write_text
from _markers import replace_between_markers
from vibrofocus.simulation.bank import FeatureBank
from vibrofocus.simulation.paper import BEST_LOCATIONS, INTERACTION_LOCATIONS, compare, comparison_markdown, seed_statistics
from vibrofocus.simulation.perception import MODEL_LABEL, PARAMETER_SOURCES, PerceptualModel, psychophysics_data

ROOT = Path(__file__).resolve().parent.parent
PAGES = {"docs": ROOT / "docs" / "simulated-participants.md", "readme": ROOT / "README.md"}
FIT_SEEDS = range(1000, 1016)  # the tables use seeds 0..


def targets() -> list[tuple[str, str, float]]:
    """(statistic key, label, paper value) of the numbers the fit matches."""
    p = psychophysics_data()["paper_statistics"]
    return [
        ("s1_location_F", "Study 1 location F", p["study1_location"]["F"]),
        ("s1_location_eps", "Study 1 location GG epsilon", p["study1_location"]["ddof1"] / 8.0),
        ("s1_method_F", "Study 1 method F", p["study1_method"]["F"]),
        ("s1_interaction_F", "Study 1 interaction F", p["study1_interaction"]["F"]),
        ("s2_location_chi2", "Study 2 location chi2(8)", p["study2_location"]["chi2"]),
        ("s2_method_chi2", "Study 2 method chi2(2)", p["study2_method"]["chi2"]),
        ("s2_reduction", "Study 2 fewer points, inverse vs funneling", p["study2_method"]["reduction"]),
    ]


#: Range searched for the drive cue's weight (``--central-weight LO HI`` narrows it, e.g.
#: to hold the paper's reading that funneling is coded centrally).
CENTRAL_WEIGHT_RANGE = (0.0, 1.0)

#: Post hoc patterns: (label, share of studies reproducing it, from one study's statistics).
PATTERNS = (
    ("inverse lower error than funneling (Study 1)",
     lambda s: float(s["s1_method_pairs"]["funneling vs inverse"] < 0.05
                     and s["s1_error_by_method"][1] < s["s1_error_by_method"][0])),
    ("sphericity violated (Study 1 location)", lambda s: float(s["s1_location_p_mauchly"] < 0.05)),
    ("only funneling vs inverse differ (Study 1)", lambda s: float(s["s1_only_funneling_vs_inverse"])),
    ("inverse differs from both at 1, 3, 9 (Study 1)",
     lambda s: float(np.isin(INTERACTION_LOCATIONS, s["s1_inverse_differs_locations"]).mean())),
    ("fewer points with the inverse filter (Study 2)", lambda s: float(s["s2_inverse_fewer"])),
)


#: Target-containing Study 2 tests: not significant in the paper; held at most at the null
#: mean of their chi2 (its degrees of freedom).
NULL_MEANS = (("s2_hit_location_chi2", 8.0), ("s2_hit_method_chi2", 2.0))
#: Participants (of 20) the target-containing Study 2 tests should keep, at least (median).
MIN_HIT_PARTICIPANTS = 15


def _median(stats: list[dict], key: str) -> float:
    v = np.array([s[key] for s in stats], dtype=float)
    return float(np.median(v[np.isfinite(v)])) if np.isfinite(v).any() else float("nan")


def loss(stats: list[dict], weights: dict[str, float] | None = None) -> float:
    """Fit loss of the studies ``stats`` (see the module docstring); inf if undefined.

    ``weights``: factors of the squared log ratios, by statistic key (default 1).
    """
    w = weights or {}
    terms = [w.get(k, 1.0) * np.log(max(_median(stats, k), 1e-3) / v) ** 2 for k, _, v in targets()]
    terms += [max(0.0, np.log(max(_median(stats, k), 1e-3) / null)) ** 2 for k, null in NULL_MEANS]
    # The target-containing tests keep only participants with such a trial in every
    # condition. Optional term (weight "s2_hit_n", default 0): keep most of them (how many
    # the paper kept is not in the data file; the paper tested 20).
    terms.append(w.get("s2_hit_n", 0.0)
                 * max(0.0, np.log(MIN_HIT_PARTICIPANTS / max(_median(stats, "s2_hit_n"), 0.5))) ** 2)
    err_loc = np.mean([s["s1_error_by_location"] for s in stats], axis=0)
    ranks = np.argsort(np.argsort(err_loc))  # 0 = lowest mean error
    terms.append(4.0 * ((ranks[BEST_LOCATIONS].mean() - 1.5) / 3.0) ** 2)
    terms.append(0.5 * (max(0.0, 4 - ranks[0]) / 4.0) ** 2)  # location 1 among the five worst
    for label, share_of in PATTERNS:
        terms.append(w.get(label, 2.0) * (1.0 - np.mean([share_of(s) for s in stats])) ** 2)
    total = float(np.sum(terms))
    return total if np.isfinite(total) else float("inf")


def residuals(stats: list[dict]) -> str:
    """The paper's numbers beside the model's medians, with the residuals, as text."""
    lines = [f"{'statistic':34s} {'paper':>8s} {'model':>8s} {'model-paper':>12s} {'log ratio':>10s}"]
    for k, label, v in targets():
        m = _median(stats, k)
        lines.append(f"{label:34s} {v:8.2f} {m:8.2f} {m - v:12.2f} {np.log(m / v):10.3f}")
    for k, null in NULL_MEANS:
        m = _median(stats, k)
        ns = np.mean([s[k.replace('_chi2', '_p')] >= 0.05 for s in stats])
        lines.append(f"{k + ' (paper: n.s.)':34s} {'n.s.':>8s} {m:8.2f} {'':12s} {'':10s} n.s. in {ns:.0%}")
    lines.append(f"{'s2_hit_n (participants kept)':34s} {'20?':>8s} {_median(stats, 's2_hit_n'):8.1f}")
    err_loc = np.mean([s["s1_error_by_location"] for s in stats], axis=0)
    best = np.sort(np.argsort(err_loc)[:4]) + 1
    lines.append(f"{'best locations':34s} {'4,5,7,8':>8s} {','.join(map(str, best)):>8s}   mean error by location (mm): "
                 + " ".join(f"{e:.1f}" for e in err_loc))
    for label, share_of in PATTERNS:
        lines.append(f"{label:50s} {np.mean([share_of(s) for s in stats]):6.0%} of the studies")
    lines.append(f"loss {loss(stats):.4f} over {len(stats)} studies")
    return "\n".join(lines)


def sample(rng: np.random.Generator, base: PerceptualModel | None = None, scale: float = 1.0,
           central_range: tuple[float, float] = CENTRAL_WEIGHT_RANGE) -> PerceptualModel:
    """A candidate: drawn from broad ranges (``base`` None) or jittered around ``base``."""
    if base is None:
        lo_a, lo_p, lo_k = rng.uniform(3e-3, 12e-3), rng.uniform(5e-3, 25e-3), rng.uniform(0.05, 0.6)
        return PerceptualModel().replace(
            sl_ref_db=rng.uniform(10, 45), funneling_exponent=rng.uniform(0.2, 2.0),
            central_weight=rng.uniform(*central_range), conflict_gain=rng.uniform(0.0, 2.0),
            acuity_sd_m=(lo_a, lo_a * rng.uniform(1.2, 2.0)), spread_gain=tuple(sorted(rng.uniform(0, 2, 2))),
            prior_sd_m=(lo_p, lo_p * rng.uniform(1.2, 2.0)),
            bias_mean_m=(rng.uniform(-8e-3, 8e-3), rng.uniform(-8e-3, 0.0)), bias_sd_m=rng.uniform(0, 4e-3),
            select_kappa=(lo_k, min(lo_k + rng.uniform(0.1, 0.4), 0.99)), select_log_sd=rng.uniform(0.1, 1.0),
        )

    def jit(v: float) -> float:
        return float(v * np.exp(rng.normal(0, 0.15 * scale)))

    b = base
    return b.replace(
        sl_ref_db=float(np.clip(b.sl_ref_db + rng.normal(0, 2 * scale), 5, 50)),
        central_weight=float(np.clip(b.central_weight + rng.normal(0, 0.1 * scale), *central_range)),
        conflict_gain=float(abs(b.conflict_gain + rng.normal(0, 0.15 * scale))),
        funneling_exponent=float(np.clip(jit(b.funneling_exponent), 0.05, 1.5)),
        acuity_sd_m=tuple(sorted(jit(v) for v in b.acuity_sd_m)),
        spread_gain=tuple(sorted(abs(jit(v + 1e-3)) for v in b.spread_gain)),
        prior_sd_m=tuple(sorted(jit(v) for v in b.prior_sd_m)),
        bias_mean_m=(float(b.bias_mean_m[0] + rng.normal(0, 1.5e-3 * scale)),
                     float(min(0.0, b.bias_mean_m[1] + rng.normal(0, 1.5e-3 * scale)))),
        bias_sd_m=float(abs(b.bias_sd_m + rng.normal(0, 5e-4 * scale))),
        select_kappa=tuple(sorted(float(np.clip(jit(v), 0.01, 0.99)) for v in b.select_kappa)),
        select_log_sd=jit(b.select_log_sd),
    )


def _load(path: Path | None) -> PerceptualModel:
    if path is None:
        return PerceptualModel()
    return PerceptualModel().replace(**json.loads(path.read_text(encoding="utf-8"))["model"])


def search(n_eval: int, n_refine: int, out: Path, start: Path | None, rng_seed: int,
           weights: dict[str, float], central_range: tuple[float, float] = CENTRAL_WEIGHT_RANGE,
           bank: FeatureBank | None = None, integration_s: float | None = None) -> PerceptualModel:
    rng = np.random.default_rng(rng_seed)
    best = _load(start).replace(integration_s=integration_s)
    best_loss = loss(seed_statistics(best, FIT_SEEDS, bank=bank), weights)
    print(f"start: loss {best_loss:.4f}", flush=True)
    t0 = time.perf_counter()
    for i in range(n_eval + n_refine):
        cand = (sample(rng, central_range=central_range) if i < n_eval else
                sample(rng, best, scale=1.0 - 0.8 * (i - n_eval) / max(n_refine, 1), central_range=central_range))
        cand = cand.replace(integration_s=integration_s)  # the bank's window, never searched
        val = loss(seed_statistics(cand, FIT_SEEDS, bank=bank), weights)
        if val < best_loss:
            best, best_loss = cand, val
            print(f"{i}: loss {val:.4f} ({time.perf_counter() - t0:.0f} s) {json.dumps(cand.to_dict())}", flush=True)
    write_text(out, json.dumps({"loss": best_loss, "weights": weights, "fit_seeds": [FIT_SEEDS.start, FIT_SEEDS.stop],
                                "model": best.to_dict()}, indent=1), what="fit")
    print(f"best loss {best_loss:.4f} after {n_eval + n_refine} candidates ({time.perf_counter() - t0:.0f} s) -> {out}")
    return best


def _value(v) -> str:
    if isinstance(v, tuple):
        return "(" + ", ".join(_value(x) for x in v) + ")"
    return f"{v:.4g}" if isinstance(v, float) else str(v)


def parameters_markdown() -> str:
    """The parameters of the model's defaults with their kind and note, as markdown."""
    model = PerceptualModel()
    lines = [f"*{MODEL_LABEL}.* Values of `PerceptualModel()` (SI units: m, s, dB, Hz); ranges (lo, hi) are "
             "uniform across simulated participants.", "",
             "| parameter | value | kind | note |", "|---|---|---|---|"]
    for name, (kind, note) in PARAMETER_SOURCES.items():
        lines.append(f"| `{name}` | {_value(getattr(model, name))} | {kind} | {note} |")
    return "\n".join(lines)


#: The power table of the README and docs: sample sizes and studies per size.
POWER_SIZES, POWER_STUDIES = (10, 15, 20, 25, 30), 200


def power_markdown() -> str:
    """Power of each test against N for the defaults (``vibrofocus power``'s numbers), as markdown."""
    from vibrofocus.simulation.power import TESTS, PowerDesign, run_power

    rows = run_power(PowerDesign(n_participants=POWER_SIZES, n_studies=POWER_STUDIES), local=True)["table"]
    power = {(r["test"], r["n_participants"]): r["power"] for r in rows}
    lines = [f"*{MODEL_LABEL}.* Power (share of {POWER_STUDIES} simulated studies with p < 0.05; binomial SE at "
             "most 3.5 points) of each test against the number of participants N, from "
             f"`vibrofocus power --participants {','.join(map(str, POWER_SIZES))} --studies {POWER_STUDIES}`.", "",
             "| test | " + " | ".join(f"N = {n}" for n in POWER_SIZES) + " |",
             "|---|" + "---:|" * len(POWER_SIZES)]
    for key, label in TESTS:
        lines.append(f"| {label} | " + " | ".join(f"{power[(key, n)]:.2f}" for n in POWER_SIZES) + " |")
    return "\n".join(lines)


def table(n_seeds: int, check: bool) -> int:
    seeds = range(n_seeds)
    stats = seed_statistics(PerceptualModel(), seeds)
    rows = compare(stats)
    resid = (f"`scripts/fit_participants.py report` ({MODEL_LABEL}; the defaults, the table's {n_seeds} seeds; "
             "model: median over seeds):\n\n```\n" + residuals(stats) + "\n```")
    power = power_markdown()
    blocks = {
        PAGES["docs"]: {"participants-table": comparison_markdown(rows, seeds),
                        "participants-parameters": parameters_markdown(), "fit-residuals": resid,
                        "power-table": power},
        PAGES["readme"]: {"participants-table": comparison_markdown(rows, seeds, short=True), "power-table": power},
    }
    stale = []
    for page, parts in blocks.items():
        text = page.read_text(encoding="utf-8")
        new = text
        for name, block in parts.items():
            new = replace_between_markers(new, name, block, page)
        if new != text:
            stale.append(page)
            if not check:
                write_text(page, new, what="page")
    print(blocks[PAGES["docs"]]["participants-table"])
    if check:
        print("up to date" if not stale else "out of date: " + ", ".join(map(str, stale)))
        return 1 if stale else 0
    print("wrote " + (", ".join(map(str, stale)) if stale else "nothing (up to date)"))
    return 0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    s = sub.add_parser("search", help="fit (random search, then local refinement)")
    s.add_argument("--n-eval", type=int, default=300, help="random candidates")
    s.add_argument("--n-refine", type=int, default=500, help="refinement candidates")
    s.add_argument("--out", type=Path, default=Path("fit_participants.json"))
    s.add_argument("--start", type=Path, default=None, help="start from this fit (JSON written by search)")
    s.add_argument("--rng-seed", type=int, default=2023)
    s.add_argument("--central-weight", type=float, nargs=2, default=None, metavar=("LO", "HI"),
                   help="search the drive cue's weight in [LO, HI] only (default 0 1)")
    s.add_argument("--bank", type=Path, default=None,
                   help="a feature bank built by scripts/build_feature_bank.py (default: the shipped one)")
    s.add_argument("--integration-ms", type=float, default=None,
                   help="the integration window the --bank was built with (PerceptualModel.integration_s)")
    s.add_argument("--weight", action="append", default=[], metavar="KEY=W",
                   help="weight of one matched statistic's term (e.g. s1_interaction_F=3); repeatable")
    r = sub.add_parser("report", help="the paper beside the model, with residuals")
    r.add_argument("--fit", type=Path, default=None, help="a fit file (default: the model's defaults)")
    r.add_argument("--seeds", type=int, default=20)
    t = sub.add_parser("table", help="write the tables of docs/simulated-participants.md and README.md")
    t.add_argument("--seeds", type=int, default=20)
    t.add_argument("--check", action="store_true", help="only compare; exit 1 if a page is out of date")
    args = ap.parse_args()
    if args.cmd == "search":
        weights = {}
        for item in args.weight:
            key, _, value = item.partition("=")
            known = [k for k, _, _ in targets()] + ["s2_hit_n"] + [label for label, _ in PATTERNS]
            if key not in known:
                ap.error(f"--weight {item}: unknown statistic (one of {', '.join(known)})")
            weights[key] = float(value)
        central_range = tuple(sorted(args.central_weight)) if args.central_weight else CENTRAL_WEIGHT_RANGE
        bank = FeatureBank.load(args.bank) if args.bank else None
        window = None if args.integration_ms is None else args.integration_ms * 1e-3
        best = search(args.n_eval, args.n_refine, args.out, args.start, args.rng_seed, weights, central_range,
                      bank, window)
        print("\nfit seeds:\n" + residuals(seed_statistics(best, FIT_SEEDS, bank=bank)))
        print("\ntable seeds 0-19:\n" + residuals(seed_statistics(best, range(20), bank=bank)))
        print("\nvalidation seeds 500-519:\n" + residuals(seed_statistics(best, range(500, 520), bank=bank)))
        return 0
    if args.cmd == "report":
        print(residuals(seed_statistics(_load(args.fit), range(args.seeds))))
        return 0
    return table(args.seeds, args.check)


if __name__ == "__main__":
    sys.exit(main())
