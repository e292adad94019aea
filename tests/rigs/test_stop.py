"""A stop from another thread is never forgotten, whenever it comes (issue: stop epoch).

The stop window these tests cover is the one before the drive reaches the device: the
drive is being checked, admitted to the energy budget, converted for the device. A stop
there must end the play with nothing played. The hooks run the stop from inside that
window, deterministically, instead of racing a timer against it.
"""

from __future__ import annotations

import threading

import numpy as np
import pytest

from vibrofocus import SimulatedForearm
from vibrofocus.rigs import StoppedError, parse_rig_config
from vibrofocus.rigs.nidaq import NidaqRig

from .fake_nidaqmx import FakeDevice

FS = 10_000.0


def _held_drive(seconds: float = 1.0, volts: float = 3.0) -> np.ndarray:
    """A 100 Hz square wave of +-volts: never near 0 V while it plays (no DC: the safety layer refuses DC)."""
    n = int(seconds * FS)
    return np.tile(volts * np.sign(np.sin(2 * np.pi * 100 * (np.arange(n) + 0.5) / FS)), (4, 1))


def _stop_inside_admit(rig):
    """Make the energy budget's admission call rig.stop() from another thread, then go on."""
    budget = rig.budget
    real = budget.admit

    def admit(drive, start_s):
        stopper = threading.Thread(target=rig.stop)
        stopper.start()
        stopper.join()
        return real(drive, start_s)

    budget.admit = admit
    return budget


@pytest.mark.parametrize("how", ["play", "play_and_record"])
def test_simulated_stop_during_admission_plays_nothing(how):
    rig = SimulatedForearm(seed=3, noise_m=0.0, dropout_rate=0.0)
    _stop_inside_admit(rig)
    with pytest.raises(StoppedError):
        getattr(rig, how)(_held_drive(0.1))
    assert rig.n_played == 0
    np.testing.assert_array_equal(rig.outputs_v, 0.0)


def test_a_stop_before_a_play_is_called_does_not_stop_it():
    rig = SimulatedForearm(seed=3, noise_m=0.0, dropout_rate=0.0)
    rig.stop()  # an old stop: the next play is a new one
    rig.play(_held_drive(0.1))
    assert rig.n_played == 1


def _nidaq(device) -> NidaqRig:
    cfg = {
        "kind": "nidaq", "fs": FS, "amplifier_gain": 10.0, "device": "Dev1",
        "channels": {"actuators": ["ao0", "ao1", "ao2", "ao3"], "vibrometer": "ai0"},
        "vibrometer": {"decoder": "displacement", "sensitivity": 1e-6, "highpass_hz": None},
    }
    rig = NidaqRig(parse_rig_config(cfg), task_factory=device.factory, system=device.system())
    device.forget_setup()  # the setup's idle-output probe (closed): tests count their own tasks
    return rig


def _drive_tasks_started(device) -> list[int]:
    """Numbers of the output tasks that were started with more than one sample written (drives, not zeros)."""
    numbers = []
    for task in device.tasks:
        started = (task.number, "start") in device.events
        if started and task.ao_channels.channels and task.data is not None and task.data.shape[1] > 1:
            numbers.append(task.number)
    return numbers


@pytest.mark.parametrize("how", ["play", "play_and_record"])
def test_nidaq_stop_during_admission_plays_nothing(how):
    device = FakeDevice(idle_zero=False)  # outputs hold their last value by themselves
    rig = _nidaq(device)
    _stop_inside_admit(rig)
    with pytest.raises(StoppedError):
        getattr(rig, how)(_held_drive(2.0))
    assert _drive_tasks_started(device) == []
    np.testing.assert_array_equal(device.output_vector(), 0.0)
    rig.close()


def test_nidaq_stop_between_task_creation_and_write_is_clean():
    """A stop after the output task exists but before it is written: no -50103, no 'stop FAILED'."""
    device = FakeDevice(idle_zero=False)
    rig = _nidaq(device)
    original = device.factory
    outcome = {}

    def factory():
        task = original()
        if len(device.tasks) == 1:  # the play's output task: stop while it is being set up
            def stop_now():
                try:
                    rig.stop()
                    outcome["stop"] = "ok"
                except Exception as exc:  # noqa: BLE001 - the test reports it
                    outcome["stop"] = repr(exc)
            stopper = threading.Thread(target=stop_now)
            stopper.start()
            stopper.join()
        return task

    rig._daq._task_factory = factory
    with pytest.raises(StoppedError):
        rig.play(_held_drive(2.0))
    assert outcome["stop"] == "ok"
    assert _drive_tasks_started(device) == []
    np.testing.assert_array_equal(device.output_vector(), 0.0)
    rig._daq._task_factory = original
    rig.close()


def test_nidaq_adapter_refuses_volts_over_the_cap():
    from vibrofocus.errors import SafetyError

    device = FakeDevice()
    rig = _nidaq(device)
    with pytest.raises(SafetyError, match="amplifier_input_max_v"):
        rig._daq.play(np.full((4, 100), 1.0 + 1e-6), stopped=lambda: False)
    with pytest.raises(SafetyError, match="finite"):
        rig._daq.play(np.full((4, 100), np.nan), stopped=lambda: False)
    assert not hasattr(rig, "tasks")  # the adapter is private: drives reach it through Rig.play only
    assert _drive_tasks_started(device) == []
    rig.close()


def test_limits_of_a_hardware_rig_cannot_be_replaced_on_the_open_rig():
    from vibrofocus.errors import ValidationError
    from vibrofocus.rigs import SafetyLimits

    device = FakeDevice()
    rig = _nidaq(device)
    rig.play(_held_drive(0.5, 1.0))
    budget = rig.budget
    with pytest.raises(ValidationError, match="cannot be changed"):
        rig.limits = SafetyLimits(peak_v=10.0, rms_v=4.0)
    assert rig.budget is budget  # the history of the plays is kept
    rig.close()


def test_a_backend_cannot_override_the_final_methods():
    from vibrofocus.rigs import Rig

    with pytest.raises(TypeError, match="final"):
        class Unsafe(Rig):  # noqa: F841 - defining it is the test
            def play(self, drive):
                return None


def test_a_second_ctrl_c_while_the_outputs_are_zeroed_leaves_no_voltage():
    """Ctrl-C mid-play, then Ctrl-C again while the zero is being written: the zero is still written."""
    import signal

    device = FakeDevice(idle_zero=False)  # outputs hold their last value
    rig = _nidaq(device)
    real_zero = rig._daq.write_zeros
    calls = []

    def write_zeros():
        calls.append("zero")
        if len(calls) == 1:
            signal.raise_signal(signal.SIGINT)  # the second Ctrl-C, inside the zero write
        real_zero()

    def play(volts, *, stopped):
        device.outputs.update({ch: 0.3 for ch in device.ao_names})  # mid-drive, held by the device
        raise KeyboardInterrupt  # the first Ctrl-C

    rig._daq.write_zeros = write_zeros
    rig._daq.play = play
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        with pytest.raises(KeyboardInterrupt):
            rig.play(_held_drive(0.2))
    finally:
        signal.signal(signal.SIGINT, previous)
    np.testing.assert_array_equal(device.output_vector(), 0.0)
    rig._daq.write_zeros = real_zero
    rig.close()
