"""`vibrofocus serve` on the audio rig, stopped by SIGTERM in the middle of a calibration sweep.

A real JACK server (dummy driver) and a second JACK client recording what the actuators
get: the outputs must be silent within 100 ms plus the interface's latency of the signal.
"""

from __future__ import annotations

import json
import signal
import time

import numpy as np
import pytest

from tests.web.conftest import Server, free_port

from .test_audio import JACK_PERIOD, JACK_RATE, _LoopbackRecorder, jack_config

pytestmark = [pytest.mark.jack, pytest.mark.slow]


def test_serve_stopped_by_sigterm_mid_calibration_silences_the_outputs(jack_server, tmp_path):
    config = tmp_path / "lab.json"
    config.write_text(json.dumps(jack_config()))
    server = Server(tmp_path / "s.sqlite", free_port(), tmp_path / "serve.log",
                    args=("--rig", "audio", "--rig-config", str(config), "--participant-audio-elsewhere"))
    server.start()
    try:
        assert server.api("POST", "/api/participants", json={"participant_id": "P01"}).status_code == 201
        r = server.api("POST", "/api/calibrations", json={"participant_id": "P01", "rig": "audio"})
        assert r.status_code == 202, r.text
        job = r.json()["job_id"]
        deadline = time.monotonic() + 30
        while server.api("GET", f"/api/calibrations/jobs/{job}").json()["status"] != "waiting":
            assert time.monotonic() < deadline, server.log.read_text()
            time.sleep(0.05)
        with _LoopbackRecorder() as recorder:
            assert server.api("POST", f"/api/calibrations/jobs/{job}/continue").status_code == 200
            deadline = time.monotonic() + 30
            while not recorder.chunks or np.abs(recorder.signal()[1]).max() < 0.01:  # the sweep is playing
                assert time.monotonic() < deadline, "the sweep never reached the outputs"
                time.sleep(0.02)
            time.sleep(0.3)
            sent = recorder.now()
            server.proc.send_signal(signal.SIGTERM)
            server.proc.wait(30)
            time.sleep(3 * JACK_PERIOD / JACK_RATE)
        times, x = recorder.signal()
    finally:
        server.stop()
    loud = np.flatnonzero(np.abs(x).max(axis=1) > 1e-4)
    last = times[loud[-1]] - sent
    # 100 ms plus the stream's latency (one period here) plus the loopback's own period.
    allowed = 0.100 + 2 * JACK_PERIOD / JACK_RATE + JACK_PERIOD / JACK_RATE
    print(f"last output {1e3 * last:.0f} ms after SIGTERM (allowed {1e3 * allowed:.0f} ms)")
    assert last < allowed
    assert "shutting down" in server.log.read_text()
