"""Where ``fcntl`` does not exist (Windows), ``vibrofocus.rigs``, ``calibration`` and
``realtime`` still import and the simulated rig plays; device locks use Windows' byte-range
locks (``msvcrt.locking``).

Each case runs in a fresh interpreter in which ``import fcntl`` fails. Windows' ``msvcrt``
is stood in for by Linux's open-file-description locks, which like Windows' belong to one
open file (two opens in one process exclude each other) and lock byte ranges.
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

SRC = str(Path(__file__).resolve().parents[2] / "src")

NO_FCNTL = """
import sys
sys.modules["fcntl"] = None  # import fcntl raises ImportError, as on Windows
"""

# msvcrt.locking(fd, mode, nbytes) on the bytes from the file's position, never waiting.
FAKE_MSVCRT = """
import errno, os, struct, sys, types
import subprocess  # which takes any msvcrt as the sign of Windows: loaded before the stand-in
import fcntl as _fcntl
_F_OFD_SETLK = getattr(_fcntl, "F_OFD_SETLK", 37)

def _locking(fd, mode, nbytes):
    start = os.lseek(fd, 0, os.SEEK_CUR)
    kind = _fcntl.F_UNLCK if mode == 0 else _fcntl.F_WRLCK
    try:
        _fcntl.fcntl(fd, _F_OFD_SETLK, struct.pack("hhqqi4x", kind, os.SEEK_SET, start, nbytes, 0))
    except OSError:
        raise PermissionError(errno.EACCES, "Permission denied") from None

msvcrt = types.ModuleType("msvcrt")
msvcrt.locking, msvcrt.LK_UNLCK, msvcrt.LK_LOCK, msvcrt.LK_NBLCK, msvcrt.LK_RLCK, msvcrt.LK_NBRLCK = _locking, 0, 1, 2, 3, 4
sys.modules["msvcrt"] = msvcrt
""" + NO_FCNTL


def _run(prelude: str, body: str, tmp_path: Path) -> str:
    env = dict(os.environ, PYTHONPATH=SRC, VIBROFOCUS_LOCK_DIR=str(tmp_path / "locks"), MPLBACKEND="Agg",
               PYTHONDONTWRITEBYTECODE="1")
    out = subprocess.run([sys.executable, "-c", textwrap.dedent(prelude) + textwrap.dedent(body)], env=env,
                         capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert out.returncode == 0, out.stderr[-3000:]
    return out.stdout


def test_imports_and_a_play_on_the_simulated_rig_need_no_fcntl(tmp_path):
    out = _run(NO_FCNTL, """
        import numpy as np
        import vibrofocus.rigs, vibrofocus.calibration, vibrofocus.realtime
        from vibrofocus.rigs import make_rig
        from vibrofocus.signals import ricker

        rig = make_rig("simulated", seed=1)
        drive = np.zeros((rig.layout.n_actuators, 2000))
        drive[0] = 2.0 * ricker(rig.fs, duration=2000 / rig.fs, t0=0.05)
        onset = rig.play(drive)
        assert rig.n_played == 1 and (rig.outputs_v == 0).all()
        assert "fcntl" not in sys.modules or sys.modules["fcntl"] is None
        print("played")
    """, tmp_path)
    assert out.strip() == "played"


def test_device_locks_use_byte_range_locks_without_fcntl(tmp_path):
    if not sys.platform.startswith("linux"):
        pytest.skip("the stand-in for msvcrt uses Linux open-file-description locks")
    out = _run(FAKE_MSVCRT, """
        from vibrofocus.rigs import DeviceBusyError, DeviceLock
        from vibrofocus.rigs.audio import audio_lock_keys
        import vibrofocus.rigs.device_lock as dl
        assert dl.fcntl is None and dl.msvcrt is not None

        a = DeviceLock("nidaq:Dev1", "first").acquire()
        try:
            DeviceLock("nidaq:Dev1", "second").acquire()
            raise SystemExit("a second lock on one device was taken")
        except DeviceBusyError as exc:
            assert "nidaq:Dev1 is in use by first" in str(exc), exc
        a.release()
        DeviceLock("nidaq:Dev1", "second").acquire().release()

        # Shared holds (two interfaces) live side by side; a routing name excludes them both.
        motu = DeviceLock("audio:motu", "motu job", keys=audio_lock_keys("MOTU Pro Audio")).acquire()
        focus = DeviceLock("audio:focusrite", "focusrite job", keys=audio_lock_keys("Focusrite USB ASIO")).acquire()
        for name in ("Out 1-2 (MOTU Pro Aud", "default"):
            try:
                DeviceLock("audio:" + name, "late", keys=audio_lock_keys(name)).acquire()
                raise SystemExit(name + " was taken beside the MOTU")
            except DeviceBusyError:
                pass
        motu.release()
        focus.release()
        DeviceLock("audio:mix", "mix job", keys=audio_lock_keys("default")).acquire().release()
        print("locked")
    """, tmp_path)
    assert out.strip() == "locked"


def test_without_any_file_lock_a_hardware_lock_is_a_clear_device_error(tmp_path):
    out = _run(NO_FCNTL + 'sys.modules["msvcrt"] = None\n', """
        from vibrofocus.rigs import DeviceError, DeviceLock
        try:
            DeviceLock("nidaq:Dev1", "me").acquire()
        except DeviceError as exc:
            print(exc)
    """, tmp_path)
    assert "offers no file locks" in out
