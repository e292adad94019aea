"""A calibration's completed points, kept on disk as they are measured.

A calibration on a single-spot rig takes minutes: the operator aims the vibrometer at
each point in turn. :class:`CalibrationCheckpoint` writes the takes of every completed
point group to a partial file (atomically, after each group), so an interruption (Ctrl-C,
a crash, a power cut) loses at most the point being measured. ``calibrate(...,
checkpoint=...)`` with the same plan on the same rig continues from there
(``vibrofocus calibrate --resume``); another plan or rig is refused, never mixed in.
"""

from __future__ import annotations

import hashlib
import io
import json
from pathlib import Path

import numpy as np

from .._atomic import write_bytes
from ..errors import CalibrationFileError

__all__ = ["CalibrationCheckpoint", "partial_path"]

FORMAT = "vibrofocus-calibration-partial-1"


def partial_path(out: str | Path) -> Path:
    """Where the partial file of a calibration written to ``out`` lives: ``<out>.partial.npz``."""
    out = Path(out)
    return out.with_name(out.name + ".partial.npz")


class CalibrationCheckpoint:
    """The completed point groups of one calibration plan, on disk.

    Parameters
    ----------
    path : path-like
        The partial file (see :func:`partial_path`).
    plan : dict
        What must match to continue: participant, method, points, actuators, sweep
        settings and the rig's description (JSON-serialisable).
    resume : bool
        Continue from an existing partial file (which must hold the same plan); without
        it an existing partial file is refused, so nothing measured is overwritten.
    """

    def __init__(self, path: str | Path, plan: dict, *, resume: bool = False):
        self.path = Path(path)
        self.fingerprint = hashlib.sha256(json.dumps(plan, sort_keys=True, default=str).encode()).hexdigest()
        self.groups: dict[int, dict[str, np.ndarray]] = {}
        if self.path.exists():
            if not resume:
                raise CalibrationFileError(
                    f"{self.path} holds the completed points of an interrupted calibration; continue it with "
                    f"--resume, or delete the file to start again"
                )
            self._load()

    def _load(self) -> None:
        try:
            with np.load(self.path, allow_pickle=False) as z:
                if str(z["format"]) != FORMAT:
                    raise CalibrationFileError(f"{self.path} is not a vibrofocus partial calibration")
                if str(z["fingerprint"]) != self.fingerprint:
                    raise CalibrationFileError(
                        f"{self.path} was measured with another plan or rig (participant, method, points, sweeps "
                        "or rig settings differ); run the same command as before, or delete it to start again"
                    )
                for gi in z["done"].tolist():
                    self.groups[int(gi)] = {k.split("/", 1)[1]: z[k] for k in z.files if k.startswith(f"{gi}/")}
        except (OSError, ValueError, KeyError) as exc:
            raise CalibrationFileError(f"{self.path} cannot be read as a partial calibration ({exc})") from None

    @property
    def n_done(self) -> int:
        return len(self.groups)

    def restore(self, index: int) -> dict[str, np.ndarray] | None:
        """The saved arrays of point group ``index``, or None if it was not completed."""
        return self.groups.get(index)

    def save(self, index: int, **arrays: np.ndarray) -> None:
        """Record point group ``index`` as completed, with its arrays, and write the file."""
        self.groups[index] = {k: np.asarray(v) for k, v in arrays.items()}
        payload = {f"{gi}/{k}": v for gi, arrays_ in self.groups.items() for k, v in arrays_.items()}
        buf = io.BytesIO()
        np.savez(buf, format=np.array(FORMAT), fingerprint=np.array(self.fingerprint),
                 done=np.array(sorted(self.groups), dtype=int), **payload)
        write_bytes(self.path, buf.getvalue(), what="partial calibration")

    def discard(self) -> None:
        """Delete the partial file (once the whole calibration is saved)."""
        self.path.unlink(missing_ok=True)
