"""A rig's onset latency and jitter through a loopback (``vibrofocus latency``).

Each click is played on its own, as a tap is, through :meth:`Rig.play_and_capture`: one
stream that plays the click on an actuator output and records the loopback input from
the same instant. The click's onset in the recording, less its onset in the drive, is
that play's latency; their spread over many plays is the jitter.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._docs import fill_doc
from .._validation import check_in_range, check_positive
from ..errors import ValidationError
from ..rigs.devices import DeviceError

__all__ = ["LatencyReport", "click_drive", "onset_s", "measure_latency", "latency_figure"]

#: A click: one raised-cosine pulse this long, s.
CLICK_S = 1e-3
#: Silence before the click in its drive, s (the safety layer's fade-in lies in it).
PRE_S = 10e-3
#: Silence after the click, s.
POST_S = 40e-3
#: An onset is where the signal first reaches this fraction of its peak.
ONSET_FRACTION = 0.5
#: Peak of a detected click over the recording's median magnitude, at least.
MIN_PEAK_OVER_FLOOR = 20.0


@dataclass(frozen=True)
class LatencyReport:
    """Onset latencies of one run.

    Attributes
    ----------
    rig : str
        The rig's kind.
    latencies_s : ndarray, shape (count,)
        Onset latency of each click, s.
    input_fs : float
        Sample rate of the recordings, Hz.
    loopback : int
        The input channel recorded.
    spacing_s : float
        Time between clicks, s.
    details : dict
        Other settings of the run, JSON-ready (the output channel, the click's peak in V).
    """

    rig: str
    latencies_s: np.ndarray
    input_fs: float
    loopback: int
    spacing_s: float
    details: dict = field(default_factory=dict)

    @property
    def stats_ms(self) -> dict[str, float]:
        """Mean, SD (ddof 1), 99th percentile, minimum and maximum, ms."""
        ms = np.asarray(self.latencies_s) * 1e3
        return {"mean": float(ms.mean()), "sd": float(ms.std(ddof=1)) if len(ms) > 1 else 0.0,
                "p99": float(np.percentile(ms, 99)), "min": float(ms.min()), "max": float(ms.max())}

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: the statistics (ms), every latency (ms) and the settings."""
        return {"rig": self.rig, "count": int(len(self.latencies_s)), "spacing_s": self.spacing_s,
                "loopback": self.loopback, "input_fs": self.input_fs, "latency_ms": self.stats_ms,
                "latencies_ms": [round(float(v) * 1e3, 6) for v in self.latencies_s], **self.details}


@fill_doc
def click_drive(fs: float, n_actuators: int, channel: int, amplitude_v: float) -> np.ndarray:
    """The drive of one click on one actuator.

    Parameters
    ----------
    %(fs)s
    n_actuators : int
    channel : int
        1-based actuator output the click plays on.
    amplitude_v : float
        Its peak, V.

    Returns
    -------
    ndarray, shape (n_actuators, n)
        V: ``PRE_S`` of silence, a raised-cosine pulse of ``CLICK_S``, ``POST_S`` of silence.
    """
    fs = check_positive(fs, "fs")
    if not 1 <= channel <= n_actuators:
        raise ValidationError(f"--channel {channel}: the rig has actuator outputs 1..{n_actuators}")
    n_click = max(3, int(round(CLICK_S * fs)))
    pulse = amplitude_v * 0.5 * (1 - np.cos(2 * np.pi * np.arange(n_click) / (n_click - 1)))
    n_pre, n_post = int(round(PRE_S * fs)), int(round(POST_S * fs))
    drive = np.zeros((n_actuators, n_pre + n_click + n_post))
    drive[channel - 1, n_pre:n_pre + n_click] = pulse
    return drive


def onset_s(signal: np.ndarray, fs: float) -> float:
    """Where a click begins: the first crossing of ``ONSET_FRACTION`` of its peak, s.

    Linear interpolation between the two samples around the crossing gives it below a
    sample. The peak's sign is the click's: a loopback that inverts the polarity works.

    Parameters
    ----------
    signal : ndarray, shape (n,)
    fs : float
        Its sample rate, Hz.

    Returns
    -------
    float
        s from the first sample.

    Raises
    ------
    DeviceError
        When nothing stands out of the noise (no click arrived).
    """
    x = np.asarray(signal, dtype=float)
    if not np.isfinite(x).all():
        raise DeviceError("the loopback recording holds NaN or Inf")
    peak_at = int(np.argmax(np.abs(x)))
    peak = x[peak_at]
    floor = float(np.median(np.abs(x)))
    if peak == 0 or abs(peak) < MIN_PEAK_OVER_FLOOR * floor:
        raise DeviceError("no click came back on the loopback input (its peak does not stand out of the noise); "
                          "check the loopback cable and --loopback / --channel")
    y = x * np.sign(peak)
    level = ONSET_FRACTION * abs(peak)
    k = int(np.flatnonzero(y[:peak_at + 1] >= level)[0])
    if k == 0:
        return 0.0
    frac = (level - y[k - 1]) / (y[k] - y[k - 1])
    return (k - 1 + frac) / fs


def measure_latency(rig: Any, *, count: int, spacing_s: float, loopback: int, channel: int = 1,
                    amplitude_v: float = 1.0, progress: Any = None) -> LatencyReport:
    """Play ``count`` clicks, one per stream, and measure each one's onset latency.

    Parameters
    ----------
    rig : Rig
        A rig with :meth:`~vibrofocus.rigs.Rig.play_and_capture` (simulated, audio, nidaq).
    count : int
        Clicks, >= 2.
    spacing_s : float
        Time from one click's play to the next, s (a play longer than it follows at once).
    loopback : int
        The input channel the loopback comes back on (1-based; on the nidaq rig, input
        ``k`` is the device's ``ai<k-1>``).
    channel : int
        The actuator output the clicks play on (1-based).
    amplitude_v : float
        Click peak at the actuator, V.
    progress : callable, optional
        Called with the number of clicks done.

    Returns
    -------
    LatencyReport
    """
    if isinstance(count, bool) or not isinstance(count, int) or count < 2:
        raise ValidationError(f"count must be an integer >= 2, got {count!r}")
    spacing_s = check_in_range(spacing_s, "spacing_s", 0.0, 60.0)
    drive = click_drive(rig.fs, rig.layout.n_actuators, channel, check_positive(amplitude_v, "amplitude_v"))
    sent = rig.check(drive)  # what plays, its fades included
    sent_onset = onset_s(sent[channel - 1], rig.fs)
    latencies, fs_in = [], None
    with rig.reserve("a latency measurement"):
        for i in range(count):
            start = time.monotonic()
            recording, fs_in = rig.play_and_capture(drive, loopback)
            latencies.append(onset_s(recording, fs_in) - sent_onset)
            if progress is not None:
                progress(i + 1)
            rest = spacing_s - (time.monotonic() - start)
            if rest > 0 and i + 1 < count:
                time.sleep(rest)
    return LatencyReport(rig.kind, np.asarray(latencies), float(fs_in), int(loopback), float(spacing_s),
                         {"channel": int(channel), "amplitude_v": float(amplitude_v)})


def latency_figure(report: LatencyReport):
    """Histogram of the latencies, ms, with the mean and the 99th percentile marked.

    Parameters
    ----------
    report : LatencyReport

    Returns
    -------
    matplotlib.figure.Figure
    """
    from matplotlib.figure import Figure

    ms = np.asarray(report.latencies_s) * 1e3
    stats = report.stats_ms
    fig = Figure(figsize=(5.5, 3.2), layout="constrained")
    ax = fig.add_subplot()
    span = ms.max() - ms.min()
    bins = 1 if span == 0 else min(50, max(10, len(ms) // 10))
    ax.hist(ms, bins=bins, range=None if span else (ms[0] - 0.05, ms[0] + 0.05), color="0.45")
    ax.axvline(stats["mean"], color="C0", label=f"mean {stats['mean']:.3f} ms (SD {stats['sd']:.3f})")
    ax.axvline(stats["p99"], color="C3", ls="--", label=f"99th percentile {stats['p99']:.3f} ms")
    ax.set_xlabel("onset latency through the loopback (ms)")
    ax.set_ylabel("clicks")
    ax.set_title(f"{report.rig} rig: {len(ms)} clicks, {report.spacing_s:g} s apart", fontsize=10)
    ax.legend(fontsize=8, frameon=False)
    return fig
