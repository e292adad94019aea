"""Where to put the actuators: a search of positions for the best worst-target peak contrast.

:func:`search_layout` places ``n_actuators`` on candidate positions of a :class:`Region` (a
rectangle of the arm, or a band around it, unrolled) so that the worst target's peak contrast
(against the other targets, at the drive limit) is the largest, with every target's fidelity
at or above a floor. It builds a layout greedily, one actuator at a time, then refines every
start (the greedy one and, for four actuators, the paper's 2 x 2 at 45 mm) by moving one
actuator at a time to a neighbouring candidate while that improves the score; the result is
the best start's, so it is never worse than the paper's layout when that is a start. The
transfer of every candidate is computed once; the designs fan out on a Dask client when one
is given. The method and its defaults: docs/design-layout.md.
"""

from __future__ import annotations

import dataclasses
import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ._validation import as_array, check_positive
from .defaults import BAND_HZ, DRIVE_LIMIT_V, FS_HZ
from .errors import ValidationError, VibrofocusError
from .layout import ArrayLayout

__all__ = ["LayoutScore", "PlacementResult", "PlacementSettings", "Region", "comparison_rows", "paper_layout",
           "plot_layout", "search_layout", "score_layout"]

#: Methods the search designs with (each target's tap through ``render``).
PLACEMENT_METHODS = ("inverse", "minimax")
#: A guard closer than this to a target is left out (it would hold the target itself down), m.
_GUARD_CLEARANCE_M = 5e-3


@dataclass(frozen=True)
class Region:
    """Where actuators may sit, in the layout frame (x across the arm, y along it), m.

    Parameters
    ----------
    x_m, y_m : (float, float)
        The region's extent across and along the arm, m.
    circumference_m : float, optional
        A band around the arm: x is arc length and wraps at this circumference (the band's
        ``x_m`` is then ``(-C / 2, C / 2)``). None: a rectangle.
    """

    x_m: tuple[float, float]
    y_m: tuple[float, float]
    circumference_m: float | None = None

    def __post_init__(self) -> None:
        for name in ("x_m", "y_m"):
            lo, hi = (float(v) for v in getattr(self, name))
            if not (np.isfinite(lo) and np.isfinite(hi) and hi > lo):
                raise ValidationError(f"region {name} must be (low, high) with high > low, m; got {(lo, hi)}")
            object.__setattr__(self, name, (lo, hi))
        if self.circumference_m is not None:
            object.__setattr__(self, "circumference_m", check_positive(self.circumference_m, "circumference_m"))

    @classmethod
    def rectangle(cls, width_m: float = 0.09, length_m: float = 0.09,
                  centre_xy: tuple[float, float] = (0.0, 0.0)) -> "Region":
        """A rectangle ``width_m`` across by ``length_m`` along the arm, centred on ``centre_xy`` (m)."""
        w, h = check_positive(width_m, "width_m"), check_positive(length_m, "length_m")
        cx, cy = (float(v) for v in centre_xy)
        return cls((cx - w / 2, cx + w / 2), (cy - h / 2, cy + h / 2))

    @classmethod
    def band(cls, circumference_m: float, length_m: float, centre_y_m: float = 0.0) -> "Region":
        """A band around the arm, ``length_m`` long, centred at ``centre_y_m`` (x wraps)."""
        c = check_positive(circumference_m, "circumference_m")
        h = check_positive(length_m, "length_m")
        return cls((-c / 2, c / 2), (centre_y_m - h / 2, centre_y_m + h / 2), circumference_m=c)

    def candidates(self, pitch_m: float) -> np.ndarray:
        """Cell centres of a grid of ``pitch_m`` over the region, shape (n, 2), m."""
        pitch = check_positive(pitch_m, "pitch_m")
        axes = []
        for lo, hi in (self.x_m, self.y_m):
            n = max(int(np.floor((hi - lo) / pitch + 1e-9)), 1)
            axes.append((lo + hi) / 2 + (np.arange(n) - (n - 1) / 2) * pitch)
        return np.array([[x, y] for y in axes[1][::-1] for x in axes[0]])

    def contains(self, xy: np.ndarray) -> np.ndarray:
        """Whether points lie in the region (bool per point)."""
        p = np.atleast_2d(xy)
        tol = 1e-9
        return ((p[:, 0] >= self.x_m[0] - tol) & (p[:, 0] <= self.x_m[1] + tol)
                & (p[:, 1] >= self.y_m[0] - tol) & (p[:, 1] <= self.y_m[1] + tol))

    def distances(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """Distances between the points of ``a`` (n, 2) and ``b`` (m, 2), m; around a band, the shorter way."""
        d = np.abs(np.asarray(a)[:, None, :] - np.asarray(b)[None, :, :])
        if self.circumference_m is not None:
            d[..., 0] = np.minimum(d[..., 0], self.circumference_m - d[..., 0])
        return np.hypot(d[..., 0], d[..., 1])

    def describe(self) -> str:
        """One line naming the region, in mm."""
        w, h = (self.x_m[1] - self.x_m[0]) * 1e3, (self.y_m[1] - self.y_m[0]) * 1e3
        if self.circumference_m is not None:
            return f"band {w:g} mm around by {h:g} mm along, y {self.y_m[0] * 1e3:g} to {self.y_m[1] * 1e3:g} mm"
        return (f"rectangle {w:g} x {h:g} mm, x {self.x_m[0] * 1e3:g} to {self.x_m[1] * 1e3:g} mm, "
                f"y {self.y_m[0] * 1e3:g} to {self.y_m[1] * 1e3:g} mm")

    def to_dict(self) -> dict:
        """JSON-ready description, m."""
        return {"x_m": list(self.x_m), "y_m": list(self.y_m), "circumference_m": self.circumference_m}


def paper_layout(targets_xy: np.ndarray | None = None) -> ArrayLayout:
    """The paper's 2 x 2 at 45 mm with its guards (docs/method.md, reference setup), on ``targets_xy``
    (default the paper's nine locations)."""
    ref = ArrayLayout.reference()
    if targets_xy is None:
        return ref
    return ArrayLayout(ref.actuators_xy, targets_xy, ref.guards_xy, spacing_xy=ref.spacing_xy, name=ref.name)


@dataclass(frozen=True)
class PlacementSettings:
    """What :func:`search_layout` searches.

    Parameters
    ----------
    region : Region
        Where actuators may sit (default a 90 x 90 mm rectangle around the paper's grid).
    n_actuators : int
        Actuators to place (default 4).
    targets_xy : ndarray, shape (n_targets, 2), optional
        Target points, m: the layout's locations, numbered in this order (default the
        paper's nine locations at 10 mm pitch).
    min_spacing_m : float
        Least distance between two actuators' centres, m (default 20 mm: a 14 mm exciter's
        footprint and room for its guard).
    pitch_m : float
        Candidate grid pitch, m (default 15 mm, which holds the paper's positions at
        +-22.5 mm on the default region).
    method : {"inverse", "minimax"}
        The design each target gets. The inverse filter by default: minimax takes seconds
        per design, hundreds of times the inverse filter's, and the search makes thousands.
    method_options : dict
        Further ``render`` keywords of the method (``min_fidelity`` for minimax, ...).
    limit_v : float
        Drive limit, V peak: every design is scaled to it.
    min_fidelity : float
        Fidelity floor of every target, in (0, 1]; a layout below it at any target ranks
        below every layout that meets it.
    guard_offset_m : float or None
        Each actuator gets a guard this far toward the targets' centroid (as the reference
        setup's, 9 mm), left out within 5 mm of a target; None: no guards.
    n_samples : int
        Design window, samples; a design that does not fit it is made with the window's ends
        tapered, as a study does.
    fs : float
        Sample rate, Hz.
    band : (float, float)
        Design band, Hz; the transfer is computed up to half an octave beyond it, as a
        calibration holds it.
    max_rounds : int
        Most refinement rounds per start.
    """

    region: Region = field(default_factory=Region.rectangle)
    n_actuators: int = 4
    targets_xy: np.ndarray | None = None
    min_spacing_m: float = 0.02
    pitch_m: float = 0.015
    method: str = "inverse"
    method_options: dict = field(default_factory=dict)
    limit_v: float = DRIVE_LIMIT_V
    min_fidelity: float = 0.8
    guard_offset_m: float | None = 9e-3
    n_samples: int = 4096
    fs: float = FS_HZ
    band: tuple[float, float] = BAND_HZ
    max_rounds: int = 10

    def __post_init__(self) -> None:
        if not isinstance(self.region, Region):
            raise ValidationError(f"region must be a Region, got {type(self.region).__name__}")
        if isinstance(self.n_actuators, bool) or not isinstance(self.n_actuators, (int, np.integer)) \
                or not 1 <= self.n_actuators <= 64:
            raise ValidationError(f"n_actuators must be an integer from 1 to 64, got {self.n_actuators!r}")
        targets = paper_layout().locations_xy if self.targets_xy is None else self.targets_xy
        targets = as_array(targets, "targets_xy", ndim=2, shape=(None, 2))
        if not 2 <= len(targets) <= 64:
            raise ValidationError(f"targets_xy must hold 2 to 64 targets (contrast is against the others), "
                                  f"got {len(targets)}")
        object.__setattr__(self, "targets_xy", targets)
        if self.method not in PLACEMENT_METHODS:
            raise ValidationError(f"method must be one of {', '.join(PLACEMENT_METHODS)}, got {self.method!r}")
        for name in ("min_spacing_m", "pitch_m", "limit_v", "fs"):
            object.__setattr__(self, name, check_positive(getattr(self, name), name))
        if not 0 < self.min_fidelity <= 1:
            raise ValidationError(f"min_fidelity must lie in (0, 1], got {self.min_fidelity!r}")
        if self.guard_offset_m is not None:
            object.__setattr__(self, "guard_offset_m", check_positive(self.guard_offset_m, "guard_offset_m"))

    def to_dict(self) -> dict:
        """JSON-ready description (SI units)."""
        out = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        out["region"] = self.region.to_dict()
        out["targets_xy"] = np.asarray(self.targets_xy).tolist()
        return out


@dataclass(frozen=True)
class LayoutScore:
    """How one layout focuses at each target.

    Attributes
    ----------
    contrast_db, fidelity, target_peak_um, peak_drive_v : ndarray, shape (n_targets,)
        Per target: peak contrast against the other targets (dB), fidelity, the tap's peak
        at the target at the drive limit (µm) and the peak drive (V); NaN where the design failed.
    errors : tuple of str
        One line per target whose design failed (empty when none did).
    min_fidelity : float
        The floor the layout is judged against.
    """

    contrast_db: np.ndarray
    fidelity: np.ndarray
    target_peak_um: np.ndarray
    peak_drive_v: np.ndarray
    errors: tuple[str, ...]
    min_fidelity: float

    @property
    def feasible(self) -> bool:
        """Every target designed, at or above the fidelity floor."""
        return not self.errors and bool(np.all(self.fidelity >= self.min_fidelity))

    @property
    def worst_db(self) -> float:
        """The worst target's peak contrast, dB (-inf when a design failed)."""
        return float(np.min(self.contrast_db)) if not self.errors else -np.inf

    @property
    def mean_db(self) -> float:
        """The mean peak contrast over the targets, dB (-inf when a design failed)."""
        return float(np.mean(self.contrast_db)) if not self.errors else -np.inf

    @property
    def key(self) -> tuple[bool, float, float]:
        """The ranking: feasible first, then the worst target's contrast, then the mean."""
        return (self.feasible, round(self.worst_db, 9), round(self.mean_db, 9))

    def to_dict(self) -> dict:
        """JSON-ready description."""
        return {"feasible": self.feasible, "worst_db": self.worst_db, "mean_db": self.mean_db,
                "contrast_db": self.contrast_db.tolist(), "fidelity": self.fidelity.tolist(),
                "target_peak_um": self.target_peak_um.tolist(), "peak_drive_v": self.peak_drive_v.tolist(),
                "errors": list(self.errors), "min_fidelity": self.min_fidelity}


def score_layout(tm: Any, settings: PlacementSettings) -> LayoutScore:
    """Design a tap at every location of ``tm``'s layout and score the layout.

    Parameters
    ----------
    tm : TransferMatrix
        The layout's transfer (locations = the targets, then its guards).
    settings : PlacementSettings
        The method, its options, the drive limit and the fidelity floor.

    Returns
    -------
    LayoutScore
    """
    from .rendering import render

    n = tm.layout.n_locations
    out = {k: np.full(n, np.nan) for k in ("contrast_db", "fidelity", "target_peak_um", "peak_drive_v")}
    errors = []
    for i, location in enumerate(tm.layout.location_numbers):
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", UserWarning)  # minimax's drive notes: the score says it all
                d = render(settings.method, tm, tm.fs, tm.layout, location, limit_v=settings.limit_v,
                           bounds=False, taper_ends=True, **settings.method_options)
        except VibrofocusError as exc:
            errors.append(f"target {location}: {exc}")
            continue
        m = d.metrics()
        out["contrast_db"][i], out["fidelity"][i] = m["contrast_db"], m["fidelity"]
        out["target_peak_um"][i], out["peak_drive_v"][i] = m["target_peak_m"] * 1e6, m["peak_drive_v"]
    return LayoutScore(**out, errors=tuple(errors), min_fidelity=settings.min_fidelity)


@dataclass
class PlacementResult:
    """What :func:`search_layout` found.

    Attributes
    ----------
    layout : ArrayLayout
        The best layout (its locations are the targets, numbered in their order).
    score : LayoutScore
        Its score.
    paper : LayoutScore or None
        The paper's 2 x 2 at 45 mm on the same targets, limit and skin (None where its
        positions are off the modelled skin).
    starts : list of dict
        Each start (``label``, ``score`` before and ``refined`` after the refinement, ``rounds``).
    candidates_xy : ndarray, shape (n_candidates, 2)
        The candidate positions searched, m.
    n_layouts : int
        Layouts scored.
    elapsed_s : float
        Wall time of the search, s.
    settings : PlacementSettings
    """

    layout: ArrayLayout
    score: LayoutScore
    paper: LayoutScore | None
    starts: list[dict]
    candidates_xy: np.ndarray
    n_layouts: int
    elapsed_s: float
    settings: PlacementSettings

    def to_dict(self) -> dict:
        """JSON-ready description."""
        return {"layout": self.layout.to_dict(), "score": self.score.to_dict(),
                "paper": None if self.paper is None else self.paper.to_dict(),
                "starts": [{**s, "score": s["score"].to_dict(), "refined": s["refined"].to_dict()}
                           for s in self.starts],
                "n_candidates": len(self.candidates_xy), "n_layouts": self.n_layouts,
                "elapsed_s": self.elapsed_s, "settings": self.settings.to_dict()}


# ---------------------------------------------------------------------- the pool's transfer
def _pool_columns(participant: Any, actuators_xy: np.ndarray, rows_xy: np.ndarray, freqs: np.ndarray,
                  fs: float) -> np.ndarray:
    """Transfer from each of ``actuators_xy`` to ``rows_xy`` at ``freqs`` (a Dask task)."""
    from .skin import SimulatedArm

    params = _resized(participant, len(actuators_xy))
    layout = ArrayLayout(actuators_xy, rows_xy[:1], spacing_xy=(1.0, 1.0))
    return SimulatedArm(0, layout, fs, participant=params).transfer(rows_xy, freqs)


def _resized(participant: Any, n: int) -> Any:
    """``participant`` with ``n`` identical actuators: each per-actuator field its mean."""
    return dataclasses.replace(participant, **{k: np.full(n, float(np.mean(getattr(participant, k))))
                                               for k in ("contact", "gains", "f0_hz", "q")})


def _score_task(H_band: np.ndarray, bins: np.ndarray, layout: ArrayLayout, settings: PlacementSettings) -> LayoutScore:
    """Score one layout from its in-band transfer (a Dask task: only the band travels)."""
    from .rendering import TransferMatrix

    H = np.zeros((settings.n_samples // 2 + 1, *H_band.shape[1:]), dtype=complex)
    H[bins] = H_band
    return score_layout(TransferMatrix(H, settings.fs, layout, band=settings.band), settings)


class _Pool:
    """The candidates, their guards and their transfer, computed once."""

    def __init__(self, settings: PlacementSettings, candidates: np.ndarray, participant: Any,
                 mapper: Callable[[Callable, list[tuple]], list]):
        self.settings, self.candidates = settings, candidates
        targets = settings.targets_xy
        self.guards: list[int | None] = []
        guard_xy = []
        centroid = targets.mean(axis=0)
        for a in candidates:
            g = None
            if settings.guard_offset_m is not None:
                r = float(np.hypot(*(centroid - a)))
                if r > settings.guard_offset_m:
                    p = a + settings.guard_offset_m * (centroid - a) / r
                    if np.min(np.hypot(*(targets - p).T)) >= _GUARD_CLEARANCE_M:
                        g = len(targets) + len(guard_xy)
                        guard_xy.append(p)
            self.guards.append(g)
        self.rows = np.concatenate([targets, np.reshape(guard_xy, (-1, 2))])
        freqs = np.fft.rfftfreq(settings.n_samples, 1 / settings.fs)
        lo, hi = settings.band
        self.bins = np.flatnonzero((freqs >= lo / np.sqrt(2)) & (freqs <= min(hi * np.sqrt(2), settings.fs / 2)))
        chunks = [candidates[i:i + 8] for i in range(0, len(candidates), 8)]
        parts = mapper(_pool_columns, [(participant, c, self.rows, freqs[self.bins], settings.fs) for c in chunks])
        self.H = np.concatenate(parts, axis=2)  # (n_band, n_rows, n_candidates)

    def layout(self, chosen: Sequence[int], name: str = "designed") -> tuple[ArrayLayout, np.ndarray]:
        """The layout of candidates ``chosen`` and its in-band transfer."""
        chosen = list(chosen)
        guard_rows = [self.guards[c] for c in chosen if self.guards[c] is not None]
        rows = list(range(len(self.settings.targets_xy))) + guard_rows
        pitch = self.settings.pitch_m
        layout = ArrayLayout(self.candidates[chosen], self.settings.targets_xy, self.rows[guard_rows],
                             spacing_xy=(pitch, pitch), name=name)
        return layout, self.H[:, rows][:, :, chosen]


def search_layout(settings: PlacementSettings | None = None, *, participant: Any = None, client: Any = None,
                  progress: Callable[[str], None] | None = None) -> PlacementResult:
    """Search actuator positions that maximize the worst target's peak contrast at the drive limit.

    Parameters
    ----------
    settings : PlacementSettings, optional
        Region, number of actuators, targets, method, limit (default: the defaults of
        :class:`PlacementSettings`).
    participant : ForearmParameters, optional
        The skin model: the arm's parameters (a preset's nominal forearm,
        ``ForearmParameters.nominal(1, skin="nominal")``, the default, or a fitted model's
        ``FittedSkin.participant``); every actuator gets its mean per-actuator values.
    client : distributed.Client, optional
        Fan the transfer and the designs out on it; default in this process.
    progress : callable, optional
        Called with one line per step of the search.

    Returns
    -------
    PlacementResult

    Raises
    ------
    ValidationError
        The region holds fewer candidates than actuators, or none off the others by
        ``min_spacing_m``.
    """
    from .skin import ForearmParameters

    t0 = time.perf_counter()
    settings = settings if settings is not None else PlacementSettings()
    participant = participant if participant is not None else ForearmParameters.nominal(1, skin="nominal")
    say = progress if progress is not None else (lambda line: None)
    mapper = _mapper(client)
    region = settings.region
    grid = region.candidates(settings.pitch_m)
    paper = paper_layout().actuators_xy
    on_skin = _on_skin(participant, np.concatenate([grid, paper]))
    grid = grid[on_skin[:len(grid)]]
    # The paper's positions join the pool: as candidates where the region holds them, and for
    # the comparison in every case.
    extra = [p for p in paper if region.distances(p[None], grid).min(initial=np.inf) > 1e-6]
    candidates = np.concatenate([grid, np.reshape(extra, (-1, 2))]) if extra else grid
    allowed = region.contains(candidates)
    if allowed.sum() < settings.n_actuators:
        raise ValidationError(f"the region ({region.describe()}) holds {allowed.sum()} candidate positions on the "
                              f"skin at {settings.pitch_m * 1e3:g} mm pitch, fewer than the {settings.n_actuators} "
                              "actuators: widen it or lower the pitch")
    say(f"{allowed.sum()} candidate positions in the {region.describe()}; computing their transfer")
    pool = _Pool(settings, candidates, participant, mapper)
    apart = region.distances(candidates, candidates) >= settings.min_spacing_m - 1e-9
    counted = [0]

    def score_all(layouts: list[list[int]]) -> list[LayoutScore]:
        tasks = []
        for chosen in layouts:
            layout, H_band = pool.layout(chosen)
            tasks.append((H_band, pool.bins, layout, settings))
        counted[0] += len(tasks)
        return mapper(_score_task, tasks)

    def fits(chosen: list[int], c: int) -> bool:
        return bool(allowed[c]) and c not in chosen and all(apart[c, o] for o in chosen)

    starts = []
    # The greedy start: add the candidate that scores best, one actuator at a time.
    chosen: list[int] = []
    for k in range(settings.n_actuators):
        options = [c for c in range(len(candidates)) if fits(chosen, c)]
        if not options:
            raise ValidationError(f"no room for actuator {k + 1} of {settings.n_actuators} at least "
                                  f"{settings.min_spacing_m * 1e3:g} mm from the others in the {region.describe()}: "
                                  "widen the region or lower --min-spacing-mm")
        scores = score_all([chosen + [c] for c in options])
        best = max(range(len(options)), key=lambda i: scores[i].key)
        chosen = chosen + [options[best]]
        say(f"greedy: actuator {k + 1} of {settings.n_actuators}, worst target {scores[best].worst_db:+.2f} dB")
    starts.append(("greedy", chosen, scores[best]))
    paper_idx = [int(np.argmin(region.distances(p[None], candidates)[0])) for p in paper]
    paper_score = score_all([paper_idx])[0]
    if settings.n_actuators == 4 and all(allowed[paper_idx]) and all(
            apart[a, b] for i, a in enumerate(paper_idx) for b in paper_idx[i + 1:]):
        starts.append(("paper 2x2 at 45 mm", paper_idx, paper_score))
    # Local refinement: move one actuator to a neighbouring candidate while the score improves.
    near = region.distances(candidates, candidates) <= 1.5 * settings.pitch_m + 1e-9
    done = []
    for label, start, score in starts:
        current, current_score, rounds = list(start), score, 0
        for rounds in range(1, settings.max_rounds + 1):
            moves = [current[:i] + [c] + current[i + 1:] for i, a in enumerate(current)
                     for c in np.flatnonzero(near[a]) if fits(current[:i] + current[i + 1:], int(c))]
            scores = score_all(moves) if moves else []
            best = max(range(len(moves)), key=lambda i: scores[i].key, default=None)
            if best is None or not scores[best].key > current_score.key:
                break
            current, current_score = [int(c) for c in moves[best]], scores[best]
            say(f"refining the {label} start: round {rounds}, worst target {current_score.worst_db:+.2f} dB")
        done.append({"label": label, "positions_xy": candidates[current].tolist(), "score": score,
                     "refined": current_score, "rounds": rounds, "chosen": current})
    best = max(done, key=lambda s: s["refined"].key)
    layout, _ = pool.layout(best["chosen"], name=f"designed {settings.n_actuators} ({best['label']} start)")
    for s in done:
        del s["chosen"]
    return PlacementResult(layout, best["refined"], paper_score, done, candidates[allowed], counted[0],
                           time.perf_counter() - t0, settings)


def _on_skin(participant: Any, xy: np.ndarray) -> np.ndarray:
    """Whether points lie on the modelled forearm (the tapered cylinder between elbow and wrist)."""
    p = participant
    y = xy[:, 1]
    frac = (y - p.elbow_y_m) / (p.wrist_y_m - p.elbow_y_m)
    circumference = p.circumference_elbow_m + frac * (p.circumference_wrist_m - p.circumference_elbow_m)
    return (y >= p.elbow_y_m) & (y <= p.wrist_y_m) & (np.abs(xy[:, 0]) <= circumference / 2 + 1e-9)


def _mapper(client: Any) -> Callable[[Callable, list[tuple]], list]:
    """``map(fn, tasks)`` in this process, or on a Dask client (in order)."""
    if client is None:
        return lambda fn, tasks: [fn(*t) for t in tasks]

    def on_dask(fn: Callable, tasks: list[tuple]) -> list:
        if not tasks:
            return []
        return client.gather(client.map(fn, *zip(*tasks), pure=False))

    return on_dask


def comparison_rows(result: PlacementResult) -> list[dict]:
    """The table of the designed layout against the paper's 2 x 2 at 45 mm, one row per target
    then the worst and the mean (contrast dB, fidelity, the tap's peak at the limit µm)."""
    rows = []
    sides = [("designed", result.score)] + ([("paper", result.paper)] if result.paper is not None else [])
    for i in range(len(result.settings.targets_xy)):
        row = {"target": str(i + 1)}
        for name, s in sides:
            row |= {f"{name}_contrast_db": s.contrast_db[i], f"{name}_fidelity": s.fidelity[i],
                    f"{name}_tap_um": s.target_peak_um[i]}
        rows.append(row)
    for label, how in (("worst", np.min), ("mean", np.mean)):
        row = {"target": label}
        for name, s in sides:
            row |= {f"{name}_contrast_db": how(s.contrast_db), f"{name}_fidelity": how(s.fidelity),
                    f"{name}_tap_um": how(s.target_peak_um)}
        rows.append(row)
    return rows


def plot_layout(result: PlacementResult) -> Any:
    """Figure of the designed layout beside the paper's: actuators, guards, candidates and each
    target's peak contrast (dB, coloured and written), in mm.

    Parameters
    ----------
    result : PlacementResult

    Returns
    -------
    matplotlib.figure.Figure
    """
    from matplotlib.figure import Figure

    s = result.settings
    panels = [(result.layout, result.score, "designed")]
    if result.paper is not None:
        panels.append((paper_layout(s.targets_xy), result.paper, "paper's 2x2 at 45 mm"))
    fig = Figure(figsize=(5.2 * len(panels), 5.0), layout="constrained")
    axes = fig.subplots(1, len(panels), squeeze=False)[0]
    scores = np.concatenate([sc.contrast_db[np.isfinite(sc.contrast_db)] for _, sc, _ in panels] or [[0.0]])
    lo, hi = (float(scores.min()), float(scores.max())) if scores.size else (0.0, 1.0)
    for ax, (layout, sc, title) in zip(axes, panels):
        r = s.region
        ax.add_patch(_rectangle(r))
        ax.plot(*(result.candidates_xy.T * 1e3), ".", color="0.75", ms=3, label="candidates")
        ax.plot(*(layout.actuators_xy.T * 1e3), "s", color="k", ms=12, mfc="none", label="actuators")
        if layout.n_guards:
            ax.plot(*(layout.guards_xy.T * 1e3), "x", color="0.4", ms=6, label="guards")
        sc_plot = ax.scatter(*(s.targets_xy.T * 1e3), c=sc.contrast_db, cmap="viridis", vmin=lo, vmax=hi + 1e-9,
                             s=60, zorder=3)
        for (x, y), c in zip(s.targets_xy * 1e3, sc.contrast_db):
            ax.annotate(f"{c:+.1f}", (x, y), textcoords="offset points", xytext=(0, 6), ha="center", fontsize=7)
        ax.set_title(f"{title}: worst {sc.worst_db:+.1f} dB, mean {sc.mean_db:+.1f} dB", fontsize=9)
        ax.set_xlabel("x across the arm (mm)")
        ax.set_ylabel("y toward the wrist (mm)")
        ax.set_aspect("equal")
    fig.colorbar(sc_plot, ax=list(axes), label="peak contrast against the other targets (dB)", shrink=0.8)
    axes[0].legend(loc="lower left", fontsize=7)
    fig.suptitle(f"{s.n_actuators} actuators, {s.method}, {s.limit_v:g} V limit", fontsize=10)
    return fig


def _rectangle(region: Region) -> Any:
    from matplotlib.patches import Rectangle

    (x0, x1), (y0, y1) = region.x_m, region.y_m
    return Rectangle((x0 * 1e3, y0 * 1e3), (x1 - x0) * 1e3, (y1 - y0) * 1e3, fill=False, ls="--", color="0.5")
