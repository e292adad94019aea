"""Issue 31: every command against bad input -- nothing overwritten, no traceback, no nonsense.

Each case runs a real command on real files (a calibration measured on the simulated
rig, a study database filled by ``simulate-study``) in a fresh folder, and asserts the
exit code, exactly one ``error:`` line (no traceback) and that every file that existed
before is unchanged, byte for byte, including symbolic links and device nodes. Cases
that must prove nothing big was allocated run in a child process under an address-space
limit.
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import shutil
import stat
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from vibrofocus.cli.main import app

runner = CliRunner()
SRC = str(Path(__file__).resolve().parents[2] / "src")
FS = 10_000.0


# ---------------------------------------------------------------------- helpers
def snapshot(*folders: Path) -> dict[str, tuple]:
    """Every entry under the folders: its type and its bytes' SHA-256 (files) or target (links)."""
    out: dict[str, tuple] = {}
    for folder in folders:
        for root, dirs, files in os.walk(folder, followlinks=False):
            for name in dirs + files:
                p = Path(root, name)
                st_ = p.lstat()
                if stat.S_ISLNK(st_.st_mode):
                    out[str(p)] = ("link", os.readlink(p))
                elif stat.S_ISREG(st_.st_mode):
                    out[str(p)] = ("file", hashlib.sha256(p.read_bytes()).hexdigest(), stat.S_IMODE(st_.st_mode))
                else:
                    out[str(p)] = (stat.S_IFMT(st_.st_mode), st_.st_ino)
    return out


def changed(before: dict, after: dict) -> list[str]:
    """Entries that existed before and differ now (new entries are the command's output)."""
    return sorted(k for k in before if after.get(k) != before[k])


def error_lines(output: str) -> list[str]:
    return [line for line in output.splitlines() if line.startswith("error:")]


def flat(output: str) -> str:
    return " ".join(output.split())


def assert_refused(result_output: str, code: int, *needles: str, expected_code: int = 2) -> None:
    """The exit code, exactly one ``error:`` line holding every needle, and no traceback."""
    assert code == expected_code, result_output
    lines = error_lines(result_output)
    assert len(lines) == 1, result_output
    text = flat(result_output)
    for needle in needles:
        assert needle in text, (needle, result_output)
    assert "Traceback" not in result_output and "Exception ignored" not in result_output, result_output


def invoke(args: list[str], **kwargs):
    result = runner.invoke(app, [str(a) for a in args], **kwargs)
    return result.output, result.exit_code


def child(args: list[str], *, memory_headroom_mb: int | None = None, stdin: str | None = None, timeout: float = 120):
    """Run the CLI in a child process; optionally cap its address space at what it uses plus a headroom."""
    cap = ""
    if memory_headroom_mb is not None:
        # The limit is set after the imports, so it bounds what the command allocates.
        cap = (
            "import resource\n"
            "vm = int([l for l in open('/proc/self/status') if l.startswith('VmSize:')][0].split()[1]) * 1024\n"
            f"resource.setrlimit(resource.RLIMIT_AS, (vm + {memory_headroom_mb} * 2**20, resource.RLIM_INFINITY))\n"
        )
    code = (
        "import sys\nfrom vibrofocus.cli.main import app\nimport numpy, scipy.signal, zipfile\n" + cap
        + "sys.argv = ['vibrofocus'] + sys.argv[1:]\napp(prog_name='vibrofocus')\n"
    )
    run = subprocess.run([sys.executable, "-c", code, *map(str, args)], capture_output=True, text=True,
                         input=stdin, timeout=timeout, env={**os.environ, "PYTHONPATH": SRC, "COLUMNS": "200"})
    return run.stdout + run.stderr, run.returncode


# ---------------------------------------------------------------------- real inputs, made once
@pytest.fixture(scope="module")
def seed_files(tmp_path_factory) -> dict[str, Path]:
    """A calibration, a filled study database and a drives file, made by the commands themselves."""
    folder = tmp_path_factory.mktemp("seed")
    cal = folder / "P01.nc"
    out, code = invoke(["calibrate", "-p", "P01", "-o", cal, "--seed", "2", "--repeats", "4", "--sweep-s", "1",
                        "--yes", "--no-figure"])
    assert code == 0, out
    db = folder / "study.db"
    out, code = invoke(["simulate-study", "-n", "1", "--db", db, "-q", "--seed", "4"])
    assert code == 0, out
    drives = folder / "drives.npz"
    out, code = invoke(["render", "-c", cal, "-l", "5", "-o", drives])
    assert code == 0, out
    return {"folder": folder, "cal": cal, "db": db, "drives": drives}


@pytest.fixture
def ws(seed_files, tmp_path) -> dict[str, Path]:
    """A private copy of the seed files in ``tmp_path`` (the database keeps listing the seed calibrations)."""
    paths = {"folder": tmp_path}
    for key in ("cal", "db", "drives"):
        paths[key] = tmp_path / seed_files[key].name
        shutil.copy2(seed_files[key], paths[key])
    paths["seed"] = seed_files["folder"]
    return paths


def run_checked(ws, args, *needles, expected_code: int = 2, **kwargs) -> str:
    """Run a command that must be refused; every file that existed (here and in the seed) stays as it was."""
    before = snapshot(ws["folder"], ws["seed"])
    out, code = invoke(args, **kwargs)
    assert_refused(out, code, *needles, expected_code=expected_code)
    assert changed(before, snapshot(ws["folder"], ws["seed"])) == []
    return out


# ---------------------------------------------------------------------- data loss (cases 1-4)
def test_1_simulate_study_trials_csv_onto_its_own_database(ws):
    db = ws["db"]
    run_checked(ws, ["simulate-study", "-q", "-n", "1", "--seed", "4", "--db", db, "--trials-csv", db],
                "study database", "same file")


def test_2_study_export_onto_its_own_database_even_by_a_hard_link_or_with_force(ws):
    db = ws["db"]
    run_checked(ws, ["study", "export", "--db", db, "--out", db], "study database", "same file")
    other_name = ws["folder"] / "another-name.csv"
    os.link(db, other_name)
    run_checked(ws, ["study", "export", "--db", db, "--out", other_name, "--force"], "same file")


def test_2_study_export_onto_a_calibration_the_database_lists(ws):
    listed = next((ws["seed"] / "study-files" / "calibrations").glob("*.nc"))
    link = ws["folder"] / "trials.csv"
    link.symlink_to(listed)
    run_checked(ws, ["study", "export", "--db", ws["db"], "--out", link, "--force"], "calibration", "same file")


@pytest.mark.parametrize("victim", ["cal", "drives", "db"])
def test_3_trials_file_over_a_file_of_another_kind_needs_force(ws, victim):
    target = ws[victim]
    if victim == "db":  # another study database than the one exported
        target = ws["folder"] / "other.db"
        shutil.copy2(ws["db"], target)
    run_checked(ws, ["study", "export", "--db", ws["seed"] / "study.db", "--out", target], "--force")
    out, code = invoke(["study", "export", "--db", ws["seed"] / "study.db", "--out", target, "--force"])
    assert code == 0, out
    assert target.read_text(encoding="utf-8").startswith("participant,study,phase")


def test_3_simulate_study_trials_csv_over_a_calibration(ws):
    run_checked(ws, ["simulate-study", "-q", "-n", "1", "--seed", "4", "--db", ws["db"], "--trials-csv", ws["cal"]],
                "HDF5", "--force")


def _writers(ws, target: Path) -> dict[str, list]:
    """Every command that writes a file, aimed at ``target``."""
    return {
        "study export": ["study", "export", "--db", ws["db"], "--out", target],
        "render -o": ["render", "-c", ws["cal"], "-l", "5", "-o", target],
        "render --wav": ["render", "-c", ws["cal"], "-l", "5", "-o", ws["folder"] / "new.npz", "--wav", target],
        "simulate-study --trials-csv": ["simulate-study", "-q", "-n", "1", "--seed", "4", "--db", ws["db"],
                                        "--trials-csv", target],
        "calibrate -o": ["calibrate", "-p", "P01", "-o", target, "--yes", "--no-figure"],
    }


SUFFIX = {"study export": ".csv", "render -o": ".npz", "render --wav": ".wav", "simulate-study --trials-csv": ".csv",
          "calibrate -o": ".nc"}
WRITERS = list(SUFFIX)


def _special(ws, kind: str, suffix: str) -> tuple[Path, str]:
    """A non-regular output target of ``kind``, named with ``suffix``; and a word its message holds."""
    folder = ws["folder"]
    if kind == "fifo":
        path = folder / f"pipe{suffix}"
        os.mkfifo(path)
        return path, "FIFO"
    if kind == "folder":
        path = folder / f"dir{suffix}"
        path.mkdir()
        return path, "folder"
    if kind == "device":
        if os.geteuid() != 0:
            pytest.skip("making a device node needs root")
        path = folder / f"full{suffix}"
        os.mknod(path, 0o644 | stat.S_IFCHR, os.makedev(1, 7))  # a private /dev/full
        return path, "character device"
    if kind == "link to fifo":
        fifo = folder / "real-pipe"
        os.mkfifo(fifo)
        path = folder / f"link{suffix}"
        path.symlink_to(fifo)
        return path, "FIFO"
    if kind == "dangling link":
        path = folder / f"dangling{suffix}"
        path.symlink_to(folder / "missing" / "nothing")
        return path, "missing"
    raise AssertionError(kind)


@pytest.mark.parametrize("kind", ["fifo", "folder", "device", "link to fifo", "dangling link"])
@pytest.mark.parametrize("writer", WRITERS)
def test_4_no_writer_replaces_a_non_regular_target(ws, writer, kind):
    target, word = _special(ws, kind, SUFFIX[writer])
    run_checked(ws, _writers(ws, target)[writer], str(target.name), word)
    assert target.is_symlink() == (kind in ("link to fifo", "dangling link"))


@pytest.mark.parametrize("writer", ["study export", "render -o", "render --wav"])
def test_4_a_symlink_to_a_regular_file_is_written_through_and_stays_a_link(ws, writer):
    real = ws["folder"] / f"real{SUFFIX[writer]}"
    out, code = invoke(_writers(ws, real)[writer])  # a first file of the right kind
    assert code == 0, out
    link = ws["folder"] / f"link{SUFFIX[writer]}"
    link.symlink_to(real.name)
    before = real.stat().st_ino
    out, code = invoke(_writers(ws, link)[writer] + ["--method", "funneling"] * writer.startswith("render"))
    assert code == 0, out
    assert link.is_symlink() and os.readlink(link) == real.name
    assert real.stat().st_ino != before  # the file behind the link was replaced atomically


# ---------------------------------------------------------------------- tracebacks (cases 5-8)
@pytest.mark.parametrize("args, needle", [
    (["--n-samples", "100000000"], "--n-samples"),
    (["--n-samples", str(2**21 + 1)], "--n-samples"),
    (["--n-samples", "3"], "--n-samples"),
    (["--limit-v", "1e-300"], "--limit-v"),
    (["--limit-v", "nan"], "--limit-v"),
])
def test_5_render_options_out_of_range(ws, args, needle):
    run_checked(ws, ["render", "-c", ws["cal"], "-l", "5", "-o", ws["folder"] / "d.npz", *args], needle)
    assert not (ws["folder"] / "d.npz").exists()


def _npz(path: Path, members: dict[str, bytes], compression=zipfile.ZIP_STORED) -> Path:
    with zipfile.ZipFile(path, "w", compression=compression) as z:
        for name, data in members.items():
            z.writestr(name, data)
    return path


def _npy(arr) -> bytes:
    b = io.BytesIO()
    np.save(b, arr)
    return b.getvalue()


def _lying_npy(shape: tuple[int, ...], n_data_bytes: int) -> bytes:
    b = io.BytesIO()
    np.lib.format.write_array_header_1_0(b, {"descr": "<f8", "fortran_order": False, "shape": shape})
    return b.getvalue() + bytes(n_data_bytes)


def test_6_a_lying_npy_header_is_refused_without_allocating(ws):
    lying = _npz(ws["folder"] / "lying.npz", {"drives.npy": _lying_npy((4, 10**11), 131_072),
                                              "fs.npy": _npy(np.float64(FS))})
    before = snapshot(ws["folder"])
    # 3.2 TB claimed; the child may allocate 256 MiB beyond what its imports took.
    out, code = child(["play", lying, "--dry-run"], memory_headroom_mb=256)
    assert_refused(out, code, "claims shape (4, 100000000000)", "131,072 bytes")
    assert changed(before, snapshot(ws["folder"])) == []


def test_11_a_long_compressed_drive_is_refused_from_its_header(ws):
    n = 25_000_000  # 2500 s at 10 kHz: 800 MB of float64, compressed to under 1 MB
    path = ws["folder"] / "long.npz"
    with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_DEFLATED, compresslevel=1) as z:
        with z.open("drives.npy", "w", force_zip64=True) as fh:
            head = io.BytesIO()
            np.lib.format.write_array_header_1_0(head, {"descr": "<f8", "fortran_order": False, "shape": (4, n)})
            fh.write(head.getvalue())
            chunk, left = bytes(1 << 24), 4 * n * 8
            while left:
                fh.write(chunk[: min(left, len(chunk))])
                left -= min(left, len(chunk))
        z.writestr("fs.npy", _npy(np.float64(FS)))
    out, code = child(["play", path, "--dry-run"], memory_headroom_mb=256)
    assert_refused(out, code, "2500 s", "limit of 30 s")


def test_7_analyze_an_export_without_participant_or_study(ws):
    export = ws["folder"] / "export.csv"
    out, code = invoke(["study", "export", "--db", ws["db"], "--out", export])
    assert code == 0, out
    rows = [line.split(",") for line in export.read_text().splitlines()]
    keep = [i for i, name in enumerate(rows[0]) if name not in ("participant", "study")]
    cut = ws["folder"] / "cut.csv"
    cut.write_text("\n".join(",".join(r[i] for i in keep) for r in rows) + "\n")
    run_checked(ws, ["analyze", cut, "-o", ws["folder"] / "report"], "missing the column(s) participant, study")
    assert not (ws["folder"] / "report").exists()


@pytest.mark.parametrize("args, needle", [
    (["--locations", "0,10"], "outside the location numbers"),
    (["--locations", "5,5"], "each location once"),
    (["-n", "1000000000"], "1000"),
    (["-n", "2"], "3"),
    (["--studies", "0"], "--studies"),
    (["--repetitions", "1000"], "--repetitions"),
    (["--workers", "100000"], "--workers"),
    (["--methods", "bogus"], "unknown method(s) ['bogus']"),
    (["--methods", "inverse"], "at least 2 methods"),
    (["--alpha", "1.5"], "--alpha"),
    (["--scheduler", "bogus"], "tcp://host:8786"),
    (["--scheduler", "tcp://127.0.0.1:1"], "cannot reach the Dask scheduler"),
])
def test_8_power_options(ws, args, needle):
    run_checked(ws, ["power", "--studies", "2", "-q", *args], needle)


def test_unexpected_errors_are_one_line_naming_a_log_and_debug_shows_the_traceback(ws, monkeypatch):
    """A failure no check foresaw (injected: the drives reader breaks) ends in one line, exit 1, and a log."""
    import vibrofocus.io.drives as drives_io

    def broken(*args, **kwargs):
        raise RuntimeError("injected failure")

    monkeypatch.setattr(drives_io, "read_drives", broken)
    logs = ws["folder"] / "logs"
    monkeypatch.setenv("VIBROFOCUS_LOG_DIR", str(logs))
    out = run_checked(ws, ["play", ws["drives"], "--dry-run"], "unexpected RuntimeError: injected failure",
                      expected_code=1)
    (log,) = logs.iterdir()
    assert str(log) in flat(out) and "RuntimeError: injected failure" in log.read_text()
    out, code = invoke(["--debug", "play", ws["drives"], "--dry-run"])
    assert code == 1 and "Traceback" in out and len(error_lines(out)) == 1


# ---------------------------------------------------------------------- nonsense (cases 9-13)
def _edit_calibration(src: Path, dst: Path, edit) -> Path:
    """Copy a calibration and change it with h5py (which keeps the checksums valid)."""
    import h5py

    shutil.copy2(src, dst)
    with h5py.File(dst, "r+") as f:
        edit(f)
    return dst


@pytest.mark.parametrize("label, edit, needle", [
    ("one value 1e300", lambda f: f["H_real"].__setitem__((100, 4, 1), 1e300), "point 5, actuator A2"),
    ("scaled by 1e12", lambda f: [f[k].__setitem__(Ellipsis, f[k][...] * 1e12) for k in ("H_real", "H_imag")],
     "not physically plausible"),
    ("scaled by 1e-12", lambda f: [f[k].__setitem__(Ellipsis, f[k][...] * 1e-12) for k in ("H_real", "H_imag")],
     "no actuator moved the skin"),
])
def test_9_an_implausible_transfer_matrix_is_refused_on_load(ws, label, edit, needle):
    cal = _edit_calibration(ws["cal"], ws["folder"] / "edited.nc", edit)
    run_checked(ws, ["render", "-c", cal, "-l", "5", "-o", ws["folder"] / "d.npz"], needle, "m/V")
    assert not (ws["folder"] / "d.npz").exists()


def test_10_a_stored_limit_never_loosens_the_rigs_own(ws):
    def raise_limit(f):
        rig = json.loads(f.attrs["rig"])
        rig.setdefault("limits", {})["peak_v"] = 1e6
        f.attrs["rig"] = json.dumps(rig)

    cal = _edit_calibration(ws["cal"], ws["folder"] / "limit.nc", raise_limit)
    out_npz, wav = ws["folder"] / "d.npz", ws["folder"] / "d.wav"
    run_checked(ws, ["render", "-c", cal, "-l", "5", "-o", out_npz, "--wav", wav], "peak_v=1e+06", "at most 10")
    run_checked(ws, ["render", "-c", cal, "-l", "5", "-o", out_npz, "--limit-v", "20"], "--limit-v 20")
    out, code = invoke(["render", "-c", cal, "-l", "5", "-o", out_npz, "--limit-v", "5", "--wav", wav])
    assert code == 0, out
    with np.load(out_npz) as data:
        assert np.abs(data["drives"]).max() <= 5 * (1 + 1e-9)
    assert json.loads(Path(str(wav) + ".json").read_text())["volts_per_full_scale"] == 5


@pytest.mark.parametrize("stored, refused", [(15.0, False), (25.0, True)])
def test_10_a_hardware_rigs_stored_limit_is_capped_by_the_hard_ceiling(ws, stored, refused):
    from vibrofocus.rigs.safety import PEAK_V_CEILING

    def as_audio(f):
        rig = json.loads(f.attrs["rig"])
        rig["kind"] = "audio"
        rig.setdefault("limits", {})["peak_v"] = stored
        f.attrs["rig"] = json.dumps(rig)

    cal = _edit_calibration(ws["cal"], ws["folder"] / "audio.nc", as_audio)
    out_npz = ws["folder"] / "d.npz"
    args = ["render", "-c", cal, "-l", "5", "-o", out_npz]
    if refused:
        run_checked(ws, args, f"peak_v={stored:g}", "hard ceiling", f"at most {PEAK_V_CEILING:g}")
        return
    out, code = invoke(args)
    assert code == 0, out
    with np.load(out_npz) as data:
        assert json.loads(str(data["metadata"]))["limit_v"] == stored


def test_12_a_bit_flip_in_the_header_is_one_line_and_no_ignored_exception(ws):
    data = bytearray(ws["cal"].read_bytes())
    data[200] ^= 0x10  # inside HDF5's superblock / root object header (checksummed)
    flipped = ws["folder"] / "flipped.nc"
    flipped.write_bytes(bytes(data))
    before = snapshot(ws["folder"])
    out, code = child(["render", "-c", flipped, "-l", "5", "-o", ws["folder"] / "d.npz"])
    assert_refused(out, code, "truncated or corrupt")
    assert changed(before, snapshot(ws["folder"])) == []


def test_13_error_verdicts_mean_exit_2_and_no_file_unless_force(ws):
    out_nc = ws["folder"] / "weak.nc"
    args = ["calibrate", "-p", "P02", "-o", out_nc, "--amplitude-v", "0.001", "--repeats", "4", "--sweep-s", "1",
            "--yes", "--no-figure"]
    out = run_checked(ws, args, "error verdict(s)", "not written", "--force")
    assert "looks dead" in flat(out)  # the verdicts are printed, indented, above the one error line
    assert not out_nc.exists()
    out, code = invoke(args + ["--force"])
    assert code == 0 and out_nc.exists(), out
    assert error_lines(out) == []


# ---------------------------------------------------------------------- the low items
@pytest.mark.parametrize("args, needle", [
    (["calibrate", "-p", "P", "-o", "{f}/c.nc", "--repeats", "1000", "--yes"], "--repeats"),
    (["calibrate", "-p", "P", "-o", "{f}/c.nc", "--amplitude-v", "1e-12", "--yes"], "--amplitude-v"),
    (["calibrate", "-p", "P", "-o", "{f}/c.nc", "--sweep-s", "0", "--yes"], "--sweep-s"),
    (["calibrate", "-p", "P", "-o", "{f}/x.csv", "--yes"], "use a .nc file name"),
    (["calibrate", "-p", "P", "-o", "{f}/c.nc", "--rig-config", "{f}/rig.toml", "--yes"], "simulated rig takes no"),
    (["calibrate", "-p", "x" * 100_000, "-o", "{f}/c.nc", "--yes"], "participant id must be"),
    (["calibrate", "-p", "P 01", "-o", "{f}/c.nc", "--yes"], "participant id must be"),
    (["study", "export", "--db", "{f}/study.db", "--out", "{f}/t2.csv", "--participant", "y" * 100_000],
     "unknown participant"),
    (["play", "{f}", "--dry-run"], "it is a folder"),
    (["play", "{drives}", "--rig-config", "{f}/rig.toml", "--dry-run"], "simulated rig takes no"),
    (["demo", "--moving-speed", "1e9", "--moving", "--out", "{f}/demo"], "--moving-speed"),
    (["demo", "--seed", "-1", "--out", "{f}/demo"], "--seed"),
    (["simulate-study", "-n", "100000", "--db", "{f}/x.db"], "--participants"),
    (["simulate-study", "--pace", "1e9", "--db", "{f}/x.db"], "--pace"),
    (["analyze", "{f}/t.csv", "--simulated", "-o", "{f}/a/b/c"], "does not exist"),
    (["render", "-c", "{cal}", "-l", "5", "-o", "{f}/d.npz", "--method", "x" * 100_000], "characters"),
])
def test_low_items(ws, args, needle):
    shutil.copy2(ws["drives"], ws["folder"] / "t.csv")  # any existing file for analyze
    (ws["folder"] / "rig.toml").write_text('kind = "audio"\n')
    fill = {"f": ws["folder"], "drives": ws["drives"], "cal": ws["cal"]}
    if args[0] == "analyze":  # a real trials file, so that only the output folder is wrong
        invoke(["study", "export", "--db", ws["db"], "--out", ws["folder"] / "t.csv", "--force"])
    out = run_checked(ws, [a.format(**fill) if len(a) < 200 else a for a in args], needle)
    assert max(len(line) for line in out.splitlines()) < 400  # no message echoes unbounded input
    assert not (ws["folder"] / "a").exists() and not (ws["folder"] / "demo").exists()
    assert not (ws["folder"] / "x-files").exists()


def test_a_refused_simulate_study_leaves_no_calibration_folder(ws):
    db = ws["folder"] / "fresh.db"
    run_checked(ws, ["simulate-study", "-q", "-n", "1", "--db", db, "--trials-csv", ws["cal"]], "--force")
    assert sorted(p.name for p in ws["folder"].iterdir()) == sorted(["P01.nc", "study.db", "drives.npz"])


def test_study_run_without_input_pauses_and_says_so(ws):
    db = ws["folder"] / "run.db"
    out, code = invoke(["study", "run", "--participant", "P01", "--study", "1", "--db", db, "--calibration",
                        ws["cal"], "--no-beep"], input="")
    assert_refused(out, code, "input ended", "paused")
    from vibrofocus.studies import StudyStore

    with StudyStore(db) as store:
        (session,) = store.sessions("P01")
        assert session.status == "paused" and session.n_answered == 0


def test_keypad_10_is_location_10_not_0():
    from vibrofocus.errors import StudyError
    from vibrofocus.studies import StudyDesign, parse_response

    with pytest.raises(StudyError, match="location 10 is outside"):
        parse_response("10", StudyDesign(study=2))
    assert parse_response("45", StudyDesign(study=2)) == (4, 5)


@pytest.mark.parametrize("column, value, needle", [
    ("trial", "\u0663", "trial must be"),        # ARABIC-INDIC DIGIT THREE
    ("target", "\uff15", "target must be"),      # FULLWIDTH DIGIT FIVE
    ("response", "\u0664", "response"),
    ("phase", "MAIN", "phase must be"),
    ("rt_s", "nan", "rt_s must be"),
    ("trial", "0", "trial must be"),
])
def test_the_trials_contract_is_enforced(ws, column, value, needle):
    export = ws["folder"] / "t.csv"
    out, code = invoke(["study", "export", "--db", ws["db"], "--out", export])
    assert code == 0, out
    lines = export.read_text(encoding="utf-8").splitlines()
    header = lines[0].split(",")
    row = lines[5].split(",")
    row[header.index(column)] = value
    lines[5] = ",".join(row)
    export.write_text("\n".join(lines) + "\n", encoding="utf-8")
    run_checked(ws, ["analyze", export, "-o", ws["folder"] / "report"], "line 6", needle)


# ---------------------------------------------------------------------- properties
@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(text=st.text(min_size=0, max_size=20_000))
def test_an_error_message_is_one_bounded_line_whatever_it_echoes(text):
    from vibrofocus.cli._errors import MAX_MESSAGE_CHARS, err_console, print_error

    with err_console.capture() as cap:
        print_error(f"bad value {text}")
    printed = cap.get()
    assert printed.endswith("\n") and len(printed.splitlines()) == 1, repr(printed[:200])
    assert printed.startswith("error: bad value")
    assert len(printed) <= MAX_MESSAGE_CHARS + 100


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(magic=st.sampled_from([b"SQLite format 3\x00", b"\x89HDF\r\n\x1a\n", b"PK\x03\x04", b"\x89PNG\r\n\x1a\n",
                              b"RIFF\x00\x00\x00\x00WAVE", b"\x00\x01\x02"]),
       tail=st.binary(max_size=200))
def test_no_trials_export_replaces_a_file_of_another_kind(seed_files, tmp_path_factory, magic, tail):
    folder = tmp_path_factory.mktemp("kind")
    target = folder / "t.csv"
    target.write_bytes(magic + tail)
    before = snapshot(folder)
    out, code = invoke(["study", "export", "--db", seed_files["db"], "--out", target])
    assert_refused(out, code, "--force")
    assert changed(before, snapshot(folder)) == []


def test_end_of_input_at_a_prompt_is_one_error_line():
    """click turns the end of input at a prompt into ``typer.Abort``; the root group says so in one line."""
    import typer

    from vibrofocus.cli.main import _OneLineErrors

    mini = typer.Typer(cls=_OneLineErrors)

    @mini.command()
    def ask() -> None:
        typer.prompt("where did you feel it")

    @mini.command()
    def other() -> None:  # two commands: a group, as the real app
        pass

    result = runner.invoke(mini, ["ask"], input="")
    assert_refused(result.output, result.exit_code, "input ended")


@pytest.mark.parametrize("target, needle", [("fifo", "FIFO"), ("cal", "not a study database"),
                                            ("folder", "folder"), ("missing", "does not exist")])
def test_serve_refuses_a_database_that_is_none_before_touching_it(ws, target, needle):
    """The server tightens its database's mode at start: a calibration given as --db kept its mode (0644)."""
    ws["cal"].chmod(0o644)
    db = {"cal": ws["cal"], "folder": ws["folder"], "missing": ws["folder"] / "no" / "x.db",
          "fifo": ws["folder"] / "fifo.db"}[target]
    if target == "fifo":
        os.mkfifo(db)
    run_checked(ws, ["serve", "--no-browser", "--db", db], needle)
    assert not (ws["folder"] / "no").exists()
