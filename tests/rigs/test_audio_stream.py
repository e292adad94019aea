"""The budget's time axis of a running audio stream (no audio server needed)."""

import numpy as np
import pytest

from vibrofocus.rigs.audio_stream import ANCHOR_WINDOW_S, FrameAxis

FS = 48000.0
BUFFER = 1024
LATENCY_S = 2 * 4096 / FS  # how far ahead of its callback a buffer reaches the outputs


def feed(axis: FrameAxis, true_anchor_s: float, frames: np.ndarray, delays_s: np.ndarray,
         lost: np.ndarray | None = None, rate_error: float = 0.0) -> None:
    """Callbacks at ``frames``, each ``delays_s`` late on the host; the device clock runs
    ``1 + rate_error`` times the host's (its frames fall behind the host for a negative error)."""
    lost = np.zeros(len(frames), bool) if lost is None else lost
    for frame, delay, was_lost in zip(frames, delays_s, lost):
        due = true_anchor_s + frame / (FS * (1 + rate_error)) - LATENCY_S
        # The stream's own clock: currentTime at the callback, the DAC time a latency later.
        axis.update(due + delay, int(frame), 5.0, 5.0 + LATENCY_S, lost=bool(was_lost))


def test_a_late_first_callback_does_not_move_the_axis_once_an_on_time_one_comes():
    rng = np.random.default_rng(7)
    frames = np.arange(40) * BUFFER  # 0.85 s: one window
    delays = rng.exponential(0.002, size=40)
    delays[0] = 0.030  # the first callback, on a loaded machine
    axis = FrameAxis(FS)
    feed(axis, 100.0, frames, delays)
    # A callback is never early: the axis is the earliest estimate, late by the least delay.
    assert axis.anchor_s == pytest.approx(100.0 + delays.min(), abs=1e-9)
    assert axis.anchor_s - 100.0 < 0.001


def test_buffers_handed_on_in_pieces_of_a_cycle_give_one_axis():
    # PortAudio's JACK host calls back four times per 4096-frame cycle, at once: the host time
    # barely moves while the DAC time moves on a buffer each time.
    axis = FrameAxis(FS)
    for cycle in range(5):
        host = 10.0 + cycle * 4096 / FS
        for piece in range(4):
            first = cycle * 4096 + piece * BUFFER
            axis.update(host + piece * 1e-5, first, 3.0, 3.0 + LATENCY_S + piece * BUFFER / FS)
    assert axis.anchor_s == pytest.approx(10.0 + LATENCY_S, abs=1e-9)


def test_a_lost_buffer_moves_the_axis_on_to_the_late_frames_never_back():
    axis = FrameAxis(FS)
    frames = np.arange(30) * BUFFER
    feed(axis, 50.0, frames, np.zeros(30))
    before = axis.anchor_s
    # The server paused 0.4 s: its frames restart behind the host's clock for good.
    later = frames[-1] + BUFFER * (1 + np.arange(30))
    lost = np.zeros(30, bool)
    lost[0] = True
    feed(axis, 50.4, later, np.full(30, 0.001), lost)
    assert axis.anchor_s == pytest.approx(50.401, abs=1e-9)
    assert axis.anchor_s > before
    # A lost buffer whose estimate is earlier (a device that kept its frames) never moves it back.
    frame = int(later[-1] + BUFFER)
    axis.update(50.4 + frame / FS - LATENCY_S - 0.1, frame, 5.0, 5.0 + LATENCY_S, lost=True)
    assert axis.anchor_s == pytest.approx(50.401, abs=1e-9)


@pytest.mark.parametrize("rate_error", [-100e-6, 100e-6])
def test_the_axis_follows_a_drift_between_the_device_and_host_clocks(rate_error):
    # A minute of callbacks from a device whose crystal is 100 ppm off: the axis drifts
    # 6 ms in that minute, and tracks it to within two windows' drift.
    axis = FrameAxis(FS)
    frames = np.arange(int(60 * FS / BUFFER)) * BUFFER
    feed(axis, 20.0, frames, np.zeros(len(frames)), rate_error=rate_error)
    now_frame = frames[-1]
    true_now = 20.0 + now_frame / (FS * (1 + rate_error))
    assert abs(axis.anchor_s + now_frame / FS - true_now) <= 2 * ANCHOR_WINDOW_S * abs(rate_error) + 1e-9
    assert abs(axis.anchor_s - 20.0) > 0.005  # it did move: a fixed axis would be 6 ms off


def test_times_the_host_api_does_not_give_mean_a_buffer_at_the_outputs_now():
    axis = FrameAxis(FS)
    axis.update(7.0, 0, float("nan"), float("nan"))
    assert axis.anchor_s == 7.0
    axis.update(7.5, 2 * BUFFER, 1.0, 9.0)  # 8 s apart: not a latency
    assert axis.anchor_s == pytest.approx(min(7.0, 7.5 - 2 * BUFFER / FS))
