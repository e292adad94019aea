"""One job on the hardware at a time, and the emergency stop, through the web app's API.

The rig is the NI rig on the FAKE NI-DAQmx task layer of tests/rigs (no NI driver runs
here); the app, its routes and its calibration thread are the real ones, in process.
"""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest
from fastapi.testclient import TestClient

from tests.rigs.fake_nidaqmx import FakeDevice
from tests.rigs.test_nidaq import nidaq_config
from vibrofocus.rigs import parse_rig_config
from vibrofocus.rigs.nidaq import NidaqRig
from vibrofocus.web.app import create_app

TOKEN = "t" * 32


def _nidaq_app(tmp_path, device):
    """The web app on the NI rig over ``device`` (a FAKE NI device); returns (app, the rigs it made)."""
    made = []

    def factory(kind, seed=None, config=None):
        if kind == "simulated":
            from vibrofocus.rigs import make_rig

            return make_rig("simulated", seed=seed)
        rig = NidaqRig(parse_rig_config(nidaq_config(force_sensors=None)), task_factory=device.factory,
                       system=device.system())
        made.append(rig)
        return rig

    config = tmp_path / "lab.json"
    config.write_text("{}")
    app = create_app(tmp_path / "s.sqlite", token=TOKEN, rig="nidaq", rig_factory=factory, rig_config=config,
                     allowed_hosts=("testserver",), resume=False)
    return app, made


def _client(app):
    return TestClient(app, headers={"X-Vibrofocus-Token": TOKEN, "Origin": "http://testserver"})


@pytest.fixture
def app_and_device(tmp_path):
    device = FakeDevice()
    app, made = _nidaq_app(tmp_path, device)
    with _client(app) as client:
        yield client, device, made
    for rig in made:
        rig.close()


def _wait(client, job_id, status, timeout=10.0):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        job = client.get(f"/api/calibrations/jobs/{job_id}").json()
        if job["status"] == status:
            return job
        time.sleep(0.05)
    raise AssertionError(f"job never reached {status}: {job}")


def test_a_second_hardware_job_is_refused_and_the_emergency_stop_zeroes_the_outputs(app_and_device):
    client, device, made = app_and_device
    assert client.post("/api/participants", json={"participant_id": "P01"}).status_code == 201
    r = client.post("/api/calibrations", json={"participant_id": "P01", "rig": "nidaq"})
    assert r.status_code == 202
    job_id = r.json()["job_id"]
    _wait(client, job_id, "waiting")  # at its first point, holding the rig
    # Another seed names the same physical device: one rig, still busy.
    r = client.post("/api/calibrations", json={"participant_id": "P01", "rig": "nidaq", "seed": 3})
    assert r.status_code == 409
    assert "The nidaq rig is busy with the calibration of P01" in r.json()["detail"]
    assert len(made) == 1
    device.outputs["Dev1/ao1"] = 0.4  # as if a drive were holding its last value
    r = client.post("/api/emergency-stop")
    assert r.status_code == 200
    assert r.json()["stopped"] == ["nidaq rig (lab.json): outputs at 0 V", "calibration of P01 cancelled: nothing is saved"]
    np.testing.assert_array_equal(device.output_vector(), 0.0)
    _wait(client, job_id, "cancelled")
    # Free again once the job ended.
    r = client.post("/api/calibrations", json={"participant_id": "P01", "rig": "nidaq"})
    assert r.status_code == 202
    client.post(f"/api/calibrations/jobs/{r.json()['job_id']}/cancel")


def test_progress_is_reported_while_a_calibration_runs(app_and_device):
    # The single-spot rig stops before each point, which holds the job mid-way whatever
    # the machine's speed: the page must then show a fraction strictly between 0 and 1.
    client, _, _ = app_and_device
    assert client.post("/api/participants", json={"participant_id": "P02"}).status_code == 201
    job_id = client.post("/api/calibrations", json={"participant_id": "P02", "rig": "nidaq"}).json()["job_id"]
    first = _wait(client, job_id, "waiting")
    assert first["progress"] == 0.0 and "point" in first["prompt"]
    assert client.post(f"/api/calibrations/jobs/{job_id}/continue").status_code == 200
    # Whatever the speed, the job stops again at the next point with takes done.
    deadline = time.monotonic() + 120.0
    while True:
        job = client.get(f"/api/calibrations/jobs/{job_id}").json()
        if job["progress"] > 0.0 or job["status"] not in ("running", "waiting"):
            break
        assert time.monotonic() < deadline, job
        time.sleep(0.02)
    assert 0.0 < job["progress"] < 1.0, job
    assert job["message"] != "starting", job
    assert client.post(f"/api/calibrations/jobs/{job_id}/cancel").status_code == 200
    assert _wait(client, job_id, "cancelled")["progress"] < 1.0


def test_a_server_shut_down_mid_calibration_stops_the_rig_and_closes_it(tmp_path):
    """SIGTERM/Ctrl-C of `vibrofocus serve` runs the app's shutdown: zero written last, job ended, rig closed."""
    device = FakeDevice(idle_zero=False)  # outputs hold their last value: only a zero write brings them down
    app, made = _nidaq_app(tmp_path, device)
    with _client(app) as client:
        assert client.post("/api/participants", json={"participant_id": "P03"}).status_code == 201
        job_id = client.post("/api/calibrations", json={"participant_id": "P03", "rig": "nidaq"}).json()["job_id"]
        _wait(client, job_id, "waiting")
        assert client.post(f"/api/calibrations/jobs/{job_id}/continue").status_code == 200
        deadline = time.monotonic() + 10
        while not (device.last_output is not None and device.last_output.state == "running"):
            assert time.monotonic() < deadline, "the sweep never started"
            time.sleep(0.005)
        threads = [t for t in threading.enumerate() if t.name == f"calibration-{job_id}"]
    # The lifespan's shutdown has run (as at SIGTERM): the sweep stopped, the rig closed.
    np.testing.assert_array_equal(device.output_vector(), 0.0)
    last_ao = [t for t in device.tasks if t.ao_channels.channels][-1]
    assert last_ao.written and not np.any(last_ao.written[-1])  # the last write was zeros
    assert not any(t.is_alive() for t in threads)
    assert made[0].device_lock is None or not made[0].device_lock.held
    assert all(t.state == "closed" for t in device.tasks)
