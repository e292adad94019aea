"""Stimulus features of simulated participants, computed once, and fast simulated studies.

Simulating a study trial by trial through the engine renders every stimulus and plays it
on the simulated forearm. For fitting the perceptual model and for power analysis that is
far too slow, and needless: the peripheral stage of the model
(:func:`~vibrofocus.simulation.perception.felt_energy`) depends only on the participant's
forearm and the stimulus (method, location). A :class:`FeatureBank` holds it for a set of
simulated forearms (each calibrated and rendered for exactly as in ``simulate-study``);
:func:`simulate_cell_means` then draws whole studies from it with numpy only: new
perceptual traits per simulated participant, a forearm drawn from the bank, every trial's
answer from :func:`~vibrofocus.simulation.perception.draw_answers`.

The answers are those of the same model as :class:`SimulatedParticipant` (a model, not
data); they use other random streams than the engine path, so they agree in
distribution, not trial by trial.
"""

from __future__ import annotations

import dataclasses
import os
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any, Callable

import numpy as np

from ..errors import StudyError, ValidationError
from ..io.feature_bank import load_feature_bank, save_feature_bank
from .perception import MODEL_VERSION, STUDY_SKIN, PerceptualModel, Traits, draw_answers

__all__ = ["FeatureBank", "build_feature_bank", "bank_from_calibration", "default_bank", "StudyArrays", "simulate_cell_means",
           "check_level_db", "MAX_LEVEL_DB"]

#: The bank shipped with the package (built by ``scripts/build_feature_bank.py``).
DEFAULT_BANK = "data/feature_bank.npz"
#: Largest magnitude of a level re the level rule, dB (a protocol file's bound).
MAX_LEVEL_DB = 120.0


def check_level_db(level_db: float, name: str = "level_db") -> float:
    """A level in dB re the level rule, as a float, or ValidationError naming ``name``.

    Parameters
    ----------
    level_db : float
        Within +-:data:`MAX_LEVEL_DB` dB.
    name : str
        What to call it in the error.

    Returns
    -------
    float
    """
    from .._validation import check_in_range

    if isinstance(level_db, bool):
        raise ValidationError(f"{name} must be a number of dB, got {level_db!r}")
    return check_in_range(level_db, name, -MAX_LEVEL_DB, MAX_LEVEL_DB)


@dataclass(frozen=True)
class FeatureBank:
    """Felt energies of every study stimulus on a set of simulated forearms.

    Attributes
    ----------
    energy : ndarray, shape (n_forearms, n_methods, n_locations, n_points)
        Felt energy re the reference tap (:func:`~vibrofocus.simulation.perception.felt_energy`).
    points_xy : ndarray, shape (n_points, 2)
        Skin grid, m.
    locations_xy : ndarray, shape (n_locations, 2)
        m.
    centre_xy : ndarray, shape (2,)
        Array centre, m.
    methods : tuple of str
    forearm_seeds : ndarray of int, shape (n_forearms,)
        Participant seeds of the forearms (``participant_seeds(seed, k)[0]``).
    seed : int
        Simulation seed they were derived from.
    actuator_energy : ndarray, shape (n_forearms, n_methods, n_locations, n_actuators)
        Felt energy (re the reference tap) that each actuator's own drive makes at its own
        contact, through its coupling to the skin: what the central (funneling) stage
        integrates (:func:`~vibrofocus.simulation.perception.actuator_energy`).
    actuators_xy : ndarray, shape (n_actuators, 2)
        Actuator centres, m.
    levels : str
        The level rule the stimuli were rendered with
        (:func:`~vibrofocus.studies.protocol.level_options`); ``"equal-peak"`` for a bank
        written before banks stored it.
    drive_peak_v : ndarray, shape (n_forearms, n_methods, n_locations), optional
        Each stimulus's largest drive magnitude (absolute value over actuators and samples), V (None in an older bank).
    target_peak_m : ndarray, shape (n_forearms, n_methods, n_locations), optional
        Each stimulus's peak at the target predicted from the calibration, m.
    """

    energy: np.ndarray
    points_xy: np.ndarray
    locations_xy: np.ndarray
    centre_xy: np.ndarray
    methods: tuple[str, ...]
    forearm_seeds: np.ndarray
    seed: int
    actuator_energy: np.ndarray
    actuators_xy: np.ndarray
    levels: str = "equal-peak"
    drive_peak_v: np.ndarray | None = None
    target_peak_m: np.ndarray | None = None

    @property
    def n_forearms(self) -> int:
        return int(self.energy.shape[0])

    def at_level(self, level_db: float, *, limit_v: float | None = None) -> "FeatureBank":
        """The same stimuli played ``level_db`` dB re the bank's level rule.

        A level multiplies every drive by ``10**(level_db / 20)`` (as a protocol block's
        level does, docs/protocols.md); felt energies are quadratic in the drives, so they
        are multiplied by ``10**(level_db / 10)`` exactly (also with a finite
        ``integration_s``), and the drive and target peaks by ``10**(level_db / 20)``.

        Parameters
        ----------
        level_db : float
            dB re the bank's level rule (0: the bank itself), within +-120 dB.
        limit_v : float, optional
            Refuse a level at which some stimulus needs a drive above this, V (default
            :data:`vibrofocus.defaults.DRIVE_LIMIT_V`); needs ``drive_peak_v``.

        Returns
        -------
        FeatureBank

        Raises
        ------
        ValidationError
            A level out of range, or one that needs more than ``limit_v``.
        """
        from ..defaults import DRIVE_LIMIT_V

        level = check_level_db(level_db)
        if level == 0.0:
            return self
        amp = 10.0 ** (level / 20.0)
        limit = DRIVE_LIMIT_V if limit_v is None else float(limit_v)
        if self.drive_peak_v is not None and level > 0:
            need = float(np.max(self.drive_peak_v)) * amp
            if need > limit * (1.0 + 1e-9):
                f, m, loc = np.unravel_index(int(np.argmax(self.drive_peak_v)), self.drive_peak_v.shape)
                raise ValidationError(f"{level:+g} dB re the {self.levels} levels needs {need:.3g} V for "
                                      f"{self.methods[m]} at location {loc + 1} (forearm {f}), over the "
                                      f"{limit:g} V drive limit; lower the level")
        scale = lambda a: None if a is None else a * amp  # noqa: E731
        return dataclasses.replace(
            self, energy=self.energy * amp**2, actuator_energy=self.actuator_energy * amp**2,
            drive_peak_v=scale(self.drive_peak_v), target_peak_m=scale(self.target_peak_m))

    def save(self, path: str | os.PathLike) -> None:
        """Write the bank (``.npz``, atomically; :func:`vibrofocus.io.feature_bank.save_feature_bank`).

        Parameters
        ----------
        path : path-like
            Destination ``.npz``; its folder must exist.
        """
        save_feature_bank(dataclasses.asdict(self), path, model_version=MODEL_VERSION)

    @classmethod
    def load(cls, path: str | os.PathLike) -> "FeatureBank":
        """Read a bank written by :meth:`save` (:func:`vibrofocus.io.feature_bank.load_feature_bank`).

        Parameters
        ----------
        path : path-like
            A feature-bank ``.npz``.

        Raises
        ------
        ValidationError
            What :func:`~vibrofocus.io.feature_bank.load_feature_bank` refuses, and
            method names that no registered method has (:func:`vibrofocus.available_methods`).
        """
        from ..rendering.registry import available_methods

        arrays = load_feature_bank(path)
        known = available_methods()
        unknown = [m for m in arrays["methods"] if m not in known]
        if unknown:
            raise ValidationError(f"feature bank {path}: method(s) {', '.join(map(repr, unknown))} are not "
                                  f"registered (registered: {', '.join(known)})")
        return cls(**arrays)


def build_feature_bank(
    n_forearms: int,
    *,
    seed: int = 0,
    methods: tuple[str, ...] = ("funneling", "inverse", "combination"),
    model: PerceptualModel | None = None,
    progress: Any = None,
    levels: str = "paper",
    calibrations: Any = None,
) -> FeatureBank:
    """Calibrate ``n_forearms`` simulated forearms, render every stimulus, compute felt energies.

    Forearm ``k`` (1-based) is simulated participant ``sim-00k`` of ``simulate-study
    --seed seed``: same participant seed, same calibration, same drives.

    Parameters
    ----------
    n_forearms : int
    seed : int
    methods : tuple of str
    model : PerceptualModel, optional
        Only its grid, band and integration window (``integration_s``) matter here.
    progress : callable, optional
        ``progress(done, total)`` after each forearm.
    levels : {"paper", "equal-peak"}
        The level rule of the stimuli (a study protocol's; default the paper's), stored
        in the bank.
    calibrations : sequence of Calibration, optional
        The forearms' calibrations made already (those ``simulate-study --seed seed``
        stored for ``sim-001``, ...), used instead of calibrating again; one per forearm.
    """
    from ..calibration import calibrate
    from ..rigs import make_rig
    from .perception import skin_grid
    from .simulate import participant_seeds

    if isinstance(n_forearms, bool) or not isinstance(n_forearms, (int, np.integer)) or n_forearms < 1:
        raise StudyError(f"n_forearms must be an integer >= 1, got {n_forearms!r}")
    m = model or PerceptualModel()
    if calibrations is not None and len(calibrations) != n_forearms:
        raise StudyError(f"calibrations: one per forearm, got {len(calibrations)} for {n_forearms}")
    energies, own, seeds, peaks, reached = [], [], [], [], []
    layout = points = None
    for k in range(1, n_forearms + 1):
        pseed = participant_seeds(seed, k)[0]
        rig = make_rig("simulated", seed=pseed, skin=STUDY_SKIN)
        layout = rig.layout
        cal = calibrate(rig, participant_id=f"bank-{k:03d}") if calibrations is None else calibrations[k - 1]
        feats = _forearm_features(cal, rig, methods, m, levels, rig=rig)
        for out, x in zip((energies, own, peaks, reached), feats):
            out.append(x)
        points = skin_grid(np.asarray(layout.actuators_xy, dtype=float).mean(axis=0), m)
        seeds.append(pseed)
        if progress is not None:
            progress(k, n_forearms)
    assert layout is not None and points is not None
    return _bank(layout, points, methods, energies, own, peaks, reached, seeds, seed, levels)


def _bank(layout: Any, points: np.ndarray, methods: tuple[str, ...], energies: list, own: list, peaks: list,
          reached: list, seeds: list, seed: int, levels: str) -> FeatureBank:
    return FeatureBank(
        energy=np.stack(energies), points_xy=points, locations_xy=np.asarray(layout.locations_xy, dtype=float),
        centre_xy=np.asarray(layout.actuators_xy, dtype=float).mean(axis=0), methods=tuple(methods),
        forearm_seeds=np.asarray(seeds, dtype=np.int64), seed=int(seed),
        actuator_energy=np.stack(own), actuators_xy=np.asarray(layout.actuators_xy, dtype=float),
        levels=str(levels), drive_peak_v=np.stack(peaks), target_peak_m=np.stack(reached),
    )


def _forearm_features(cal: Any, skin: Any, methods: tuple[str, ...], m: PerceptualModel, levels: str,
                      rig: Any = None) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Felt energies, actuator energies, drive peaks and target peaks of every stimulus of one forearm.

    ``cal`` renders the stimuli as a study does; ``skin`` (a simulated forearm, or a skin
    model fitted to a measured calibration) gives the true transfer to the skin grid.
    """
    from ..studies.engine import calibration_renderer
    from .perception import actuator_energy, band_transfer, felt_energy, skin_grid

    layout = cal.layout
    # Same drives as simulate-study: the study renderer's window, its tapered ends where a
    # design needs them, the same level rule (the contrast bounds, not part of the
    # drives, are not computed).
    render = calibration_renderer(cal, bounds=False, levels=levels)
    n_loc = len(layout.locations_xy)
    # One window every stimulus fits, each within the rig's limits, as a study's.
    render.prepare(methods, range(1, n_loc + 1), rig=rig)
    drives = np.stack([render(meth, loc) for meth in methods for loc in range(1, n_loc + 1)])
    peaks = np.max(np.abs(drives), axis=(1, 2)).reshape(len(methods), n_loc)
    reached = np.array([render.rendering(meth, loc).reached_peak_m for meth in methods
                        for loc in range(1, n_loc + 1)]).reshape(len(methods), n_loc)
    actuators = np.asarray(layout.actuators_xy, dtype=float)
    points = skin_grid(actuators.mean(axis=0), m)
    H = band_transfer(skin, points, drives.shape[-1], m)  # the window the stimuli fit
    energy = felt_energy(H, drives, skin.fs, m).reshape(len(methods), n_loc, len(points))
    own = actuator_energy(skin, actuators, drives, m).reshape(len(methods), n_loc, len(actuators))
    return energy, own, peaks, reached


def bank_from_calibration(
    calibration: Any,
    *,
    methods: tuple[str, ...] = ("funneling", "inverse", "combination"),
    model: PerceptualModel | None = None,
    levels: str = "paper",
    law: str = "layered",
) -> FeatureBank:
    """A one-forearm feature bank from a measured calibration: its stimuli's felt fields.

    The stimuli are rendered from the calibration as a study renders them; the skin
    displacement they make between the measured points comes from the skin model fitted
    to the calibration (its ``fit``, else :func:`~vibrofocus.calibration.fit_model` with
    ``law``), since a calibration measures the locations and guards only. A MODEL of the
    participant's skin, not a measurement of the felt field.

    Parameters
    ----------
    calibration : Calibration
        A participant's calibration (:func:`~vibrofocus.calibration.load_calibration`).
    methods : tuple of str
    model : PerceptualModel, optional
        Only its grid, band and integration window matter here.
    levels : {"paper", "equal-peak"}
        The level rule of the stimuli.
    law : {"layered", "homogeneous"}
        Wave law of the fitted skin model, where the calibration carries none.

    Returns
    -------
    FeatureBank
        One forearm (row 0; its seed -1: not a simulated participant's).
    """
    from ..calibration import fit_model
    from .perception import skin_grid

    m = model or PerceptualModel()
    skin = calibration.fit if calibration.fit is not None else fit_model(calibration, law=law)
    feats = _forearm_features(calibration, skin, methods, m, levels)
    points = skin_grid(np.asarray(calibration.layout.actuators_xy, dtype=float).mean(axis=0), m)
    return _bank(calibration.layout, points, methods, *([x] for x in feats), [-1], 0, levels)


_DEFAULT: FeatureBank | None = None


def default_bank() -> FeatureBank:
    """The feature bank shipped with vibrofocus (reference layout, seed 0)."""
    global _DEFAULT
    if _DEFAULT is None:
        ref = resources.files("vibrofocus.simulation").joinpath(DEFAULT_BANK)
        with resources.as_file(ref) as path:
            if not Path(path).is_file():
                raise StudyError(
                    "the feature bank is missing; build it with scripts/build_feature_bank.py"
                )
            _DEFAULT = FeatureBank.load(path)
    return _DEFAULT


@dataclass(frozen=True)
class StudyArrays:
    """Cell means of one simulated study (what the statistics of docs/method.md (Analysis) need).

    Attributes
    ----------
    error_mm : ndarray, shape (n_participants, n_locations, n_methods)
        Study 1: mean Euclidean error per participant and condition, mm.
    count : ndarray, shape (n_participants, n_locations, n_methods)
        Study 2: mean number of selected locations.
    count_hit : ndarray, shape (n_participants, n_locations, n_methods)
        Study 2, trials whose selection contains the target only (NaN: no such trial).
    felt : ndarray, shape (n_participants,), optional
        Share of the stimuli each participant felt (anywhere on the skin); None where not
        recorded.
    """

    error_mm: np.ndarray
    count: np.ndarray
    count_hit: np.ndarray
    felt: np.ndarray | None = None


def simulate_cell_means(
    n_participants: int,
    rng: np.random.Generator,
    *,
    bank: FeatureBank | None = None,
    model: PerceptualModel | None = None,
    repetitions: int = 3,
    methods: tuple[str, ...] | None = None,
    locations: tuple[int, ...] | None = None,
    forearms: np.ndarray | None = None,
    hypothesis: Any = None,
    rule: Callable[..., tuple[np.ndarray, np.ndarray]] | None = None,
    level_db: float = 0.0,
) -> StudyArrays:
    """Simulate Study 1 and Study 2 for ``n_participants`` and return their cell means.

    Parameters
    ----------
    n_participants : int
    rng : numpy.random.Generator
        All randomness (forearm choice, traits, trials) comes from it, in a fixed order.
    bank : FeatureBank, optional
        Default :func:`default_bank`.
    model : PerceptualModel, optional
        Default: the hypothesis' fitted model (:meth:`Hypothesis.model`).
    repetitions : int
        Trials per condition and study.
    methods, locations : tuple, optional
        Subsets of the bank's methods and of location numbers (default all).
    forearms : ndarray of int, optional
        Bank rows to use per participant (default: drawn without replacement when the
        bank is large enough, else with replacement).
    hypothesis : str or Hypothesis, optional
        How the participants read the felt field
        (:func:`~vibrofocus.simulation.hypotheses.hypothesis`; default
        :data:`~vibrofocus.simulation.hypotheses.DEFAULT_HYPOTHESIS`).
    rule : callable, optional
        How answers and selections follow from the posterior, in both studies (default
        the model's, :func:`~vibrofocus.simulation.perception.posterior_ratio_rule`;
        ``scripts/selection_rules.py`` compares others).
    level_db : float
        Level of every stimulus, dB re the bank's level rule (:meth:`FeatureBank.at_level`;
        default 0, the bank's own).
    """
    from .hypotheses import hypothesis as find_hypothesis

    h = find_hypothesis(hypothesis)
    b = (bank if bank is not None else default_bank()).at_level(level_db)
    m = model or h.model()
    if isinstance(n_participants, bool) or not isinstance(n_participants, (int, np.integer)) or n_participants < 1:
        raise ValidationError(f"n_participants must be an integer >= 1, got {n_participants!r}")
    if isinstance(repetitions, bool) or not isinstance(repetitions, (int, np.integer)) or repetitions < 1:
        raise ValidationError(f"repetitions must be an integer >= 1, got {repetitions!r}")
    meth_idx = np.arange(len(b.methods)) if methods is None else np.array([b.methods.index(x) for x in methods])
    loc_idx = np.arange(len(b.locations_xy)) if locations is None else np.asarray(locations, dtype=int) - 1
    if forearms is None:
        replace = n_participants > b.n_forearms
        forearms = rng.choice(b.n_forearms, size=n_participants, replace=replace)
    n_l, n_m = loc_idx.size, meth_idx.size
    # Trials of one study: every (location, method) ``repetitions`` times; order is irrelevant
    # to the model (no sequence effects), so the plan's shuffle is not simulated.
    cell_l = np.repeat(np.tile(np.arange(n_l), n_m), repetitions)
    cell_m = np.repeat(np.repeat(np.arange(n_m), n_l), repetitions)
    stim = meth_idx[cell_m] * len(b.locations_xy) + loc_idx[cell_l]
    targets = loc_idx[cell_l]
    shape = (n_participants, n_l, n_m)
    err, cnt, cnt_hit = np.empty(shape), np.empty(shape), np.empty(shape)
    felt = np.empty(n_participants)
    locs_mm = b.locations_xy * 1e3
    n_cell = n_l * n_m
    flat = cell_l * n_m + cell_m
    for i in range(n_participants):
        traits = Traits.draw(m, rng)
        energy = b.energy[forearms[i]].reshape(-1, b.points_xy.shape[0])
        own = b.actuator_energy[forearms[i]].reshape(-1, b.actuators_xy.shape[0])
        per = h.percepts(energy, b.points_xy, m, traits, own, b.actuators_xy, b.locations_xy)
        felt[i] = per.felt[stim].mean()
        a1, _, _ = draw_answers(per, stim, b.locations_xy, b.centre_xy, m, traits, rng, allowed=loc_idx, rule=rule)
        a2, sel, _ = draw_answers(per, stim, b.locations_xy, b.centre_xy, m, traits, rng, allowed=loc_idx, rule=rule)
        e = np.linalg.norm(locs_mm[a1] - locs_mm[targets], axis=1)
        err[i] = (np.bincount(flat, e, n_cell) / np.bincount(flat, minlength=n_cell)).reshape(n_l, n_m)
        k = sel[:, loc_idx].sum(axis=1)
        cnt[i] = (np.bincount(flat, k, n_cell) / np.bincount(flat, minlength=n_cell)).reshape(n_l, n_m)
        hit = sel[np.arange(sel.shape[0]), targets]
        nh = np.bincount(flat[hit], minlength=n_cell)
        with np.errstate(invalid="ignore", divide="ignore"):
            cnt_hit[i] = (np.bincount(flat[hit], k[hit], n_cell) / nh).reshape(n_l, n_m)
    return StudyArrays(err, cnt, cnt_hit, felt)
