"""Study power by simulation: every hypothesis of the simulated participants, side by side,
and the files of the result (docs/simulated-participants.md, "Power")."""

from __future__ import annotations

import contextlib
import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .progress import Progress, QuietProgress

__all__ = ["PowerOutcome", "study_power", "write_power"]


@dataclass(frozen=True)
class PowerOutcome:
    """What :func:`study_power` computed and wrote.

    Attributes
    ----------
    result : dict
        The first hypothesis' result with every hypothesis' table, the robust
        conclusions, the directional claims and the paper's implied power (power.json).
    per : dict
        :func:`~vibrofocus.simulation.power.run_power`'s result per hypothesis name.
    design : PowerDesign
        The design simulated (``hypothesis``: the first one).
    paths : list of Path
        The files written (power.json, power.csv, power.png), empty without ``out``.
    """

    result: dict[str, Any]
    per: dict[str, dict[str, Any]]
    design: Any
    paths: list[Path]


def study_power(
    *,
    participants: tuple[int, ...],
    studies: int = 200,
    repetitions: int = 3,
    methods: tuple[str, ...] | None = None,
    bank: Path | None = None,
    locations: tuple[int, ...] | None = None,
    alpha: float = 0.05,
    seed: int = 0,
    scheduler: str | None = None,
    workers: int | None = None,
    local: bool = False,
    out: Path | None = None,
    hypotheses: str = "all",
    skin: str = "nominal",
    progress: Progress | None = None,
) -> PowerOutcome:
    """Simulate studies under each hypothesis and report each test's power against N.

    Parameters
    ----------
    participants : tuple of int
        The numbers of participants N.
    studies : int
        Simulated studies per N and hypothesis.
    repetitions : int
        Trials per condition and study.
    methods : tuple of str, optional
        At least two of the feature bank's methods (default the bank's).
    bank : Path, optional
        A feature bank (.npz); default the shipped one.
    locations : tuple of int, optional
        Location numbers, at least two (default every location).
    alpha : float
        Significance level, in (0, 1).
    seed : int
        Seed of the simulated studies (not a participant's: the docdict's ``seed`` is one arm's).
    scheduler : str, optional
        Dask scheduler address; default a LocalCluster.
    workers : int, optional
        Workers of the LocalCluster.
    local : bool
        Run in this process without Dask (the same numbers).
    out : Path, optional
        Folder for power.json, power.csv and power.png (checked before the simulations).
    hypotheses : str
        ``"all"`` or hypothesis names, comma separated.
    skin : str
        Skin preset; only the one the model is fitted on.
    progress : Progress, optional
        The model's label first (``notice=True``), then one step per simulated study.

    Returns
    -------
    PowerOutcome
    """
    from .._validation import check_in_range
    from ..errors import ValidationError
    from ..simulation.hypotheses import available_hypotheses, hypothesis as find_hypothesis
    from ..simulation.perception import MODEL_LABEL, STUDY_SKIN
    from ..simulation.power import (CONTRASTS, PowerDesign, dask_client, direction_sentences, effect_directions,
                                    paper_implied_power, paper_implied_wilcoxon_power,
                                    robust_conclusions, run_power)
    from ..skin import skin_preset

    progress = progress if progress is not None else QuietProgress()
    if skin_preset(skin).name != STUDY_SKIN:
        # Its effect sizes come from a model fitted on one skin: on another, the numbers
        # would look like power but rest on nothing fitted.
        raise ValidationError(
            f"--skin {skin}: the simulated participants' perceptual model and its feature bank are fitted on "
            f"the {STUDY_SKIN} skin only; power on {skin} needs them refitted on it first"
        )
    check_in_range(alpha, "--alpha", 0.0, 1.0, inclusive=False)
    names = (available_hypotheses() if hypotheses.strip() == "all"
             else tuple(dict.fromkeys(find_hypothesis(h.strip()).name for h in hypotheses.split(",") if h.strip())))
    if not names:
        raise ValidationError("--hypotheses: name at least one (or all)")
    design = PowerDesign(
        n_participants=participants, n_studies=studies, repetitions=repetitions, methods=methods,
        locations=locations, alpha=alpha, seed=seed, hypothesis=names[0],
    )
    feature_bank = None
    if bank is not None:
        from ..simulation.bank import FeatureBank

        feature_bank = FeatureBank.load(bank)
    if out is not None:
        from .._atomic import check_writable, make_output_folder

        make_output_folder(out)
        check_writable(out / "power.json", what="power results")  # before the simulations, not after
    progress.note(MODEL_LABEL, notice=True)
    per: dict[str, dict] = {}
    each = len(design.n_participants) * design.n_studies
    progress.step(0, each * len(names), "studies")
    # One cluster for every hypothesis: workers start once, and stop once at the end.
    with contextlib.ExitStack() as stack:
        client = None if local else stack.enter_context(dask_client(scheduler=scheduler, n_workers=workers))
        for k, name in enumerate(names):
            per[name] = run_power(
                dataclasses.replace(design, hypothesis=name), client=client, local=local, bank=feature_bank,
                progress=lambda done, total, _k=k: progress.step(_k * each + done, each * len(names), "studies"),
            )
    result = dict(per[names[0]])
    result["hypotheses"] = {name: {"label": r["label"], "hypothesis": r["hypothesis"], "table": r["table"]}
                            for name, r in per.items()}
    tables = {name: r["table"] for name, r in per.items()}
    result["robust"] = robust_conclusions(tables)
    result["directional"] = {c: {name: r["directional"][c] for name, r in per.items() if c in r["directional"]}
                             for c in CONTRASTS if any(c in r["directional"] for r in per.values())}
    directions = effect_directions(tables)
    result["directions"] = directions
    result["direction_sentences"] = direction_sentences(directions)
    result["paper_implied"] = paper_implied_power(design.n_participants, alpha)
    result["paper_implied_study2"] = paper_implied_wilcoxon_power(design.n_participants, alpha)
    result["elapsed_s"] = sum(r["elapsed_s"] for r in per.values())
    return PowerOutcome(result, per, design, write_power(result, out) if out is not None else [])


def write_power(result: dict, out: Path) -> list[Path]:
    """Write power.json, power.csv (the table) and power.png (power against N per test).

    Each file appears whole or not at all (:mod:`vibrofocus._atomic`) and says it comes
    from simulated participants: ``label`` in the JSON, ``hypothesis`` and ``model``
    columns in the CSV (one block of rows per hypothesis, with ``robust``: every hypothesis
    agrees), the title of the plot (the first hypothesis').
    """
    import json

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import pandas as pd

    from .._atomic import save_figure, write_text
    from ..simulation.power import DIRECTIONAL_TESTS, TESTS

    hyps = result.get("hypotheses") or {result.get("hypothesis", {}).get("name", "v3-centroid"):
                                         {"label": result["label"], "table": result["table"]}}
    robust = {(r["test"], r["n_participants"]): r["robust"] for r in result.get("robust", [])}
    table = pd.concat([pd.DataFrame(h["table"]).assign(hypothesis=name, model=h["label"]) for name, h in hyps.items()],
                      ignore_index=True)
    table["robust"] = [robust.get((t, n)) for t, n in zip(table["test"], table["n_participants"])]
    csv = write_text(out / "power.csv", table.to_csv(index=False), what="power table")
    keys = ("label", "levels", "hypothesis", "design", "table", "hypotheses", "robust", "directional", "directions",
            "direction_sentences", "paper_implied", "paper_implied_study2", "elapsed_s")
    js = write_text(out / "power.json", json.dumps({k: result[k] for k in keys if k in result}, indent=1),
                    what="power results")
    first = next(iter(hyps))
    table = table[table["hypothesis"] == first]
    fig, ax = plt.subplots(figsize=(7, 4.5))
    try:
        for key, label in TESTS + DIRECTIONAL_TESTS:
            t = table[table["test"] == key]
            if t.empty:
                continue
            ax.errorbar(t["n_participants"], t["power"], yerr=t["se"], marker="o", capsize=3, label=label)
        ax.axhline(0.8, color="grey", lw=0.8, ls="--")
        ax.set_xlabel("participants N")
        ax.set_ylabel("power")
        ax.set_ylim(-0.02, 1.02)
        levels = f"; stimuli at {result['levels']} levels" if "levels" in result else ""
        ax.set_title(f"Power by simulation — {result['label']}{levels}", fontsize=9)
        ax.legend(fontsize=7, loc="lower right")
        fig.tight_layout()
        png = save_figure(fig, out / "power.png", what="power plot", dpi=120)
    finally:
        plt.close(fig)
    return [js, csv, png]
