"""A moving focus: taps along a path, designed where nothing was measured (``demo --moving``).

Each tap is designed at its own skin position from a model of the skin fitted to the
calibration (``render(method, fitted, ..., target_xy=...)``); the taps follow each
other along the path at the given speed, and their sum is the drive. The field it
makes on the (simulated) arm is written as an animated GIF.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .._docs import fill_doc
from .._validation import as_array, check_positive
from ..defaults import DRIVE_LIMIT_V
from ..errors import ValidationError

__all__ = ["MovingFocus", "moving_focus", "write_moving_gif"]


@dataclass(frozen=True, eq=False)
class MovingFocus:
    """A sequence of taps along a path.

    Attributes
    ----------
    targets_xy : ndarray, shape (n_taps, 2)
        Tap positions, m.
    onsets_s : ndarray, shape (n_taps,)
        Time of each tap's peak in the drive, s.
    drives : ndarray, shape (n_actuators, n_samples)
        The summed drive, V, within the drive limit.
    fs : float
        Sample rate, Hz.
    scale : float
        Factor applied to the sum of the taps to keep it within the limit (<= 1).
    """

    targets_xy: np.ndarray
    onsets_s: np.ndarray
    drives: np.ndarray
    fs: float
    scale: float


@fill_doc
def moving_focus(model, layout, fs: float, *, start_xy, end_xy, speed_m_s: float = 0.1,
                 tap_interval_s: float = 0.04, method: str = "inverse", limit_v: float = DRIVE_LIMIT_V,
                 n_samples: int | None = None) -> MovingFocus:
    """Taps along a straight path at a given speed, each designed at its own position.

    Parameters
    ----------
    model : FittedSkin or SimulatedForearm
        Skin model giving ``transfer(points_xy, freqs)`` (see ``render``'s ``target_xy``).
    %(layout)s
    %(fs)s
    start_xy, end_xy : (float, float)
        Ends of the path on the skin, m.
    speed_m_s : float
        Speed of the focus along the path, m/s.
    tap_interval_s : float
        Time between taps, s (the path advances ``speed * interval`` per tap).
    method : str
        Rendering method of every tap.
    limit_v : float
        Drive limit, V; the summed drive is scaled down to it if needed.
    n_samples : int, optional
        Window of each tap's design, samples; default :func:`~vibrofocus.demo.design_window`
        of the model (4096 for a model that does not know its response length).

    Returns
    -------
    MovingFocus
    """
    from ..rendering import render
    from ..rendering.inverse import scale_to_peak

    start = as_array(start_xy, "start_xy", ndim=1, shape=(2,))
    end = as_array(end_xy, "end_xy", ndim=1, shape=(2,))
    speed = check_positive(speed_m_s, "speed_m_s")
    interval = check_positive(tap_interval_s, "tap_interval_s")
    length = float(np.linalg.norm(end - start))
    if length == 0:
        raise ValidationError("start_xy and end_xy are the same point: a moving focus needs a path")
    n_taps = int(np.floor(length / (speed * interval))) + 1
    if n_taps > 200:
        raise ValidationError(f"the path needs {n_taps} taps at this speed and interval; at most 200")
    frac = np.arange(n_taps) * speed * interval / length
    targets = start + frac[:, None] * (end - start)
    step = int(round(interval * fs))
    if n_samples is None:
        from .run import design_window

        n_samples = design_window(model)
    total = np.zeros((layout.n_actuators, n_samples + step * (n_taps - 1)))
    onsets = np.zeros(n_taps)
    for i, xy in enumerate(targets):  # one design per position (each its own matrix)
        r = render(method, model, fs, layout, target_xy=xy, limit_v=limit_v, n_samples=n_samples)
        total[:, i * step:i * step + n_samples] += r.drives
        onsets[i] = i * step / fs + r.t0
    peak = float(np.abs(total).max())
    # Overlapping taps add up: the sum is scaled down to the limit (to it, never one rounding over).
    drives, scale = (scale_to_peak(total, limit_v), limit_v / peak) if peak > limit_v else (total, 1.0)
    return MovingFocus(targets_xy=targets, onsets_s=onsets, drives=drives, fs=float(fs), scale=scale)


def write_moving_gif(focus: MovingFocus, arm, path, *, half_width_m: float = 0.025, n_grid: int = 41,
                     frames_per_tap: int = 3, fps: int = 8) -> Path:
    """Animate the field a moving focus makes on an arm and write it as a GIF, atomically.

    Parameters
    ----------
    focus : MovingFocus
    arm : SimulatedForearm
        The arm that plays the drive (its noise-free :meth:`field`).
    path : path-like
        GIF file; written through :func:`vibrofocus._atomic.atomic_path`.
    half_width_m : float
        Half width of the square field shown, m.
    n_grid : int
        Grid points per side.
    frames_per_tap : int
        Frames between one tap's peak and the next.
    fps : int
        Frames per second of the GIF.

    Returns
    -------
    Path
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.animation import FuncAnimation, PillowWriter

    import tempfile

    from .._atomic import write_bytes

    axis = np.linspace(-half_width_m, half_width_m, n_grid)
    gx, gy = np.meshgrid(axis, axis)
    grid = np.column_stack([gx.ravel(), gy.ravel()])
    dt = np.diff(focus.onsets_s).mean() if focus.onsets_s.size > 1 else 0.01
    times = np.concatenate([o + np.arange(frames_per_tap) * dt / frames_per_tap for o in focus.onsets_s])
    u = arm.field(focus.drives, grid, times).reshape(n_grid, n_grid, -1)
    vmax = float(np.abs(u).max()) or 1.0
    fig, ax = plt.subplots(figsize=(4.4, 4), layout="constrained")
    mm = half_width_m * 1e3
    img = ax.imshow(u[..., 0] * 1e6, origin="lower", extent=(-mm, mm, -mm, mm), cmap="RdBu_r",
                    vmin=-vmax * 1e6, vmax=vmax * 1e6)
    fig.colorbar(img, ax=ax, label="displacement (µm)")
    lay = arm.layout
    ax.plot(lay.actuators_xy[:, 0] * 1e3, lay.actuators_xy[:, 1] * 1e3, "ks", ms=8)
    ax.plot(focus.targets_xy[:, 0] * 1e3, focus.targets_xy[:, 1] * 1e3, "k.", ms=3)
    dot, = ax.plot([], [], "o", mfc="none", mec="k", ms=12)
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    fig.suptitle("Moving focus from the fitted skin model, played on the simulated forearm (a model)", fontsize=7)

    def frame(k):
        img.set_data(u[..., k] * 1e6)
        tap = min(k // frames_per_tap, len(focus.targets_xy) - 1)
        dot.set_data([focus.targets_xy[tap, 0] * 1e3], [focus.targets_xy[tap, 1] * 1e3])
        ax.set_title(f"t = {times[k] * 1e3:.0f} ms")
        return img, dot

    anim = FuncAnimation(fig, frame, frames=len(times), blit=False)
    try:
        # Pillow picks the format from the file name: draw into a private .gif, then
        # write its bytes to ``path`` atomically.
        with tempfile.TemporaryDirectory() as tmp:
            gif = Path(tmp) / "moving_focus.gif"
            anim.save(gif, writer=PillowWriter(fps=fps))
            data = gif.read_bytes()
    finally:
        plt.close(fig)
    return write_bytes(Path(path), data, what="moving-focus animation")
