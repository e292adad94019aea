"""serve's beep check on a rig whose outputs are JACK's ``system`` (PortAudio's default on Linux)."""

from __future__ import annotations

import pytest

from vibrofocus.errors import ValidationError
from vibrofocus.rigs import parse_rig_config

from .test_audio import jack_config


def _system_config():
    cfg = jack_config(actuators=[1, 2], loopback_output=None, loopback_input=None)
    cfg["device"]["name"] = "system"
    return parse_rig_config(cfg)


def test_a_rig_on_jack_system_is_not_refused_for_portaudios_default_output(jack_server):
    import sounddevice as sd

    from vibrofocus.cli.serve import _check_page_beep_output

    assert sd.query_devices(kind="output")["name"] == "system"  # the case: PortAudio's default is the rig
    _check_page_beep_output(_system_config(), False)  # the browser plays through PulseAudio/PipeWire


def test_a_program_connected_to_the_actuator_outputs_is_refused(jack_server):
    import jack

    from vibrofocus.cli.serve import _check_page_beep_output

    with jack.Client("desktop-sink", no_start_server=True) as other:
        port = other.outports.register("front-left")
        other.connect(port, "system:playback_1")
        with pytest.raises(ValidationError, match=r"another program feeds the actuator outputs on JACK "
                                                  r"\(desktop-sink:front-left -> system:playback_1\)"):
            _check_page_beep_output(_system_config(), False)
