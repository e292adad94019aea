"""Fixtures of the rig tests: a real JACK server on its dummy driver for the audio rig.

The server runs under its own name (so it never meets a lab's or a colleague's JACK
server) with JACK's loopback driver (``-L``): every ``loopback:playback_k`` port comes
back on ``loopback:capture_k`` one period later, like a cable from output k to input k
of an audio interface. PortAudio lists those ports as the device ``loopback`` of its
JACK host API.
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import tempfile
import time

from types import SimpleNamespace

import pytest

#: Rate and period of the test server; the rig runs at 10 kHz and resamples (24/5).
JACK_RATE = 48_000
JACK_PERIOD = 4096
#: Loopback ports: four actuators, the latency loopback, a spare.
JACK_LOOPBACK_PORTS = 6

# libjack would otherwise start a default server when a client finds none.
os.environ.setdefault("JACK_NO_START_SERVER", "1")


def _reinit_portaudio() -> None:
    # PortAudio lists devices once, at initialisation: make it look again.
    import sounddevice as sd

    sd._terminate()
    sd._initialize()


@pytest.fixture(scope="session")
def jack_server():
    """Start ``jackd -d dummy`` with loopback ports; stop it at the end.

    Yields a namespace with ``name``, ``rate`` (Hz) and ``period`` (samples).
    """
    if shutil.which("jackd") is None or shutil.which("jack_wait") is None:
        reason = "jackd is not installed (apt-get install jackd2); the audio rig tests need a JACK server"
        if os.environ.get("CI"):
            pytest.fail(reason)
        pytest.skip(reason)
    try:
        import sounddevice  # noqa: F401
    except OSError as exc:
        reason = f"PortAudio is not installed (apt-get install libportaudio2): {exc}"
        if os.environ.get("CI"):
            pytest.fail(reason)
        pytest.skip(reason)
    name = f"vibrofocus-test-{os.getpid()}"
    env_before = os.environ.get("JACK_DEFAULT_SERVER")
    os.environ["JACK_DEFAULT_SERVER"] = name
    cmd = ["jackd", "-n", name, "--no-realtime", "-L", str(JACK_LOOPBACK_PORTS),
           "-d", "dummy", "-r", str(JACK_RATE), "-p", str(JACK_PERIOD), "-C", "2", "-P", "2"]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, start_new_session=True)
    try:
        deadline = time.monotonic() + 15
        while True:
            ok = subprocess.run(["jack_wait", "-s", name, "-c"], capture_output=True, text=True)
            if "running" in ok.stdout and "not" not in ok.stdout:
                break
            if proc.poll() is not None or time.monotonic() > deadline:
                out = proc.stdout.read().decode(errors="replace") if proc.poll() is not None else ""
                pytest.fail(f"jackd did not start: {' '.join(cmd)}\n{out}")
            time.sleep(0.1)
        _reinit_portaudio()
        yield SimpleNamespace(name=name, rate=JACK_RATE, period=JACK_PERIOD)
    finally:
        try:
            import sounddevice as sd

            sd.stop()
            sd._terminate()  # close PortAudio's JACK client before the server goes
        except Exception:  # noqa: BLE001 - teardown must go on to stop the server
            pass
        proc.terminate()
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
        if env_before is None:
            os.environ.pop("JACK_DEFAULT_SERVER", None)
        else:
            os.environ["JACK_DEFAULT_SERVER"] = env_before
        try:
            import sounddevice as sd

            sd._initialize()
        except Exception:  # noqa: BLE001
            pass


def start_private_jackd(name: str) -> subprocess.Popen:
    """A JACK server named ``name`` (dummy driver, loopback ports, the test rate and period), running."""
    log = tempfile.TemporaryFile("w+")  # not a pipe: a server whose output nobody reads would block on it
    proc = subprocess.Popen(["jackd", "-n", name, "--no-realtime", "-L", str(JACK_LOOPBACK_PORTS), "-d", "dummy",
                             "-r", str(JACK_RATE), "-p", str(JACK_PERIOD), "-C", "2", "-P", "2"],
                            stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
    deadline = time.monotonic() + 15
    while True:
        answer = subprocess.run(["jack_wait", "-s", name, "-c"], capture_output=True, text=True).stdout
        if "running" in answer and "not" not in answer:
            return proc
        if time.monotonic() > deadline:
            proc.kill()
            proc.wait()
            log.seek(0)
            pytest.fail(f"the private jackd {name} did not start: {log.read()[-1500:]}")
        time.sleep(0.1)


def end_private_jackd(proc: subprocess.Popen, name: str) -> None:
    """Stop a private server; one that dies (of SIGPIPE, writing to a client gone while it was
    stopped) leaves its entry in JACK's registry of servers, which holds 8: a server of the same
    name, started and stopped, takes the entry back."""
    if proc.poll() is None:
        os.kill(proc.pid, signal.SIGCONT)
        proc.terminate()
        try:
            proc.wait(10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
    if proc.returncode != 0:
        again = start_private_jackd(name)
        again.terminate()
        again.wait(10)
