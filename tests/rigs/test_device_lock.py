"""The device lock: one job per device across processes and users, every spelling of one
audio interface one lock, and a lock folder that nobody can turn against a job.

A second process is a real one (a child Python taking the lock); the hostile folder is
made by the test in its own tmp_path and named by ``VIBROFOCUS_LOCK_DIR``.
"""

from __future__ import annotations

import os
import re
import stat
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from vibrofocus.rigs import DeviceBusyError, DeviceError, DeviceLock
from vibrofocus.rigs.audio import audio_lock_keys, same_audio_interface
from vibrofocus.rigs.device_lock import LockKey, lock_dir

posix_only = pytest.mark.skipif(os.name == "nt", reason="POSIX modes, owners and links")
SRC = str(Path(__file__).resolve().parents[2] / "src")


@pytest.fixture
def locks(tmp_path, monkeypatch):
    folder = tmp_path / "locks"
    monkeypatch.setenv("VIBROFOCUS_LOCK_DIR", str(folder))
    return folder


def _holder(folder: Path, keys: str, *, extra: str = "") -> subprocess.Popen:
    """A child process that takes a lock on ``keys`` (a Python list of LockKey) and waits on stdin."""
    code = textwrap.dedent(f"""
        import sys
        {extra}
        from vibrofocus.rigs.device_lock import DeviceLock, LockKey
        lock = DeviceLock("held", "the child job", keys={keys}).acquire()
        print("held", flush=True)
        sys.stdin.readline()
    """)
    env = dict(os.environ, VIBROFOCUS_LOCK_DIR=str(folder), PYTHONPATH=SRC)
    proc = subprocess.Popen([sys.executable, "-c", code], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=env)
    line = proc.stdout.readline()
    if line.strip() != "held":
        proc.kill()
        raise AssertionError(f"the child did not take the lock: {line!r} {proc.stderr.read()!r}")
    return proc


def _end(proc: subprocess.Popen) -> None:
    proc.stdin.close()
    proc.wait(60)


# -- one lock per device, whatever its spelling ---------------------------------------------
SPELLINGS = [
    ("MOTU Pro Audio", "Out 1-2 (MOTU Pro Audio)"),
    ("Out 1-2 (MOTU Pro Audio)", "Out 1-2 (MOTU Pro Aud"),  # MME cuts names at 31 characters
    ("Speakers (Focusrite USB Audio)", "Focusrite USB ASIO"),
    ("Scarlett 2i2 USB: Audio (hw:1,0)", "Focusrite Scarlett 2i2"),
    ("system", "MOTU Pro Audio"),  # JACK's system ports route to the mix: the same as anything
    ("default", "pulse"),
]
DISTINCT = [
    ("MOTU Pro Audio", "Focusrite USB ASIO"),
    ("Out 1-2 (MOTU Pro Audio)", "Out 1-2 (Focusrite USB Audio)"),  # channel numbers name no interface
]


@pytest.mark.parametrize("a, b", SPELLINGS)
def test_two_spellings_of_one_interface_are_one_lock(locks, a, b):
    assert same_audio_interface(a, b)  # the cue check's rule, which the lock follows
    with DeviceLock(f"audio:{a}", "first", keys=audio_lock_keys(a)):
        with pytest.raises(DeviceBusyError, match=re.escape(f"audio:{b} is in use by first")):
            DeviceLock(f"audio:{b}", "second", keys=audio_lock_keys(b)).acquire()
    DeviceLock(f"audio:{b}", "second", keys=audio_lock_keys(b)).acquire().release()  # free once the first goes


@pytest.mark.parametrize("a, b", DISTINCT)
def test_two_interfaces_are_two_locks(locks, a, b):
    assert not same_audio_interface(a, b)
    with DeviceLock(a, "first", keys=audio_lock_keys(a)), DeviceLock(b, "second", keys=audio_lock_keys(b)):
        pass


def test_a_refused_lock_keeps_none_of_its_files(locks):
    with DeviceLock("audio:motu", "first", keys=audio_lock_keys("MOTU Pro Audio")):
        late = DeviceLock("audio:mix", "second", keys=audio_lock_keys("default"))
        with pytest.raises(DeviceBusyError):
            late.acquire()
        assert not late.held
        # Its shared hold on "audio-any" was given back too: a routing name is refused by the
        # holder of the MOTU, not by a leftover of the refused lock.
    with DeviceLock("audio:mix", "second", keys=audio_lock_keys("default")):
        pass


def test_another_process_holding_the_device_is_named(locks):
    child = _holder(locks, '[LockKey("nidaq:Dev1")]')
    try:
        with pytest.raises(DeviceBusyError, match=r"nidaq:Dev1 is in use by the child job \(process \d+"):
            DeviceLock("nidaq:Dev1", "me").acquire()
    finally:
        _end(child)
    DeviceLock("nidaq:Dev1", "me").acquire().release()


# -- one folder for the machine, safe against another local user ----------------------------
def test_the_default_folder_is_one_for_the_machine_not_one_per_user(monkeypatch, tmp_path):
    import vibrofocus.rigs.device_lock as dl

    assert dl.POSIX_LOCK_DIR == Path("/tmp/vibrofocus-locks")  # no uid, not $TMPDIR (per user on macOS)
    machine = tmp_path / "machine-wide"
    monkeypatch.setattr(dl, "POSIX_LOCK_DIR", machine)
    monkeypatch.delenv("VIBROFOCUS_LOCK_DIR", raising=False)
    monkeypatch.setenv("TMPDIR", str(tmp_path / "per-user"))
    monkeypatch.setenv("PROGRAMDATA", str(machine.parent))
    folder = lock_dir()
    assert folder == (machine if os.name != "nt" else machine.parent / "vibrofocus" / "locks")
    assert not (tmp_path / "per-user").exists()


@posix_only
def test_a_new_folder_is_sticky_and_open_to_every_user_and_its_files_too(locks):
    old = os.umask(0o077)
    try:
        DeviceLock("nidaq:Dev1", "me").acquire().release()
    finally:
        os.umask(old)
    assert stat.S_IMODE(locks.stat().st_mode) == 0o1777
    assert stat.S_IMODE((locks / "nidaq_Dev1.lock").stat().st_mode) == 0o666


@posix_only
def test_a_folder_others_may_write_without_the_sticky_bit_is_refused(locks):
    locks.mkdir()
    os.chmod(locks, 0o777)
    with pytest.raises(DeviceError, match="without the sticky bit"):
        DeviceLock("nidaq:Dev1", "me")
    assert list(locks.iterdir()) == []


@posix_only
def test_a_folder_that_is_a_link_is_refused(locks, tmp_path):
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    locks.symlink_to(elsewhere)
    with pytest.raises(DeviceError, match="is a symbolic link"):
        DeviceLock("nidaq:Dev1", "me")
    assert list(elsewhere.iterdir()) == []


@posix_only
def test_a_lock_file_that_is_a_link_is_refused_and_its_target_untouched(locks, tmp_path):
    lock_dir()
    victim = tmp_path / "victim.txt"
    victim.write_bytes(bytes(range(256)) * 4 + b"x" * 26)  # 1050 bytes, as in the issue
    before = victim.read_bytes()
    (locks / LockKey("nidaq:Dev1").path(locks).name).symlink_to(victim)
    with pytest.raises(DeviceError, match="is a symbolic link"):
        DeviceLock("nidaq:Dev1", "me").acquire()
    assert victim.read_bytes() == before
    # A link to nothing, which O_CREAT would otherwise make at its target, is refused too.
    dangling = tmp_path / "made-through-the-link"
    (locks / LockKey("nidaq:Dev2").path(locks).name).symlink_to(dangling)
    with pytest.raises(DeviceError, match="is a symbolic link"):
        DeviceLock("nidaq:Dev2", "me").acquire()
    assert not dangling.exists()


@posix_only
def test_a_lock_file_with_a_second_name_is_refused_and_untouched(locks, tmp_path):
    lock_dir()
    victim = tmp_path / "victim.txt"
    victim.write_bytes(b"keep me" * 150)
    os.link(victim, locks / LockKey("nidaq:Dev1").path(locks).name)
    with pytest.raises(DeviceError, match="not a plain file with one name"):
        DeviceLock("nidaq:Dev1", "me").acquire()
    assert victim.read_bytes() == b"keep me" * 150


@posix_only
def test_what_a_lock_file_says_is_shown_printable_and_short(locks):
    lock_dir()
    path = LockKey("nidaq:Dev1").path(locks)
    import fcntl
    import json

    with open(path, "w") as fh:
        json.dump({"owner": "\x1b[2Jevil" + "x" * 500, "pid": 1}, fh)
        fh.flush()
        fcntl.flock(fh, fcntl.LOCK_EX)
        with pytest.raises(DeviceBusyError) as info:
            DeviceLock("nidaq:Dev1", "me").acquire()
    assert "\x1b" not in str(info.value) and len(str(info.value)) < 400
