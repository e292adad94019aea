"""The loop closes: simulate-study on a protocol under each hypothesis, then model choice by marginal likelihood.

For each registered hypothesis H and each protocol (the designed one, and the paper's
Study 1), N simulated participants run the protocol through the study engine
(``simulate_studies``, the code of ``vibrofocus simulate-study --protocol P --hypothesis
H``); their Study 1 answers are then scored under every hypothesis at its shipped
parameters (``vibrofocus.simulation.design.choose_hypothesis``, the marginal likelihood of
``vibrofocus.simulation.likelihood``) and the hypothesis of the largest summed marginal
likelihood is chosen. The participants' forearms are calibrated once per seed and shared
by every database; their felt fields come from a feature bank built on those
calibrations. Use seeds the design did not use (the design used the shipped bank, seed 0).
A MODEL, not data.

    python scripts/design_loop.py --protocol design/protocol.toml -n 6 --seeds 7,8 --out loop/

``--protocols designed`` runs the designed protocol alone. ``loop.md`` ends with the
confusion matrix per protocol (rows: the true hypothesis; columns: the share of studies
choosing each).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from vibrofocus.calibration import load_calibration
from vibrofocus.io import write_text
from vibrofocus.simulation import available_hypotheses, build_feature_bank, simulate_studies
from vibrofocus.simulation.design import choose_hypothesis
from vibrofocus.studies import StudyStore
from vibrofocus.studies.protocol_files import load_protocol, shipped_protocol


def _share_calibrations(first: Path, db: Path) -> None:
    """Register in ``db`` the calibrations ``first`` holds, so the same forearms are not calibrated again."""
    src, dst = StudyStore(first), StudyStore(db)
    for p in src.participants():
        dst.add_participant(p.participant_id, simulated=True)
        for rec in src.calibrations(p.participant_id):
            dst.add_calibration(p.participant_id, rec.path)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--protocol", type=Path, required=True, help="The designed protocol (design-experiment --out).")
    ap.add_argument("-n", type=int, default=6, help="Participants per study.")
    ap.add_argument("--seeds", default="7", help="Simulation seeds, one study per seed, hypothesis and protocol.")
    ap.add_argument("--n-draws", type=int, default=32, help="Trait draws of the marginal likelihood.")
    ap.add_argument("--protocols", default="designed,paper", help="Which protocols to run: designed, paper or both.")
    ap.add_argument("--out", type=Path, required=True)
    a = ap.parse_args()
    a.out.mkdir(parents=True, exist_ok=True)
    protocols = {k: v for k, v in (("designed", lambda: load_protocol(a.protocol)),
                                   ("paper", lambda: shipped_protocol("paper-study1")))
                 if k in a.protocols.split(",")}
    protocols = {k: make() for k, make in protocols.items()}
    names = list(available_hypotheses())
    rows = []
    t0 = time.perf_counter()
    for seed in (int(s) for s in a.seeds.split(",")):
        first = None
        cal_dir = a.out / f"calibrations-{seed}"
        dbs = {}
        for pname, proto in protocols.items():
            for h in names:
                db = a.out / f"{pname}-{h}-seed{seed}.db"
                if first is not None and not db.exists():
                    _share_calibrations(first, db)
                simulate_studies(db, n_participants=a.n, seed=seed, protocol=proto, hypothesis=h,
                                 calibration_dir=cal_dir)
                first = first or db
                dbs[(pname, h)] = db
        store = StudyStore(first)
        cals = [load_calibration(store.verify_calibration(store.calibrations(f"sim-{k:03d}")[-1].calibration_id))
                for k in range(1, a.n + 1)]
        bank = build_feature_bank(a.n, seed=seed, calibrations=cals)
        for (pname, h), db in dbs.items():
            r = choose_hypothesis(db, bank, names, n_draws=a.n_draws)
            rows.append({"seed": seed, "protocol": pname, "true": h, "chosen": r["chosen"], "total": r["total"]})
            print(f"seed {seed} {pname:9s} true {h:18s} chosen {r['chosen']}", flush=True)
    lines = ["| protocol | seed | true hypothesis | chosen | log BF (true vs best other) |", "|---|---|---|---|---|"]
    for r in rows:
        other = max(v for k, v in r["total"].items() if k != r["true"])
        lines.append(f"| {r['protocol']} | {r['seed']} | {r['true']} | {r['chosen']} | "
                     f"{(r['total'][r['true']] - other) / 2.302585:.1f} |")
    lines += ["", "| protocol | true \\ chosen | " + " | ".join(names) + " |", "|---|---|" + "---|" * len(names)]
    for pname in protocols:
        for h in names:
            mine = [r["chosen"] for r in rows if r["protocol"] == pname and r["true"] == h]
            lines.append(f"| {pname} | {h} | " + " | ".join(f"{mine.count(c) / len(mine):.2f}" for c in names) + " |")
    write_text(a.out / "loop.md", "\n".join(lines) + "\n")
    write_text(a.out / "loop.json", json.dumps({"n": a.n, "rows": rows, "elapsed_s": time.perf_counter() - t0},
                                               indent=1) + "\n")
    print("\n".join(lines))
    print(f"{time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
