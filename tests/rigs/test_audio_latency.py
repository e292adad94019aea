"""``vibrofocus latency`` on the audio rig against JACK's dummy driver: its loopback port
returns what was played one JACK period later, so every click's latency is that period."""

from __future__ import annotations

import numpy as np
import pytest

from vibrofocus.realtime import measure_latency
from vibrofocus.rigs import make_rig

from .conftest import JACK_PERIOD, JACK_RATE
from .test_audio import jack_config

pytestmark = [pytest.mark.jack, pytest.mark.slow]


def test_latency_through_jack_loopback_is_one_period(jack_server):
    with make_rig("audio", config=jack_config()) as rig:
        report = measure_latency(rig, count=5, spacing_s=0.0, loopback=5, channel=1, amplitude_v=1.0)
    assert report.input_fs == JACK_RATE
    lat = np.asarray(report.latencies_s)
    # The output stream starts on a period boundary: one period of round trip, to a sample.
    np.testing.assert_allclose(lat, JACK_PERIOD / JACK_RATE, atol=1.5 / JACK_RATE)
    assert report.stats_ms["sd"] < 1e3 / JACK_RATE
