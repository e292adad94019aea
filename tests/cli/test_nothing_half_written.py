"""Issue 13: output files, interrupts and input mistakes never leave anything half-written.

Each numbered case of the issue has a test. A full disk is an ``OSError(ENOSPC)``
injected at the write (monkeypatch); read-only folders are real where the tests can
make them (chmod, when not root) and injected ``EROFS``/``EACCES`` otherwise (root
ignores chmod). Interrupts are real SIGINTs sent to a subprocess at seeded random times.
"""

from __future__ import annotations

import errno
import json
import os
import re
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from vibrofocus import _atomic
from vibrofocus.cli.main import app
from vibrofocus.errors import OutputError

runner = CliRunner()
#: An earlier "calibration": HDF5's signature, so replacing it needs no --force (same kind).
PREVIOUS_CALIBRATION = b"\x89HDF\r\n\x1a\nprevious calibration"
SRC = str(Path(__file__).resolve().parents[2] / "src")


def text(result) -> str:
    """The output with rich's line wrapping undone."""
    return " ".join(result.output.split())


def error_lines(result) -> list[str]:
    return [line for line in result.output.splitlines() if line.startswith("error:")]


def assert_one_error(result, *needles: str) -> None:
    """Exit 2, exactly one ``error:`` line containing every needle, no traceback."""
    assert result.exit_code == 2, result.output
    lines = error_lines(result)
    assert len(lines) == 1, result.output
    joined = text(result)
    for needle in needles:
        assert needle in joined, (needle, result.output)
    assert "Traceback" not in result.output


def no_temp_files(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if p.name.endswith((".tmp", ".probe")) or ".tmp" in p.name)


# ---------------------------------------------------------------------- fault injection
class Faults:
    """Make writes into chosen folders fail with a chosen errno."""

    def __init__(self, monkeypatch):
        self.monkeypatch = monkeypatch

    def disk_full_on_write(self, after_bytes: int = 0, only: str = ""):
        """Writes of temporary files fail with ENOSPC once ``after_bytes`` went through (a partial write).

        ``only``: fail only files whose temporary name contains this text.
        """
        budget = {"left": after_bytes}
        real = _atomic._open_fd

        class FullDisk:
            def __init__(self, fh):
                self._fh = fh

            def write(self, data):
                size = len(data)
                if budget["left"] < size:
                    part = data[: budget["left"]]
                    if len(part):
                        self._fh.write(part)  # what fits is written: a truncated file
                    budget["left"] = 0
                    raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
                budget["left"] -= size
                return self._fh.write(data)

            def __getattr__(self, name):
                return getattr(self._fh, name)

            def __enter__(self):
                return self

            def __exit__(self, *exc):
                return self._fh.__exit__(*exc)

        def open_fd(fd, *args, **kwargs):
            fh = real(fd, *args, **kwargs)
            if only and only not in os.readlink(f"/proc/self/fd/{fd}"):
                return fh
            return FullDisk(fh)

        self.monkeypatch.setattr(_atomic, "_open_fd", open_fd)

    def read_only(self, folder: Path, code: int = errno.EROFS):
        """Creating files in ``folder`` fails (mkstemp/mkdtemp), as on a read-only file system."""
        import tempfile

        real_mkstemp, real_mkdtemp = tempfile.mkstemp, tempfile.mkdtemp
        folder = Path(folder).resolve()

        def deny(dir):
            if dir is not None and Path(dir).resolve() == folder:
                raise OSError(code, os.strerror(code), str(dir))

        def mkstemp(*args, **kwargs):
            deny(kwargs.get("dir"))
            return real_mkstemp(*args, **kwargs)

        def mkdtemp(*args, **kwargs):
            deny(kwargs.get("dir"))
            return real_mkdtemp(*args, **kwargs)

        self.monkeypatch.setattr(tempfile, "mkstemp", mkstemp)
        self.monkeypatch.setattr(tempfile, "mkdtemp", mkdtemp)


@pytest.fixture
def faults(monkeypatch):
    return Faults(monkeypatch)


def chmod_protects() -> bool:
    """Whether chmod 0555 stops this process writing (not as root)."""
    return hasattr(os, "geteuid") and os.geteuid() != 0


# ---------------------------------------------------------------------- shared data
@pytest.fixture(scope="module")
def cal_file(tmp_path_factory):
    out = tmp_path_factory.mktemp("cal") / "P01.nc"
    result = runner.invoke(app, ["calibrate", "--participant", "P01", "--out", str(out), "--seed", "2",
                                 "--repeats", "4", "--sweep-s", "1", "--yes", "--no-figure"])
    assert result.exit_code == 0, result.output
    return out


# ---------------------------------------------------------------------- the helper itself
def test_atomic_write_keeps_the_old_file_on_a_full_disk(tmp_path, faults):
    target = tmp_path / "f.bin"
    target.write_bytes(b"old contents")
    faults.disk_full_on_write(after_bytes=3)
    with pytest.raises(OutputError, match="no space left") as info:
        _atomic.write_bytes(target, b"new contents, longer", what="test file")
    assert info.value.errno == errno.ENOSPC
    assert target.read_bytes() == b"old contents"
    assert no_temp_files(tmp_path) == []


def test_atomic_write_gives_new_files_the_usual_mode(tmp_path):
    old = os.umask(0o022)
    try:
        path = _atomic.write_text(tmp_path / "a.txt", "x")
    finally:
        os.umask(old)
    assert path.stat().st_mode & 0o777 == 0o644
    path.chmod(0o600)  # an existing file keeps its mode
    _atomic.write_text(path, "y")
    assert path.stat().st_mode & 0o777 == 0o600 and path.read_text() == "y"


def test_atomic_write_removes_the_temp_file_on_an_exception(tmp_path):
    target = tmp_path / "f.txt"
    target.write_text("old")
    with pytest.raises(RuntimeError):
        with _atomic.atomic_write(target, "w") as fh:
            fh.write("half")
            raise RuntimeError("boom")
    assert target.read_text() == "old" and no_temp_files(tmp_path) == []


def test_atomic_write_refuses_to_commit_after_a_swallowed_interrupt(tmp_path):
    target = tmp_path / "f.txt"
    target.write_text("old")
    restore = _atomic.install_signal_handlers()
    try:
        with pytest.raises(KeyboardInterrupt):
            with _atomic.atomic_write(target, "w") as fh:
                fh.write("new")
                try:
                    os.kill(os.getpid(), signal.SIGINT)
                    time.sleep(0.1)
                except KeyboardInterrupt:
                    pass  # a library swallowing Ctrl-C
    finally:
        restore()
        _atomic.clear_interrupt()
    assert target.read_text() == "old" and no_temp_files(tmp_path) == []


def test_check_writable_names_missing_room(tmp_path, monkeypatch):
    class Stat:
        f_bavail, f_frsize = 10, 4096

    monkeypatch.setattr(os, "statvfs", lambda path: Stat())
    with pytest.raises(OutputError, match=r"has 40\.0 KiB free.*before starting"):
        _atomic.check_writable(tmp_path / "x.nc", expected_bytes=10_000_000, what="calibration")


def test_atomic_directory_replaces_a_report_folder_as_a_whole(tmp_path):
    out = tmp_path / "report"
    owned = {"a.txt", "b.txt"}
    with _atomic.atomic_directory(out, owned=owned) as build:
        (build / "a.txt").write_text("1")
        (build / "b.txt").write_text("1")
    with pytest.raises(RuntimeError):
        with _atomic.atomic_directory(out, owned=owned) as build:
            (build / "a.txt").write_text("2")
            raise RuntimeError("figure failed")
    assert {p.name: p.read_text() for p in out.iterdir()} == {"a.txt": "1", "b.txt": "1"}
    with _atomic.atomic_directory(out, owned=owned) as build:
        (build / "a.txt").write_text("3")
    assert {p.name: p.read_text() for p in out.iterdir()} == {"a.txt": "3"}
    assert [p.name for p in tmp_path.iterdir()] == ["report"]


def test_atomic_directory_leaves_a_users_other_files_alone(tmp_path):
    (tmp_path / "trials.csv").write_text("mine")
    (tmp_path / "report.json").write_text("old")
    (tmp_path / "study2_counts.png").write_text("old figure")
    with _atomic.atomic_directory(tmp_path, owned={"report.json", "study2_counts.png"}) as build:
        (build / "report.json").write_text("new")
    assert (tmp_path / "trials.csv").read_text() == "mine"
    assert (tmp_path / "report.json").read_text() == "new"
    assert not (tmp_path / "study2_counts.png").exists()  # a stale figure of the old report


# ---------------------------------------------------------------------- case 1: calibration on a full disk
@pytest.mark.parametrize("command", ["calibrate", "demo"])
def test_1_full_disk_while_saving_a_calibration_keeps_the_measurement(tmp_path, faults, monkeypatch, command):
    monkeypatch.chdir(tmp_path)
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    fallback_dir = tmp_path / "elsewhere"
    fallback_dir.mkdir()
    from vibrofocus.cli import _save

    real_fallbacks = _save.fallback_paths
    monkeypatch.setattr(_save, "fallback_paths", lambda out: [fallback_dir / real_fallbacks(out)[0].name])
    # Only the first save (into out/) fails: the disk holding out/ is full.
    from vibrofocus import calibration as cal_io

    real_write_bytes = _atomic.write_bytes

    def write_bytes(path, data, *, what="file"):
        if Path(path).parent == out_dir:
            raise _atomic.output_error(OSError(errno.ENOSPC, "No space left on device"), path, what)
        return real_write_bytes(path, data, what=what)

    monkeypatch.setattr(_atomic, "write_bytes", write_bytes)
    if command == "calibrate":
        (out_dir / "P01.nc").write_bytes(PREVIOUS_CALIBRATION)
        args = ["calibrate", "-p", "P01", "-o", str(out_dir / "P01.nc"), "--repeats", "4", "--sweep-s", "1",
                "--yes", "--no-figure"]
    else:
        (out_dir / "calibration.nc").write_bytes(PREVIOUS_CALIBRATION)
        args = ["demo", "--out", str(out_dir), "--no-figures", "--json"]
    result = runner.invoke(app, args)
    assert_one_error(result, "no space left on the device", "saved to", str(fallback_dir))
    saved = list(fallback_dir.glob("*.nc"))
    assert len(saved) == 1
    cal = cal_io.load_calibration(saved[0])
    assert cal.H.shape[1:] == (cal.layout.n_points, cal.layout.n_actuators)
    name = "P01.nc" if command == "calibrate" else "calibration.nc"
    assert (out_dir / name).read_bytes() == PREVIOUS_CALIBRATION
    assert no_temp_files(out_dir) == []


def test_1_a_real_full_disk_gives_one_line_not_a_crash(tmp_path):
    """A real, tiny tmpfs where the system allows mounting one (root in a container); else skipped."""
    mnt = tmp_path / "tiny"
    mnt.mkdir()
    if subprocess.run(["mount", "-t", "tmpfs", "-o", "size=300k", "tmpfs", str(mnt)],
                      capture_output=True).returncode != 0:
        pytest.skip("cannot mount a tmpfs here (needs root and CAP_SYS_ADMIN); the injected ENOSPC tests cover it")
    try:
        (mnt / "P01.nc").write_bytes(PREVIOUS_CALIBRATION)
        env = {**os.environ, "PYTHONPATH": SRC}
        # The free-space check before measuring refuses at once ...
        run = subprocess.run([sys.executable, "-m", "vibrofocus", "calibrate", "-p", "P01", "-o", str(mnt / "P01.nc"),
                              "--repeats", "4", "--sweep-s", "1", "--yes"], capture_output=True, text=True,
                             env=env, cwd=tmp_path, timeout=300)
        assert run.returncode == 2, run.stderr
        assert "before starting" in run.stderr and "Traceback" not in run.stderr
        assert (mnt / "P01.nc").read_bytes() == PREVIOUS_CALIBRATION
        # ... and a save that meets a full disk anyway fails cleanly (no segfault), old file intact.
        code = textwrap.dedent(f"""
            import sys
            from vibrofocus.calibration import calibrate, save_calibration
            from vibrofocus.rigs import SimulatedForearm
            from vibrofocus.errors import OutputError
            cal = calibrate(SimulatedForearm(seed=1), participant_id="P01", repeats=4, sweep_s=1.0)
            try:
                save_calibration(cal, {str(mnt / 'P01.nc')!r})
            except OutputError as exc:
                print(exc); sys.exit(2)
        """)
        run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=300)
        assert run.returncode == 2, (run.returncode, run.stderr)
        assert "no space left on the device" in run.stdout
        assert (mnt / "P01.nc").read_bytes() == PREVIOUS_CALIBRATION
        assert sorted(p.name for p in mnt.iterdir()) == ["P01.nc"]
    finally:
        subprocess.run(["umount", str(mnt)], capture_output=True)


# ---------------------------------------------------------------------- case 2: render on a full disk
@pytest.mark.parametrize("suffix", [".npz", ".csv", ".wav"])
def test_2_full_disk_on_render_keeps_the_old_drives_file(cal_file, tmp_path, faults, suffix):
    out = tmp_path / ("d.npz" if suffix == ".wav" else f"d{suffix}")
    wav = tmp_path / "d.wav"
    target = wav if suffix == ".wav" else out
    args = ["render", "-c", str(cal_file), "-l", "5", "-o", str(out)] + (["--wav", str(wav)] if suffix == ".wav" else [])
    ok = runner.invoke(app, args)
    assert ok.exit_code == 0, ok.output
    before = target.read_bytes()
    faults.disk_full_on_write(after_bytes=100, only=".wav." if suffix == ".wav" else "")
    result = runner.invoke(app, args + ["--method", "funneling"])
    assert_one_error(result, "no space left on the device", str(target))
    assert target.read_bytes() == before
    assert no_temp_files(tmp_path) == []


# ---------------------------------------------------------------------- case 3: analyze on a full disk
@pytest.fixture
def trials_csv(tmp_path):
    from ..analysis.synthetic import make_trials

    df = make_trials(4, seed=3, repetitions=1, n_training=1)
    path = tmp_path / "trials.csv"
    df.to_csv(path, index=False)
    return path


def test_3_full_disk_on_analyze_keeps_the_old_report_whole(trials_csv, tmp_path, faults):
    out = tmp_path / "report"
    assert runner.invoke(app, ["analyze", str(trials_csv), "--out", str(out), "-q"]).exit_code == 0
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    faults.disk_full_on_write(after_bytes=20_000)  # a first figure fits, the rest does not
    result = runner.invoke(app, ["analyze", str(trials_csv), "--out", str(out), "-q", "--alpha", "0.01"])
    assert_one_error(result, "no space left on the device")
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["report", "trials.csv"]


def test_3_full_disk_on_a_first_analyze_leaves_no_folder(trials_csv, tmp_path, faults):
    out = tmp_path / "report"
    faults.disk_full_on_write(after_bytes=0)
    result = runner.invoke(app, ["analyze", str(trials_csv), "--out", str(out), "-q"])
    assert_one_error(result, "no space left on the device")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["trials.csv"]


# ---------------------------------------------------------------------- case 4: read-only output locations
@pytest.fixture
def read_only(faults):
    """Make a folder read-only: chmod where it stops this process, else injected EROFS."""
    made: list[Path] = []

    def make(folder: Path) -> Path:
        folder.mkdir(exist_ok=True)
        if chmod_protects():
            folder.chmod(0o555)
            made.append(folder)
        else:
            faults.read_only(folder, errno.EROFS)
        return folder

    yield make
    for folder in made:
        folder.chmod(0o755)


def test_4_calibrate_refuses_a_read_only_folder_before_measuring(tmp_path, read_only, monkeypatch):
    folder = read_only(tmp_path / "ro")
    import vibrofocus.calibration as calibration_pkg

    def never(*args, **kwargs):
        raise AssertionError("the measurement started although the output cannot be written")

    monkeypatch.setattr(calibration_pkg, "calibrate", never)
    result = runner.invoke(app, ["calibrate", "-p", "P01", "-o", str(folder / "P01.nc"), "--yes"])
    assert_one_error(result, str(folder / "P01.nc"), "before starting")


def test_4_demo_refuses_a_read_only_folder_before_calibrating(tmp_path, read_only):
    folder = read_only(tmp_path / "ro")
    result = runner.invoke(app, ["demo", "--out", str(folder)])
    assert_one_error(result, "calibration", "before starting")


@pytest.mark.parametrize("where", ["out", "wav"])
def test_4_render_into_a_read_only_folder(cal_file, tmp_path, read_only, where):
    folder = read_only(tmp_path / "ro")
    out = folder / "d.npz" if where == "out" else tmp_path / "d.npz"
    args = ["render", "-c", str(cal_file), "-l", "5", "-o", str(out)]
    if where == "wav":
        args += ["--wav", str(folder / "d.wav")]
    result = runner.invoke(app, args)
    assert_one_error(result, "read-only" if not chmod_protects() else "permission denied")
    assert not out.exists()  # checked before anything is written


def test_4_analyze_into_a_read_only_folder(trials_csv, tmp_path, read_only):
    out = tmp_path / "report"
    assert runner.invoke(app, ["analyze", str(trials_csv), "--out", str(out), "-q"]).exit_code == 0
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    read_only(tmp_path)  # the report folder's parent: the new report cannot be built beside it
    result = runner.invoke(app, ["analyze", str(trials_csv), "--out", str(out), "-q"])
    assert_one_error(result, "report folder")
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before


def _study_db(tmp_path: Path) -> Path:
    from vibrofocus.studies import StudyStore

    db = tmp_path / "s.db"
    with StudyStore(db) as store:
        store.add_participant("P1")
        sid = store.create_session("P1", 1, seed=1)
        trial = store.next_trial(sid)
        store.record_answer(sid, trial.trial_index, (trial.target,), 0.5, answer_id="a1")
    return db


def test_4_study_export_into_a_read_only_folder(tmp_path, read_only):
    db = _study_db(tmp_path)
    folder = read_only(tmp_path / "ro")
    result = runner.invoke(app, ["study", "export", "--db", str(db), "--out", str(folder / "t.csv")])
    assert_one_error(result, str(folder / "t.csv"))


# ---------------------------------------------------------------------- case 5: a study database in a read-only folder
def test_5_export_from_a_read_only_folder_reads_a_private_copy(tmp_path, monkeypatch):
    from vibrofocus.studies import database

    db = _study_db(tmp_path)
    monkeypatch.setattr(database, "_folder_writable", lambda folder: Path(folder) != tmp_path)
    out_dir = tmp_path.parent / (tmp_path.name + "-out")
    out_dir.mkdir()
    result = runner.invoke(app, ["study", "export", "--db", str(db), "--out", str(out_dir / "t.csv")])
    assert result.exit_code == 0, result.output
    lines = (out_dir / "t.csv").read_text().splitlines()
    assert len(lines) == 2 and lines[1].startswith("P1,1,training,1,")


def test_5_running_a_study_in_a_read_only_folder_says_so(tmp_path, monkeypatch):
    from vibrofocus.errors import StudyError
    from vibrofocus.studies import StudyStore, database

    db = _study_db(tmp_path)
    monkeypatch.setattr(database, "_folder_writable", lambda folder: False)
    with pytest.raises(StudyError, match="read-only") as info:
        StudyStore(db)
    assert "not a vibrofocus study database" not in str(info.value)


def test_5_a_real_read_only_mount(tmp_path):
    """A study database on a read-only mount (root with CAP_SYS_ADMIN); else skipped."""
    mnt = tmp_path / "mnt"
    mnt.mkdir()
    if subprocess.run(["mount", "-t", "tmpfs", "-o", "size=4m", "tmpfs", str(mnt)], capture_output=True).returncode:
        pytest.skip("cannot mount here (needs root and CAP_SYS_ADMIN); the injected tests cover the logic")
    try:
        db = _study_db(mnt)
        subprocess.run(["mount", "-o", "remount,ro", str(mnt)], check=True)
        result = runner.invoke(app, ["study", "export", "--db", str(db), "--out", str(tmp_path / "t.csv")])
        assert result.exit_code == 0, result.output
        assert len((tmp_path / "t.csv").read_text().splitlines()) == 2
        from vibrofocus.errors import StudyError
        from vibrofocus.studies import StudyStore

        with pytest.raises(StudyError, match="read-only"):
            StudyStore(db)
        result = runner.invoke(app, ["study", "export", "--db", str(db), "--out", str(mnt / "t.csv")])
        assert_one_error(result, "read-only")
    finally:
        subprocess.run(["umount", str(mnt)], capture_output=True)


# ---------------------------------------------------------------------- case 6: a typo in the method column
@pytest.mark.parametrize("typo, hint", [("bogus", "no participant has it for every target"),
                                        ("Inverse", "write 'inverse'"), ("invrse", "did you mean 'inverse'")])
def test_6_a_typo_in_method_is_named_not_analysed(tmp_path, typo, hint):
    from ..analysis.synthetic import make_trials

    df = make_trials(4, seed=5, repetitions=1, n_training=1)
    row = df.index[(df["participant"] == "P02") & (df["phase"] == "main") & (df["study"] == 1)][3]
    df.loc[row, "method"] = typo
    path = tmp_path / "trials.csv"
    df.to_csv(path, index=False)
    line = int(row) + 2
    result = runner.invoke(app, ["analyze", str(path), "--out", str(tmp_path / "r")])
    assert_one_error(result, f"line {line}", repr(typo), hint)
    assert not (tmp_path / "r").exists()
    # Excluding invalid rows drops only the participant with the typo; the others stay complete.
    result = runner.invoke(app, ["analyze", str(path), "--out", str(tmp_path / "r"), "--exclude-invalid"])
    assert result.exit_code == 0, result.output
    report = json.loads((tmp_path / "r" / "report.json").read_text())
    assert report["study1"]["participants"] == ["P01", "P03", "P04"]
    assert report["study1"]["methods"] == ["funneling", "inverse", "combination"]


# ---------------------------------------------------------------------- case 7: Ctrl-C during a save
SAVER = textwrap.dedent("""
    import sys, time
    import numpy as np
    from vibrofocus.cli._errors import user_errors
    from vibrofocus import _atomic
    import typer

    path, n = sys.argv[1], int(sys.argv[2])
    payload = np.full(n, float(sys.argv[3]))

    def main():
        with user_errors():
            print("ready", flush=True)
            for _ in range(40):
                with _atomic.atomic_write(path, "wb", what="test file") as fh:
                    for chunk in np.array_split(payload, 64):
                        fh.write(chunk.tobytes())
                        time.sleep(0.0005)

    try:
        main()
    except typer.Exit as exc:
        sys.exit(exc.exit_code)
""")


@pytest.mark.parametrize("seed", range(4))
def test_7_sigint_at_a_random_point_of_a_save(tmp_path, seed):
    rng = np.random.default_rng(1300 + seed)
    path = tmp_path / "data.bin"
    n = 200_000
    np.full(n, 1.0).tofile(path)
    old = path.read_bytes()
    new = np.full(n, 2.0).tobytes()
    env = {**os.environ, "PYTHONPATH": SRC}
    proc = subprocess.Popen([sys.executable, "-c", SAVER, str(path), str(n), "2.0"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=env)
    assert proc.stdout.readline().strip() == "ready"
    time.sleep(float(rng.uniform(0.0, 0.4)))
    proc.send_signal(signal.SIGINT if seed % 2 == 0 else signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert "Traceback" not in err
    assert [line for line in err.splitlines() if line.strip()] == [
        "interrupted: stopped; no file was left half-written"
    ]
    assert path.read_bytes() in (old, new)  # never a mix
    assert sorted(p.name for p in tmp_path.iterdir()) == ["data.bin"]


# ---------------------------------------------------------------------- case 8: smaller items
def test_8_non_integer_location_is_one_line(cal_file, tmp_path):
    result = runner.invoke(app, ["render", "-c", str(cal_file), "-l", "five", "-o", str(tmp_path / "d.npz")])
    assert_one_error(result, "--location", "see 'vibrofocus render --help'")
    assert "╭" not in result.output


def test_8_calibrate_seed_comes_from_the_participant(tmp_path):
    from vibrofocus.calibration import load_calibration
    from vibrofocus.defaults import participant_seed

    seeds = {}
    for pid in ("P01", "P02"):
        out = tmp_path / f"{pid}.nc"
        result = runner.invoke(app, ["calibrate", "-p", pid, "-o", str(out), "--repeats", "4", "--sweep-s", "1",
                                     "--yes", "--no-figure"])
        assert result.exit_code == 0, result.output
        seeds[pid] = load_calibration(out).rig["seed"]
    assert seeds == {"P01": participant_seed("P01"), "P02": participant_seed("P02")}
    assert seeds["P01"] != seeds["P02"]
    shown = runner.invoke(app, ["calibrate", "--help"], env={"COLUMNS": "400"})
    assert "default: (derived from --participant)" in text(shown)


def test_8_calibration_files_get_the_usual_mode(cal_file):
    assert cal_file.stat().st_mode & 0o777 == 0o666 & ~_atomic._umask()


def test_8_debug_shows_the_traceback(tmp_path):
    args = ["render", "-c", str(tmp_path / "none.nc"), "-l", "5", "-o", str(tmp_path / "d.npz")]
    plain = runner.invoke(app, args)
    assert_one_error(plain, "no such calibration file")
    debug = runner.invoke(app, ["--debug", *args])
    assert debug.exit_code == 2 and "Traceback" in debug.output


def test_8_no_help_text_cites_a_spec_file_users_do_not_have():
    import vibrofocus

    root = Path(vibrofocus.__file__).parent
    offenders = [f"{p.relative_to(root)}:{i}" for p in root.rglob("*.py")
                 for i, line in enumerate(p.read_text(encoding="utf-8").splitlines(), 1) if re.search(r"SPEC\s§", line)]
    assert offenders == []
    for command in (["analyze"], ["study", "export"], ["render"], ["calibrate"], ["demo"], ["simulate-study"]):
        shown = runner.invoke(app, [*command, "--help"], env={"COLUMNS": "300"})
        assert shown.exit_code == 0 and "SPEC" not in shown.output, command
    assert "docs/file-formats.md" in runner.invoke(app, ["analyze", "--help"], env={"COLUMNS": "300"}).output
    docs = Path(SRC).parent / "docs"
    for page in ("file-formats.md", "method.md"):
        assert (docs / page).is_file()


def test_8_render_from_a_calibration_refuses_a_band_outside_it(cal_file):
    from vibrofocus.calibration import load_calibration
    from vibrofocus.errors import ValidationError
    from vibrofocus.rendering import render

    cal = load_calibration(cal_file)
    inside = render("inverse", cal, cal.fs, cal.layout, 5, band=cal.band)
    assert inside.drives.shape == (cal.layout.n_actuators, 4096)
    with pytest.raises(ValidationError, match="calibrated_band|calibrat"):
        render("inverse", cal, cal.fs, cal.layout, 5, band=(cal.band[0], cal.band[1] * 2))


def test_8_vf_rigs_is_reachable_without_importing_it():
    code = "import vibrofocus as vf; print(type(vf.rigs.make_rig('simulated', seed=1)).__name__)"
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         env={**os.environ, "PYTHONPATH": SRC}, timeout=120)
    assert run.returncode == 0 and run.stdout.strip() == "SimulatedForearm", run.stderr


def test_8_safety_errors_number_channels_from_one():
    from vibrofocus.errors import SafetyError
    from vibrofocus.rigs.safety import SafetyLimits, check_drive

    drive = np.zeros((4, 100))
    drive[0, 50] = 11.0  # the first channel, A1
    with pytest.raises(SafetyError, match="channel 1 reaches 11 V"):
        check_drive(drive, 10_000.0, 4, SafetyLimits(peak_v=10.0))


def test_8_shapiro_does_not_count_tied_conditions_as_rejections():
    import pandas as pd

    from vibrofocus.analysis.study1 import shapiro_tests

    # Three participants, two of whom localised perfectly: [0, 0, x] in every condition.
    rows = [{"participant": f"P{i}", "location": loc, "method": m, "error_mm": 0.0 if i < 2 else 4.0 + loc}
            for i in range(3) for loc in (1, 2) for m in ("funneling", "inverse")]
    res = shapiro_tests(pd.DataFrame(rows))
    assert res["p"].isna().all() and res["note"].str.contains("ties").all()


def test_a_save_in_another_thread_does_not_hold_back_ctrl_c_in_the_main_thread():
    # Signals are handled in the main thread: a commit running in a worker thread (a web
    # request saving a file) must not defer, and so lose, the main thread's Ctrl-C.
    import threading

    inside, release = threading.Event(), threading.Event()

    def save_in_a_thread():
        with _atomic.critical_section():
            inside.set()
            release.wait(10)

    worker = threading.Thread(target=save_in_a_thread)
    restore = _atomic.install_signal_handlers()
    try:
        worker.start()
        assert inside.wait(10)
        with pytest.raises(KeyboardInterrupt):
            signal.pthread_kill(threading.main_thread().ident, signal.SIGINT)  # Ctrl-C
            time.sleep(2.0)  # the interrupt arrives during this wait
    finally:
        release.set()
        worker.join(10)
        restore()
        _atomic.clear_interrupt()
