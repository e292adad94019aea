"""The web app's rigs, calibrations and renderers, each made once and shared.

One part of :class:`~vibrofocus.web.state.WebState`, split along its jobs.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from fastapi import HTTPException

from ..errors import StudyError, VibrofocusError
from .public_text import public_text

__all__ = ["RigState"]


class RigState:
    """The rigs in use, the calibrations loaded and their renderers: a part of
    :class:`~vibrofocus.web.state.WebState` (its ``rigs``, ``calibrations``, ``banks``)."""

    @property
    def rig_kinds(self) -> list[str]:
        """Rig kinds this server can use: its own, and the simulated forearm for rehearsals."""
        return [self.rig_kind] + (["simulated"] if self.rig_kind != "simulated" else [])

    def check_rig_kind(self, kind: str) -> None:
        """Raise 409 unless this server can use rigs of ``kind``."""
        if kind not in self.rig_kinds:
            raise HTTPException(409, detail=(
                f"This server was started for the {self.rig_label} rig. To use the {kind} rig, restart it with "
                f"'vibrofocus serve --rig {kind} --rig-config FILE'."
            ))

    def make_rig(self, kind: str, seed: int | None):
        """A rig by kind and seed, made once and reused (a hardware rig holds a device).

        A hardware rig is the one the server was started with (``serve --rig KIND
        --rig-config FILE``), built from that config file.
        """
        self.check_rig_kind(kind)
        # One rig per physical device: a hardware rig is the same object whatever the seed.
        key = (kind, -1 if seed is None or kind != "simulated" else int(seed))
        with self.lock:
            if key not in self.rigs:
                factory = self.rig_factory
                if factory is None:
                    from ..rigs import make_rig as factory
                extra = {"config": self.rig_config} if kind != "simulated" and self.rig_config is not None else {}
                try:
                    self.rigs[key] = factory(kind, seed=seed, **extra)
                except VibrofocusError as exc:
                    raise HTTPException(400, detail=str(exc)) from None
            return self.rigs[key]

    def calibration(self, calibration_id: int):
        """A calibration by id, after checking its file's SHA-256; 404 if unknown, 409 if changed.

        Every use checks the hash, the cached copy's too: a file changed on disk is
        refused at once, not after a restart.
        """
        calibration_id = int(calibration_id)
        with self.db:
            try:
                rec = self.store.calibration(calibration_id)
            except StudyError:
                raise HTTPException(404, detail=f"unknown calibration {calibration_id}") from None
            name = Path(rec.path).name
            try:
                path = self.store.verify_calibration(calibration_id)
            except StudyError:
                with self.lock:  # a file that changed is never used again from memory
                    self.calibrations.pop(calibration_id, None)
                    for key in [k for k in self.banks if k[0] == calibration_id]:
                        del self.banks[key]
                raise HTTPException(409, detail=(
                    f"Calibration {calibration_id} ({name}) is missing or has changed since it was saved, so it is not "
                    "used. Calibrate again, or put the original file back."
                )) from None
        with self.lock:
            if calibration_id in self.calibrations:
                return self.calibrations[calibration_id]
        from ..calibration import load_calibration

        try:
            cal = load_calibration(path)
        except VibrofocusError as exc:
            raise HTTPException(409, detail=public_text(f"Calibration {calibration_id} ({name}) cannot be loaded: {exc}")) from None
        with self.lock:
            self.calibrations[calibration_id] = cal
        return cal

    def bank(self, calibration_id: int, limit_v: float | None = None, levels: str | None = None):
        """The renderer of a calibration (renders each condition once; previews and sessions share it).

        Parameters
        ----------
        calibration_id : int
            A registered calibration.
        limit_v : float, optional
            Drive limit, V peak (a rig's limit); default the rendering layer's.
        levels : {"paper", "equal-peak"}, optional
            The level rule (a session's); default the paper's
            (:data:`~vibrofocus.studies.protocol.DEFAULT_LEVELS`).

        Returns
        -------
        CalibrationRenderer
        """
        from ..defaults import DRIVE_LIMIT_V
        from ..studies.engine import CalibrationRenderer
        from ..studies.protocol import DEFAULT_LEVELS

        limit = DRIVE_LIMIT_V if limit_v is None else float(limit_v)
        levels = DEFAULT_LEVELS if levels is None else str(levels)
        key = (int(calibration_id), limit, levels)
        cal = self.calibration(calibration_id)  # the hash, checked at every use
        with self.lock:
            bank = self.banks.get(key)
        if bank is None:
            bank = CalibrationRenderer(cal, limit_v=limit, levels=levels)
            with self.lock:
                bank = self.banks.setdefault(key, bank)
        return bank

    def rig_name(self, kind: str, rig: Any) -> str:
        """A rig as the emergency stop names it: its kind, and its seed or config file."""
        if kind == "simulated":
            seed = getattr(rig, "seed", None)
            return "simulated rig" + (f" (seed {seed})" if seed is not None else "")
        if isinstance(self.rig_config, (str, os.PathLike)):
            return f"{kind} rig ({Path(self.rig_config).name})"
        return f"{kind} rig"
