"""A hardware rig from the web app: ``serve --rig audio --rig-config FILE`` on a real audio
device (JACK's loopback driver, as in tests/rigs), driven from the experimenter page."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from tests.rigs.conftest import jack_server  # noqa: F401 - the fixture
from tests.rigs.test_audio import jack_config

from .conftest import Server, free_port, login

pytestmark = [pytest.mark.browser, pytest.mark.slow]


def test_serve_refuses_a_hardware_rig_without_its_config(tmp_path):
    r = subprocess.run([sys.executable, "-m", "vibrofocus", "serve", "--rig", "audio", "--no-browser",
                        "--db", str(tmp_path / "s.sqlite")], capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and "--rig-config" in r.stderr


def test_calibrate_on_the_audio_rig_from_the_page(jack_server, tmp_path, chromium):  # noqa: F811
    config = tmp_path / "lab.json"
    config.write_text(json.dumps(jack_config()))
    server = Server(tmp_path / "studies.sqlite", free_port(), tmp_path / "server.log",
                    args=("--rig", "audio", "--rig-config", str(config)),
                    env={"JACK_DEFAULT_SERVER": jack_server.name, "JACK_NO_START_SERVER": "1"})
    server.start()
    context = chromium.new_context(viewport={"width": 1280, "height": 900})
    context.set_default_timeout(20_000)
    try:
        assert "rig: audio (lab.json)" in server.log.read_text()
        page = context.new_page()
        login(page, server)
        assert page.inner_text("#rig-label") == "audio (lab.json)"
        page.wait_for_function("document.getElementById('rig').options.length === 2")
        assert page.eval_on_selector_all("#rig option", "os => os.map(o => o.value)") == ["audio", "simulated"]
        assert page.input_value("#rig") == "audio"
        page.fill("#new-participant-id", "P40")
        page.click("#new-participant button")
        page.wait_for_function("document.getElementById('participant').value === 'P40'")
        # This interface has no strap sensors: the page says so in words.
        page.click("#straps")
        page.wait_for_function("document.getElementById('strap-message').textContent.includes('no strap force sensors')")
        # One vibrometer: the calibration asks where to aim it, records after Continue.
        page.click("#calibrate")
        page.wait_for_selector("#cal-prompt", state="visible")
        assert "Aim the vibrometer at point" in page.inner_text("#cal-prompt-text")
        assert server.api("GET", "/api/rigs").json()["label"] == "audio (lab.json)"
        page.click("#cal-continue")
        page.wait_for_function("document.getElementById('cal-progress').value > 0", timeout=60_000)
        page.click("#cal-cancel")
        page.wait_for_function("document.getElementById('flash').textContent.includes('cancelled')", timeout=60_000)
        assert server.rows("SELECT COUNT(*) FROM calibrations") == [(0,)]
        assert not page.is_visible("#cal-prompt") and not page.is_visible("#cal-cancel")
        # A session on this server's rig is planned; one on a rig it was not started for is refused.
        r = server.api("POST", "/api/sessions", json={"participant_id": "P40", "study": 1, "rig": "nidaq"})
        assert r.status_code == 409 and "--rig nidaq --rig-config" in r.json()["detail"]

        # One job on the hardware at a time. The server holds the interface: the CLI is refused...
        drives = tmp_path / "tap.npz"
        import numpy as np

        np.savez(drives, drives=np.zeros((4, 200)), fs=10_000.0)
        cli = subprocess.run([sys.executable, "-m", "vibrofocus", "play", str(drives), "--rig", "audio",
                              "--rig-config", str(config)], capture_output=True, text=True, timeout=60,
                             env={**os.environ, "JACK_DEFAULT_SERVER": jack_server.name, "JACK_NO_START_SERVER": "1"})
        assert cli.returncode == 2, cli.stderr
        assert "audio:loopback is in use by" in cli.stderr and "Traceback" not in cli.stderr
        # ...and so is a second calibration while one waits at its first point.
        page.click("#calibrate")
        page.wait_for_selector("#cal-prompt", state="visible")
        r = server.api("POST", "/api/calibrations", json={"participant_id": "P40", "rig": "audio"})
        assert r.status_code == 409 and "busy with the calibration of P40" in r.json()["detail"]
        # The emergency stop: outputs at zero, the calibration cancelled, said on the page.
        page.click("#emergency-stop")
        page.wait_for_function("document.getElementById('flash').textContent.includes('audio rig (lab.json): outputs at 0 V')")
        assert "calibration of P40 cancelled: nothing is saved" in page.inner_text("#flash")
    finally:
        context.close()
        server.stop()
