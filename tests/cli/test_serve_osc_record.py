"""``vibrofocus serve-osc --lsl --log FILE`` as a process, with a real python-osc client and a
real pylsl inlet: every acknowledged tap is in the log and on LSL, stamped with its onset."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys

import pytest

pytest.importorskip("pythonosc")
pylsl = pytest.importorskip("pylsl")
from pythonosc.osc_message import OscMessage  # noqa: E402
from pythonosc.udp_client import SimpleUDPClient  # noqa: E402

from vibrofocus.io.lsl import clock_offset, stable_source_id  # noqa: E402

from .serve_osc_lines import problems  # noqa: E402
from vibrofocus.realtime import PLAYED_FIELDS, read_tap_log  # noqa: E402

pytestmark = pytest.mark.slow

TAPS = [("/tap", [5]), ("/tap", [5, -6.0]), ("/tap", [2, -12]), ("/tap_xy", [3.5, -4.0]),
        ("/tap_xy", [-2.0, 1.0, -3.0]), ("/tap", [9, -20.0])]


def _ask(client, address, args):
    client.send_message(address, args)
    data = client.receive(60)
    assert data, f"no reply to {address}"
    return OscMessage(data)


@pytest.mark.parametrize("name", ["taps.csv"])  # SQLite: tests/realtime/test_osc_levels.py
def test_serve_osc_lsl_log_records_every_tap_with_its_onsets(tmp_path, lsl_config, name):
    log = tmp_path / name
    env = dict(os.environ, PYTHONDONTWRITEBYTECODE="1", MPLBACKEND="Agg")
    proc = subprocess.Popen([sys.executable, "-m", "vibrofocus", "serve-osc", "--port", "0", "--seed", "2",
                             "--lsl", "--log", str(log)], cwd=tmp_path, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=env)
    try:
        lines = [proc.stdout.readline() for _ in range(3)]
        port = re.search(r"osc\.udp://127\.0\.0\.1:(\d+)", lines[0])
        source = re.search(r"source_id (\S+)\)", lines[2])
        assert port and source and f"taps logged to {log}" in lines[2], (lines, proc.stderr.read())
        # The stream is named after the log: a restarted server keeps it (LabRecorder recovers it).
        assert source.group(1) == stable_source_id(log)
        inlets = []
        for sid in (source.group(1), source.group(1) + "-detail"):  # the codes, then the JSON details
            streams = pylsl.resolve_bypred(f"source_id='{sid}'", 1, 60.0)
            assert streams, f"the marker outlet {sid} was not found"
            inlets.append(pylsl.StreamInlet(streams[0], max_buflen=60))
            inlets[-1].open_stream(timeout=60.0)  # connected before the first tap: no marker is sent to nobody
        client = SimpleUDPClient("127.0.0.1", int(port.group(1)))
        replies = [_ask(client, address, args) for address, args in TAPS]
        refused = _ask(client, "/tap", [5, 3.0])  # over the limit: not played, not logged, no marker
        markers, codes = [], []
        for _ in TAPS:
            code, code_stamp = inlets[0].pull_sample(timeout=60.0)
            sample, stamp = inlets[1].pull_sample(timeout=60.0)
            assert code is not None and sample is not None, "a tap's marker was lost"
            assert code_stamp == stamp
            codes.append(code[0])
            markers.append((json.loads(sample[0]), stamp))
        assert _ask(client, "/stop", []).address == "/stopped"
        out, err = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert proc.returncode == 0 and problems(err) == [], err
    assert [r.address for r in replies] == ["/played"] * len(TAPS)
    assert refused.address == "/error" and "drive refused" in refused.params[0]
    tails = [dict(zip(PLAYED_FIELDS, r.params[-len(PLAYED_FIELDS):])) for r in replies]
    assert [t["tap_id"] for t in tails] == list(range(1, len(TAPS) + 1))
    assert [t["level_db"] for t in tails] == [0.0, -6.0, -12.0, 0.0, -3.0, -20.0]

    rows = read_tap_log(log)
    assert len(rows) == len(TAPS)  # every acknowledged tap, the refused one not
    for row, tail, (address, args) in zip(rows, tails, TAPS):
        assert (row["tap_id"], row["address"], row["level_db"]) == (tail["tap_id"], address, tail["level_db"])
        assert (row["onset_host_s"], row["onset_device_s"], row["onset_clock"]) == (
            tail["onset_host_s"], tail["onset_device_s"], tail["onset_clock"])
        assert row["location"] == (args[0] if address == "/tap" else None)
        # The drive's peak follows the level: the designs are at the 10 V limit, -6 dB is half of it.
        assert row["drive_peak_v"] == pytest.approx(10.0 * 10 ** (row["level_db"] / 20), rel=1e-9)
    assert [r["onset_clock"] for r in rows] == ["simulated_samples"] * len(TAPS)
    # Markers: one per tap, in order, stamped with the tap's host onset on LSL's clock.
    offset = clock_offset(pylsl.local_clock)  # CLOCK_MONOTONIC and LSL's clock are machine-wide
    assert [m["tap_id"] for m, _ in markers] == [r["tap_id"] for r in rows]
    assert {m["event"] for m, _ in markers} == {"stimulus_onset"}
    assert codes == [f"tap/{m['method']}" for m, _ in markers]
    assert [m["level_db"] for m, _ in markers] == [r["level_db"] for r in rows]
    assert [m["onset_device_s"] for m, _ in markers] == [r["onset_device_s"] for r in rows]
    errors = [abs(stamp - (row["onset_host_s"] + offset)) for (_, stamp), row in zip(markers, rows)]
    assert max(errors) < 1e-3, errors
    assert "serve-osc stopped by /stop" in out


def test_without_pylsl_lsl_is_one_error_line_and_nothing_starts(tmp_path, monkeypatch):
    from typer.testing import CliRunner

    from vibrofocus.cli.main import app

    monkeypatch.setitem(sys.modules, "pylsl", None)  # import pylsl raises ImportError
    result = CliRunner().invoke(app, ["serve-osc", "--port", "0", "--lsl", "--log", str(tmp_path / "taps.csv")])
    assert result.exit_code == 2, result.output
    errors = [line for line in result.output.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and "vibrofocus[lsl]" in errors[0]
    assert list(tmp_path.iterdir()) == []  # no tap log


@pytest.mark.parametrize("name, needle", [("taps.txt", ".csv or a SQLite file"), ("study.db", "another kind")])
def test_a_log_that_cannot_be_a_tap_log_is_one_error_line(tmp_path, name, needle):
    from typer.testing import CliRunner

    from vibrofocus.cli.main import app

    if name == "study.db":
        from vibrofocus.studies import StudyStore

        StudyStore(tmp_path / name).close()
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    result = CliRunner().invoke(app, ["serve-osc", "--port", "0", "--log", str(tmp_path / name)])
    assert result.exit_code != 0 and needle in result.output, result.output
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == before
