"""The takes of a calibration on a rig: one actuator at a time, or all at once (``mimo``).

Retries of takes lost to dropouts, the progress of the takes, and the strap reading taken
before them.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from ..errors import CoolingError, VibrofocusError
from ..layout import ArrayLayout
from ..rigs.base import Rig
from ..rigs.safety import MAX_COOLING_WAITS

#: Extra recordings tried for a point whose every repeat had a dropout.
MAX_RETRIES = 3

ProgressFn = Callable[[int, int, str], None]


class _Takes:
    """Records takes on a rig and keeps what a take tells besides the displacement.

    Also the progress of the takes (``done`` of ``total``) and the optional checkpoint of
    completed point groups.
    """

    def __init__(self, rig: Rig, points_xy: np.ndarray, aimed: bool, n_rec: int, tail_s: float,
                 shape: tuple[int, int], progress: ProgressFn | None = None, total: int = 0) -> None:
        self.rig, self.points_xy, self.aimed = rig, points_xy, aimed
        self.n_rec, self.tail_s = n_rec, tail_s
        self.adc_clipped = np.zeros(shape, dtype=bool)  # (P, A): the rig's converter clipped
        self.n_takes = 0
        self.progress, self.total, self.done = progress, total, 0
        self.checkpoint = None
        self.pause_s = 0.0  # silence after each sweep before the next (the plan's pause_s), s

    def tell(self, message: str, *, took: int = 0) -> None:
        self.done += took
        if self.progress is not None:
            self.progress(self.done, self.total, message)

    def restored(self, index: int, group: np.ndarray, labels) -> dict | None:
        """The saved takes of point group ``index`` from the checkpoint, if it was completed."""
        saved = None if self.checkpoint is None else self.checkpoint.restore(index)
        if saved is not None:
            self.adc_clipped[group] = saved["adc_clipped"]
            self.n_takes += int(saved["n_takes"])
            self.tell(f"point {', '.join(labels[p] for p in group)}: kept from the partial file",
                      took=int(saved["n_planned"]))
        return saved

    def completed(self, index: int, group: np.ndarray, n_planned: int, n_takes_before: int, **arrays) -> None:
        if self.checkpoint is not None:
            self.checkpoint.save(index, adc_clipped=self.adc_clipped[group], n_takes=self.n_takes - n_takes_before,
                                 n_planned=n_planned, **arrays)

    def record(self, drive: np.ndarray, group: np.ndarray, actuator: int | None) -> np.ndarray:
        """One take at the points ``group``; ``actuator`` None when all of them played.

        Returns
        -------
        ndarray, shape (len(group), n_rec)
            Displacement, m; NaN where the rig flagged a dropout.
        """
        rig = self.rig
        if self.pause_s:
            self._pause()
        where = self.points_xy[group] if self.aimed else self.points_xy
        for attempt in range(MAX_COOLING_WAITS + 1):
            try:
                y = rig.play_and_record(drive, where, tail_s=self.tail_s)
                break
            except CoolingError as exc:  # a take again after lost samples, past the plan's pauses
                if attempt == MAX_COOLING_WAITS:
                    raise
                self._wait(exc.wait_s)
        self.n_takes += 1
        if y.shape != (len(group), self.n_rec):
            raise VibrofocusError(
                f"the {rig.kind} rig returned a recording of shape {y.shape}, expected {(len(group), self.n_rec)}"
            )
        # A rig may flag dropout samples instead of (or besides) writing NaN into them.
        flagged = getattr(rig, "last_dropout_mask", None)
        if isinstance(flagged, np.ndarray) and flagged.shape == y.shape and flagged.any():
            y = np.where(flagged, np.nan, y)
        # Clipping at the sensor's converter may be invisible after the rig converts to
        # displacement (a velocity decoder is integrated): a rig can report it.
        rig_clipped = getattr(rig, "last_clipped", None)
        if rig_clipped is not None:
            hit = np.broadcast_to(np.asarray(rig_clipped, bool), (len(group),))
            if actuator is None:
                self.adc_clipped[group] |= hit[:, None]
            else:
                self.adc_clipped[group, actuator] |= hit
        return y


    def _pause(self) -> None:
        """Wait until the last sweep has been silent for ``pause_s`` on the rig's budget clock.

        Progress is told every 0.1 s, so a cancel (the web's emergency stop) ends the pause.
        """
        end = self.rig.budget.end_s
        if end is not None:
            self._wait(end + self.pause_s - self.rig._clock())

    def _wait(self, seconds: float) -> None:
        """Wait ``seconds`` for the actuators to cool, telling progress every 0.1 s (a cancel ends it)."""
        until = self.rig._clock() + seconds
        while (left := until - self.rig._clock()) > 0:
            self.tell(f"pausing {left:.1f} s for the actuators to cool")
            time.sleep(min(0.1, left))


def _where(labels, group: np.ndarray, aimed: bool) -> str:
    return "point " + ", ".join(labels[p] for p in group) if aimed else "all points"


def _record_one_at_a_time(session, excitation, a_idx, n_r, groups, labels, layout, prompt):
    """The takes of ``h1``/``paper``: one actuator at a time.

    Returns recordings (n_actuators, n_repeats, n_points, n_rec) float32 and the dropouts
    per (point, actuator)."""
    rig = session.rig
    n_a, n_p = len(a_idx), len(session.points_xy)
    recordings = np.full((n_a, n_r, n_p, session.n_rec), np.nan, dtype=np.float32)
    dropouts = np.zeros((n_p, n_a), dtype=int)
    for gi, group in enumerate(groups):
        saved = session.restored(gi, group, labels)
        if saved is not None:
            recordings[:, :, group], dropouts[group] = saved["recordings"], saved["dropouts"]
            continue
        takes_before = session.n_takes
        if session.aimed:
            for p in group:
                prompt(labels[p], session.points_xy[p].copy())
        for a, channel in enumerate(a_idx):
            drive = np.zeros((rig.layout.n_actuators, excitation.size))
            drive[channel] = excitation
            for r in range(n_r):
                what = f"{layout.actuator_names[a]}, {_where(labels, group, session.aimed)}, take {r + 1}/{n_r}"
                session.tell(what + ": playing")
                recordings[a, r, group] = session.record(drive, group, a)
                session.tell(what, took=1)
            bad = ~np.isfinite(recordings[a][:, group]).all(axis=-1)  # (R, len(group))
            dropouts[group, a] = bad.sum(axis=0)
            # A point that dropped out in every take is re-recorded into its first slot.
            for _ in range(MAX_RETRIES):
                lost = group[bad.all(axis=0)]
                if lost.size == 0:
                    break
                y = session.record(drive, group, a)
                ok_now = np.isfinite(y).all(axis=-1)
                fill = bad.all(axis=0) & ok_now
                recordings[a, 0, group[fill]] = y[fill]
                bad[0, fill] = False
            lost = group[bad.all(axis=0)]
            if lost.size:
                raise VibrofocusError(
                    f"the vibrometer dropped out in every recording of point(s) "
                    f"{', '.join(labels[p] for p in lost)} with actuator {layout.actuator_names[a]} "
                    f"({n_r + MAX_RETRIES} tries); check its aim and signal level"
                )
        session.completed(gi, group, n_a * n_r, takes_before, recordings=recordings[:, :, group],
                          dropouts=dropouts[group])
    return recordings, dropouts


def _separable(codes: np.ndarray, kept: np.ndarray, condition_max: float) -> np.ndarray:
    """Whether the takes kept at each point still tell the actuators apart.

    Parameters
    ----------
    codes : ndarray, shape (n_takes, n_actuators)
    kept : ndarray of bool, shape (n_takes, n_points)
    condition_max : float

    Returns
    -------
    ndarray of bool, shape (n_points,)
        The condition number of ``codes[kept].T @ codes[kept]`` is at most ``condition_max``.
    """
    c = codes.astype(float)
    gram = np.einsum("rp,ra,rb->pab", kept.astype(float), c, c)
    eig = np.linalg.eigvalsh(gram)
    return eig[:, 0] * condition_max >= eig[:, -1] * (1 - 1e-12)


def _record_mimo(session, excitation, a_idx, codes, groups, labels, layout, thresholds, prompt):
    """The takes of ``mimo``: every actuator at once, with the signs ``codes[r]`` in take ``r``.

    Returns recordings (n_takes, n_points, n_rec) float32 and the dropouts per (point,
    actuator) (the same for every actuator of a point)."""
    rig = session.rig
    n_r, n_a = codes.shape
    n_p = len(session.points_xy)
    recordings = np.full((n_r, n_p, session.n_rec), np.nan, dtype=np.float32)
    dropouts = np.zeros((n_p, n_a), dtype=int)

    def take(r: int) -> np.ndarray:
        drive = np.zeros((rig.layout.n_actuators, excitation.size))
        drive[a_idx] = codes[r].astype(float)[:, None] * excitation[None, :]
        return drive

    for gi, group in enumerate(groups):
        saved = session.restored(gi, group, labels)
        if saved is not None:
            recordings[:, group], dropouts[group] = saved["recordings"], saved["dropouts"]
            continue
        takes_before = session.n_takes
        if session.aimed:
            for p in group:
                prompt(labels[p], session.points_xy[p].copy())
        for r in range(n_r):
            what = f"all {n_a} actuators, {_where(labels, group, session.aimed)}, take {r + 1}/{n_r}"
            session.tell(what + ": playing")
            recordings[r, group] = session.record(take(r), group, None)
            session.tell(what, took=1)
        bad = ~np.isfinite(recordings[:, group]).all(axis=-1)  # (R, len(group))
        dropouts[group] = bad.sum(axis=0)[:, None]
        # Too many takes lost at a point to separate the actuators: record the first of
        # its lost takes again (same signs) into that slot.
        for _ in range(MAX_RETRIES):
            lost = np.flatnonzero(~_separable(codes, ~bad, thresholds.condition_max))
            if lost.size == 0:
                break
            r = int(np.flatnonzero(bad[:, lost[0]])[0])
            y = session.record(take(r), group, None)
            fill = bad[r] & np.isfinite(y).all(axis=-1)
            recordings[r, group[fill]] = y[fill]
            bad[r, fill] = False
        lost = group[~_separable(codes, ~bad, thresholds.condition_max)]
        if lost.size:
            raise VibrofocusError(
                f"the vibrometer dropped out in so many takes of point(s) {', '.join(labels[p] for p in lost)} "
                f"that the {n_a} actuators cannot be told apart ({n_r + MAX_RETRIES} tries); check its aim and "
                "signal level"
            )
        session.completed(gi, group, n_r, takes_before, recordings=recordings[:, group], dropouts=dropouts[group])
    return recordings, dropouts


def _read_straps(rig: Rig) -> dict | None:
    """The strap force reading of rigs that have strap sensors (stored with the calibration)."""
    from ..rigs.force import check_straps, has_strap_sensors

    if not has_strap_sensors(rig):
        return None

    return check_straps(rig).to_dict()
