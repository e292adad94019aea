"""Designing the study that tells the hypotheses apart: the workflow under ``design-experiment``."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .progress import Progress, QuietProgress

__all__ = ["DesignOutcome", "design_study"]


@dataclass
class DesignOutcome:
    """What :func:`design_study` made.

    Attributes
    ----------
    design : Design
        The chosen blocks (:func:`~vibrofocus.simulation.design.design_experiment`).
    identification : dict or None
        The check: P(true hypothesis chosen) against N per protocol; None without one.
    report : dict
        The design's report (:func:`~vibrofocus.simulation.design.design_report`).
    paths : list of Path
        The files written (protocol.toml and the report), empty without ``out``.
    """

    design: Any
    identification: dict[str, Any] | None
    report: dict[str, Any]
    paths: list[Path]


def design_study(settings: Any, *, participants: list[int], studies: int, bank: Path | None = None,
                 calibration: Path | None = None, pool: int = 8, score_forearms: int = 8, score_draws: int = 32,
                 scheduler: str | None = None, workers: int | None = None, local: bool = False,
                 out: Path | None = None, threshold_trials: int = 0, rival_fits: Path | None = None,
                 rival_fits_per_pair: int = 2, progress: Progress | None = None) -> DesignOutcome:
    """Design the Study 1 blocks of ``settings``, check them by simulation, and write them.

    Parameters
    ----------
    settings : DesignSettings
        The candidates, budget and hypotheses (:class:`~vibrofocus.simulation.design.DesignSettings`).
    participants : list of int
        The N the check estimates P(true hypothesis chosen) at.
    studies : int
        Simulated studies per N in the check (0: no check).
    bank, calibration : Path, optional
        A feature bank file, or a calibration whose fitted skin gives the felt fields (not
        both); default the shipped simulated bank.
    pool, score_forearms, score_draws : int
        The check's participant pool, bank forearms and trait draws.
    scheduler, workers, local
        The check's Dask options, as ``power``'s.
    out : Path, optional
        Folder for protocol.toml and the report (checked before the design runs).
    threshold_trials : int
        Trials of a threshold block put first in protocol.toml (0: none;
        :func:`~vibrofocus.simulation.design.design_protocol_text`).
    rival_fits : Path, optional
        A free-fit model recovery's results file: ``rival_fits_per_pair`` fits of each
        hypothesis per other true hypothesis join its draws
        (:func:`~vibrofocus.simulation.design.read_rival_fits`; replaces
        ``settings.rival_fits``).
    rival_fits_per_pair : int
    progress : Progress, optional
        Notes of the design's and the check's times.

    Returns
    -------
    DesignOutcome
    """
    import dataclasses

    from .._atomic import protect
    from ..errors import ValidationError
    from ..simulation.bank import FeatureBank, default_bank
    from ..simulation.design import (design_experiment, design_report, identification, paper_plan, read_rival_fits,
                                     write_design)

    progress = progress if progress is not None else QuietProgress()
    if calibration is not None and bank is not None:
        raise ValidationError("give --calibration or --bank, not both")
    if rival_fits is not None:
        protect(rival_fits, "rival fits file")  # an input: no output of this command may replace it
        settings = dataclasses.replace(settings, rival_fits=read_rival_fits(rival_fits, settings.hypotheses,
                                                                            rival_fits_per_pair))
    if calibration is not None:
        from ..calibration import load_calibration
        from ..simulation.bank import bank_from_calibration

        protect(calibration, "calibration")
        fb = bank_from_calibration(load_calibration(calibration))
        settings = dataclasses.replace(settings, n_forearms=1)
        score_forearms = 1
    else:
        fb = FeatureBank.load(bank) if bank is not None else default_bank()
    if out is not None:
        from .._atomic import check_writable, make_output_folder

        make_output_folder(out)
        check_writable(out / "protocol.toml", what="protocol")
    design = design_experiment(settings, bank=fb)
    progress.note(f"designed in {design.elapsed_s:.1f} s: {design.trials} trials, "
                  f"{design.information_nats:.3f} nats per participant")
    ident = None
    if studies:
        ident = identification({"designed": design.blocks, "paper": paper_plan()}, list(settings.hypotheses or ()),
                               n_participants=participants, n_studies=studies, pool=pool, seed=settings.seed + 1,
                               n_forearms=score_forearms, n_draws=score_draws, bank=fb, scheduler=scheduler,
                               n_workers=workers, local=local, population=settings.population)
        progress.note(f"checked in {ident['elapsed_s']:.1f} s")
    paths = write_design(design, out, ident=ident, bank=fb, threshold_trials=threshold_trials) if out is not None else []
    return DesignOutcome(design, ident, design_report(design, ident), paths)
