"""How Study 2's selection rule trades the paper's headline against its target-containing tests (a MODEL).

De Vlam et al. (IEEE ToH 16(4), 2023, doi:10.1109/TOH.2023.3270362, Sec. III.C) found
fewer points selected with the inverse filter than with funneling (about 20 %), and on
only the trials whose selection held the target, neither the method nor the location
effect. The default hypothesis reproduces the first in most held-out studies but not the
second as often as the issue's baseline model did (docs/simulated-participants.md, "What
the model does not reproduce"). This script asks whether another way of choosing the
selected points would hold both. Each rule below gets the same participants, the same
posteriors and the same random draws (:func:`~vibrofocus.simulation.bank.simulate_cell_means`
with ``rule=``); only how the answer and the selection follow from the posterior changes:

    python scripts/selection_rules.py [--seeds 800 840] [--plot FILE]

prints, per rule and setting, in how many studies (20 participants each, default
hypothesis and its fitted parameters, the paper's levels) the Study 2 headline holds
(fewer points with the inverse filter, Friedman + Bonferroni Wilcoxon, a 10-30 %
reduction), the median reduction, and the shares of the two target-containing tests that
are not significant; and, since some rules move the answers too, the Study 1 direction
(the inverse filter's error below funneling's, Bonferroni) and the Study 1 interaction's
significance. All are analysed with pingouin and scipy by ``vibrofocus_tools.findings`` (``scripts/check_findings.py``). The
default seeds are not the fit's held-out ones (``vibrofocus.simulation.fitting.HELD_OUT_SEEDS``).
Only the answer rule varies here (most rules change the selection only; the diffuse trials
and both unfused families move the answers too, and may switch the conflict's own noise
off; the width read from the trial's discrepancy draws the place's noise in two parts, so
its answers are new draws of the same law, and two of its settings raise the conflict's
noise), the rest of the model stays as fitted; a rule
worth adopting would then be refitted with ``scripts/fit_participants.py`` like every
hypothesis.
"""


from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Callable

import numpy as np

from vibrofocus.simulation.bank import FeatureBank, simulate_cell_means
from vibrofocus.simulation.hypotheses import hypothesis
from vibrofocus.simulation.perception import (Percepts, PerceptualModel, TrialPosteriors, location_distances,
                                              posterior_ratio_rule, select_locations, unfuse)

from .baseline import HEADLINE_BAR, baseline
from .findings import findings

PITCH_M = 10e-3  # the 3 x 3 grid's pitch (the shipped bank)


def baseline_share(key: str) -> float:
    """Share of the studies in which c313a27's participants (the issue's baseline) held the
    finding ``key``, over every seed range measured (seeds 700-739 and 800-999)."""
    seeds = baseline().values()
    return sum(v["holds"][key] for v in seeds) / sum(v["studies"] for v in seeds)


#: The baseline's shares that a rule must not fall below: the target-containing method
#: test not significant (121 of 240) and the Study 1 interaction significant (128 of 240).
BASELINE_HIT_METHOD_NS = baseline_share("s2_hit_method_ns")
BASELINE_INTERACTION = baseline_share("s1_interaction")


def capped(k_max: int) -> Callable[..., tuple[np.ndarray, np.ndarray]]:
    """The model's rule, keeping at most the ``k_max`` most probable locations."""
    def rule(post: TrialPosteriors, criterion: np.ndarray, locations_xy: np.ndarray, allowed: Any,
             percepts: Percepts, index: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        d2 = location_distances(post.perceived_m, locations_xy, allowed)
        answer, selected = select_locations(d2, post.sd_m, criterion)
        rank = np.argsort(np.argsort(d2, axis=1), axis=1)  # 0 = nearest
        return answer, selected & (rank < k_max)
    return rule


def fixed_width(exponent: float, reference_m: float) -> Callable[..., tuple[np.ndarray, np.ndarray]]:
    """Selection width ``sd^a * ref^(1-a)``: less of the posterior's stimulus-level width, more a fixed habit."""
    def rule(post: TrialPosteriors, criterion: np.ndarray, locations_xy: np.ndarray, allowed: Any,
             percepts: Percepts, index: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        d2 = location_distances(post.perceived_m, locations_xy, allowed)
        return select_locations(d2, post.sd_m**exponent * reference_m ** (1.0 - exponent), criterion)
    return rule


def hedge_to_centre(tau: float) -> Callable[..., tuple[np.ndarray, np.ndarray]]:
    """The selection centred a fraction ``tau`` of the way from the percept to the grid's centre."""
    def rule(post: TrialPosteriors, criterion: np.ndarray, locations_xy: np.ndarray, allowed: Any,
             percepts: Percepts, index: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        locs = np.asarray(locations_xy, dtype=float)
        d2 = location_distances(post.perceived_m, locs, allowed)
        answer = np.argmin(d2, axis=1)
        hedged = post.perceived_m + tau * (locs.mean(axis=0) - post.perceived_m)
        _, selected = select_locations(location_distances(hedged, locs, allowed), post.sd_m, criterion)
        selected[np.arange(answer.size), answer] = True
        return answer, selected
    return rule


@dataclass
class DiffuseTrials:
    """Some trials' percepts are displaced and the participant does not know by how much.

    With probability ``gain * conflict / pitch`` (the distance between the skin and the
    drive cue, per grid pitch) a trial's percept jumps by a normal displacement of SD
    ``jump_m`` per axis, which moves both the answer and the selection; the selection's
    width stays the posterior's. Its own generator (``seed``) keeps the shared draws
    unchanged.
    """

    gain: float
    jump_m: float
    seed: int = 0
    rng: np.random.Generator = field(init=False, repr=False)

    def __post_init__(self) -> None:
        self.rng = np.random.default_rng([self.seed, 0xD1F])

    def __call__(self, post: TrialPosteriors, criterion: np.ndarray, locations_xy: np.ndarray, allowed: Any,
                 percepts: Percepts, index: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        n = index.size
        conflict = (np.nan_to_num(percepts.conflict_m[index]) if percepts.conflict_m is not None else np.zeros(n))
        jumped = self.rng.random(n) < np.clip(self.gain * conflict / PITCH_M, 0.0, 1.0)
        perceived = post.perceived_m + np.where(jumped[:, None], self.rng.standard_normal((n, 2)) * self.jump_m, 0.0)
        return select_locations(location_distances(perceived, locations_xy, allowed), post.sd_m, criterion)


@dataclass
class FeltAtDrive:
    """Unfused trials felt at the drive cue's place (where the actuators push), not at a random angle.

    With probability ``per_m * conflict`` a trial's percept moves by ``fraction`` of the way
    from the felt place to the drive cue's place and its selection widens by ``width``.
    Its own generator (``seed``) keeps the shared draws unchanged.
    """

    per_m: float
    fraction: float
    width: float
    seed: int = 0
    rng: np.random.Generator = field(init=False, repr=False)
    unfusing: PerceptualModel = field(init=False, repr=False)

    def __post_init__(self) -> None:
        self.rng = np.random.default_rng([self.seed, 0xD21])
        # The model's own unfusing decides which trials and how much wider, with no jump of
        # its own: the displacement is toward the drive cue instead of at a random angle.
        self.unfusing = PerceptualModel().replace(unfused_per_m=self.per_m, unfused_jump_m=0.0,
                                                  unfused_width=self.width)

    def __call__(self, post: TrialPosteriors, criterion: np.ndarray, locations_xy: np.ndarray, allowed: Any,
                 percepts: Percepts, index: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        if percepts.drive_position_m is None:  # no drive cue: nothing to be felt at
            return posterior_ratio_rule(post, criterion, locations_xy, allowed, percepts, index)
        wider, unfused = unfuse(post, percepts.conflict_m[index], self.unfusing, self.rng.random(index.size),
                                np.zeros(index.size))
        shift = np.nan_to_num(percepts.drive_position_m[index] - percepts.position_m[index])
        moved = replace(wider, perceived_m=wider.perceived_m + np.where(unfused[:, None], self.fraction * shift, 0.0))
        return posterior_ratio_rule(moved, criterion, locations_xy, allowed, percepts, index)


@dataclass(frozen=True)
class Setting:
    """One rule with its parameters, and the changes to the fitted model it runs with."""

    family: str
    label: str
    make: Callable[[int], Callable[..., tuple[np.ndarray, np.ndarray]]]
    changes: tuple[tuple[str, Any], ...] = ()


def settings(model: PerceptualModel) -> list[Setting]:
    """The rules compared, each over a few settings (the shipped rule first)."""
    k = model.select_kappa
    wide, narrow = (max(0.05, k[0] - 0.15), max(0.2, k[1] - 0.1)), (min(0.9, k[0] + 0.15), 0.99)
    out = [Setting("posterior ratio (shipped)", f"kappa {k[0]:.2f}-{k[1]:.2f}", lambda s: posterior_ratio_rule)]
    out += [Setting("posterior ratio (shipped)", f"kappa {a:.2f}-{b:.2f}", lambda s: posterior_ratio_rule,
                    (("select_kappa", (a, b)),)) for a, b in (wide, narrow)]
    out += [Setting("at most K points", f"K = {kk}", lambda s, kk=kk: capped(kk)) for kk in (2, 3)]
    out += [Setting("partly fixed width", f"a = {a}, ref = {r * 1e3:.0f} mm", lambda s, a=a, r=r: fixed_width(a, r))
            for a in (0.5, 0.75) for r in (6e-3, 10e-3)]
    out += [Setting("hedge toward the centre", f"tau = {t}", lambda s, t=t: hedge_to_centre(t)) for t in (0.25, 0.5)]
    out += [Setting("hedge toward the centre", f"tau = 0.25, kappa {narrow[0]:.2f}-{narrow[1]:.2f}",
                    lambda s: hedge_to_centre(0.25), (("select_kappa", narrow),))]
    out += [Setting("diffuse trials", f"gain {g}, jump {j * 1e3:.0f} mm", lambda s, g=g, j=j: DiffuseTrials(g, j, s))
            for g in (1.0, 2.0) for j in (15e-3, 25e-3)]
    # The model's unfused percepts (PerceptualModel.unfused_*), the conflict's own noise off;
    # the rule stays the shipped one.
    out += [Setting("unfused percepts", f"{p:.0f}/m, jump {j * 1e3:.0f} mm, width x{w:g}", lambda s: posterior_ratio_rule,
                    (("conflict_gain", 0.0), ("unfused_per_m", p), ("unfused_jump_m", j), ("unfused_width", w)))
            for p, j, w in ((200.0, 20e-3, 2.5), (300.0, 20e-3, 2.5), (250.0, 36e-3, 3.8))]
    # Unfused percepts felt where the actuators push (the drive cue's place), not at a random
    # angle: a displacement structured by the stimulus, as the paper's partial contact near
    # locations 1 and 3 would make it (Sec. IV).
    out += [Setting("felt at the drive cue", f"{p:.0f}/m, {f:g}x the way, width x{w:g}" + (", conflict noise off" if quiet else ""),
                    lambda s, p=p, f=f, w=w: FeltAtDrive(p, f, w, s), (("conflict_gain", 0.0),) if quiet else ())
            for p, f, w, quiet in ((100.0, 1.0, 1.0, False), (200.0, 2.0, 1.0, False), (200.0, 1.0, 1.5, False),
                                (400.0, 1.0, 2.5, True))]
    # The selection's width reads the trial's own cue discrepancy (PerceptualModel.
    # conflict_awareness), alone and with more conflict noise; the rule stays the shipped one.
    out += [Setting("width from the trial's discrepancy", f"lambda {lam:g}" + (f", conflict gain {g:g}" if g else ""),
                    lambda s: posterior_ratio_rule,
                    (("conflict_awareness", lam),) + ((("conflict_gain", g),) if g else ()))
            for lam, g in ((1.0, None), (1.2, None), (1.0, 2.6), (0.9, 3.0))]
    return out


#: The findings whose shares the comparison reports (``check_findings.findings``' keys).
SHARES = ("s1_inverse_lower", "s1_interaction", "s2_headline", "s2_hit_location_ns", "s2_hit_method_ns")


def meets_bars(share: dict[str, float]) -> bool:
    """Both headlines in two thirds of the studies, and the interaction and the target-containing
    method test at least at c313a27's shares."""
    return (share["s2_headline"] >= HEADLINE_BAR and share["s1_inverse_lower"] >= HEADLINE_BAR
            and share["s2_hit_method_ns"] >= BASELINE_HIT_METHOD_NS and share["s1_interaction"] >= BASELINE_INTERACTION)


def run(setting: Setting, seeds: range, n: int, bank: FeatureBank, name: str | None = None) -> dict[str, float]:
    """Shares of ``seeds``' studies in which each finding of :data:`SHARES` holds under one setting."""
    h = hypothesis(name)
    model = h.model().replace(**dict(setting.changes))
    res = []
    for s in seeds:
        arrays = simulate_cell_means(n, np.random.default_rng([s, 16]), bank=bank, model=model, hypothesis=h,
                                     rule=setting.make(s))
        res.append(findings(arrays.error_mm, arrays.count, arrays.count_hit))
    share = {key: float(np.mean([r[key] for r in res])) for key in SHARES}
    share["reduction"] = float(np.median([r["s2_reduction"] for r in res]))
    return share


@dataclass
class Recorder:
    """The shipped rule, keeping each call's selections and stimuli (the bank's stimulus ``m * 9 + l``)."""

    calls: list[tuple[np.ndarray, np.ndarray]] = field(default_factory=list)

    def __call__(self, post: TrialPosteriors, criterion: np.ndarray, locations_xy: np.ndarray, allowed: Any,
                 percepts: Percepts, index: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        answer, selected = posterior_ratio_rule(post, criterion, locations_xy, allowed, percepts, index)
        self.calls.append((selected, index))
        return answer, selected


def points_by_outcome(seeds: range, n: int, bank: FeatureBank, name: str | None = None) -> str:
    """Mean points selected per method on the trials whose selection holds the target, and on the others."""
    h = hypothesis(name)
    n_loc = len(bank.locations_xy)
    sums = np.zeros((len(bank.methods), 2, 2))  # method, (miss, hit), (points, trials)
    for s in seeds:
        rec = Recorder()
        simulate_cell_means(n, np.random.default_rng([s, 16]), bank=bank, hypothesis=h, rule=rec)
        for selected, index in rec.calls[1::2]:  # Study 2: every participant's second call
            hit = selected[np.arange(index.size), index % n_loc].astype(int)
            np.add.at(sums, (index // n_loc, hit, 0), selected.sum(axis=1))
            np.add.at(sums, (index // n_loc, hit, 1), 1)
    lines = [f"Points selected under the shipped rule, seeds {seeds.start}-{seeds.stop - 1} ({h.label()}):"]
    for m, meth in enumerate(bank.methods):
        share = sums[m, 1, 1] / sums[m, :, 1].sum()
        lines.append(f"  {meth:12s} selection holds the target in {share:.0%} of trials; points "
                     f"{sums[m, 1, 0] / sums[m, 1, 1]:.2f} on those, {sums[m, 0, 0] / sums[m, 0, 1]:.2f} on the others")
    return "\n".join(lines)


def markdown(rows: list[tuple[Setting, dict[str, float]]], seeds: range, n: int) -> str:
    lines = [f"Seeds {seeds.start}-{seeds.stop - 1} ({len(seeds)} studies of {n}; not the held-out seeds), "
             f"{hypothesis(None).label()}. Bars: the Study 2 headline and the Study 1 direction in at least "
             f"{HEADLINE_BAR:.0%} of the studies, the target-containing method test n.s. in at least "
             f"{BASELINE_HIT_METHOD_NS:.0%} and the Study 1 interaction significant in at least "
             f"{BASELINE_INTERACTION:.0%} (c313a27's shares).",
             "",
             "| rule | setting | fewer points *and* 10-30 % | median reduction | target-containing location n.s. "
             "| target-containing method n.s. | Study 1: inverse below funneling | Study 1 interaction | all bars |",
             "|---|---|---:|---:|---:|---:|---:|---:|:---:|"]
    for s, r in rows:
        lines.append(f"| {s.family} | {s.label} | {r['s2_headline']:.0%} | {r['reduction']:.1%} "
                     f"| {r['s2_hit_location_ns']:.0%} | {r['s2_hit_method_ns']:.0%} | {r['s1_inverse_lower']:.0%} "
                     f"| {r['s1_interaction']:.0%} | {'yes' if meets_bars(r) else 'no'} |")
    return "\n".join(lines)


def plot(rows: list[tuple[Setting, dict[str, float]]], path: Path, seeds: range) -> None:
    """Headline share against the target-containing method test's n.s. share, per rule (PNG).

    A hollow marker: the setting loses the Study 1 direction or the interaction (below its bar).
    """
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from vibrofocus.io import save_figure
    from vibrofocus.simulation import model_footer

    fig, ax = plt.subplots(figsize=(9.4, 5.0))
    ax.axvspan(HEADLINE_BAR, 1.02, ymin=0, ymax=1, color="0.93", zorder=0)
    ax.axhline(BASELINE_HIT_METHOD_NS, color="0.4", ls="--", lw=1)
    ax.axvline(HEADLINE_BAR, color="0.4", ls="--", lw=1)
    ax.fill_between([HEADLINE_BAR, 1.02], BASELINE_HIT_METHOD_NS, 1.02, color="#d8f0d8", zorder=0,
                    label="Study 2 bars met")
    markers = dict(zip(dict.fromkeys(s.family for s, _ in rows), "osD^v<>P"))
    for (fam, mk), colour in zip(markers.items(), plt.rcParams["axes.prop_cycle"].by_key()["color"]):
        mine = [r for s, r in rows if s.family == fam]
        study1 = [r["s1_inverse_lower"] >= HEADLINE_BAR and r["s1_interaction"] >= BASELINE_INTERACTION
                  for r in mine]
        ax.scatter([r["s2_headline"] for r in mine], [r["s2_hit_method_ns"] for r in mine], marker=mk, s=46,
                   label=fam, zorder=3, edgecolors=colour, linewidths=1.3,
                   facecolors=[colour if ok else "none" for ok in study1])
    ax.set_xlim(-0.02, 1.02)
    ax.set_ylim(-0.02, 1.02)
    ax.set_xlabel("studies with fewer points for the inverse filter and a 10-30 % reduction")
    ax.set_ylabel("studies whose target-containing method test is n.s.")
    ax.set_title(f"Study 2 selection rules (seeds {seeds.start}-{seeds.stop - 1})", fontsize=10)
    ax.legend(fontsize=7.5, loc="center left", bbox_to_anchor=(1.02, 0.5), title="hollow: Study 1 below its bars",
              title_fontsize=7.5)
    model_footer(fig, hypothesis(None).label())
    fig.tight_layout(rect=(0, 0.03, 1, 1))
    save_figure(fig, path, dpi=110)
    plt.close(fig)
