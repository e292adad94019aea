"""Long commands show their progress where the output is not a terminal (issue 54, item 9)."""

from __future__ import annotations

import io
import subprocess
import sys
import time

from rich.console import Console

from vibrofocus.cli._progress import ProgressLines, progress_bar


class Clock:
    def __init__(self):
        self.t = 100.0

    def __call__(self):
        return self.t


def test_lines_at_start_every_ten_seconds_and_at_the_end_with_the_time_left():
    out, clock = io.StringIO(), Clock()
    lines = ProgressLines(Console(file=out, width=200), clock=clock)
    task = lines.add_task("trials", total=100)
    for done in range(1, 101):
        clock.t += 1.0  # one trial a second
        lines.update(task, completed=done, description="sim-001 study 1")
    lines.stop()
    printed = out.getvalue().splitlines()
    assert printed[0] == "1/100 sim-001 study 1 (1 s elapsed, about 1 min 39 s left)"
    assert printed[1].startswith("11/100 ") and "about 1 min 29 s left" in printed[1]
    assert printed[-1] == "100/100 sim-001 study 1 (1 min 40 s elapsed)"
    assert len(printed) == 11  # 1, 11, ..., 91 and the end: not one line per trial


def test_quiet_prints_nothing_and_a_terminal_gets_rich_bar():
    out = io.StringIO()
    lines = ProgressLines(Console(file=out), disable=True)
    lines.update(lines.add_task("x", total=2), completed=2)
    assert out.getvalue() == ""
    assert isinstance(progress_bar(Console(file=io.StringIO())), ProgressLines)
    assert not isinstance(progress_bar(Console(file=io.StringIO(), force_terminal=True)), ProgressLines)


def test_the_simulation_shows_its_progress_in_a_log():
    from vibrofocus.cli.simulate_study import SimulationProgress

    out = io.StringIO()
    with SimulationProgress(Console(file=out, width=200), quiet=False, skin="nominal") as shown:
        for done in range(0, 4):
            shown.step(done, 3, "sim-001: study 1")
    assert "3/3 sim-001: study 1" in out.getvalue()


def test_output_to_a_pipe_is_flushed_line_by_line():
    # The CLI sets line buffering: a line reaches a log while the command still runs.
    code = ("import time; from vibrofocus.cli.main import _line_buffered; _line_buffered(); "
            "print('first line', flush=False); time.sleep(60)")
    proc = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    try:
        start = time.monotonic()
        line = proc.stdout.readline()
        assert line == "first line\n" and time.monotonic() - start < 50
    finally:
        proc.kill()
        proc.wait()
