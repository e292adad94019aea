"""Progress bars at a terminal, and progress lines where the output is not one (logs, CI, ``| tee``).

``rich`` draws nothing when its console is not a terminal, so a long command piped into a
file was silent for minutes. :func:`progress_bar` gives rich's bar, with the time left, at
a terminal, and :class:`ProgressLines` elsewhere: the same methods, printing one line (done
of total, elapsed, left) at most every :data:`LINE_EVERY_S` seconds and at the end.
"""

from __future__ import annotations

import time
from typing import Any

__all__ = ["LINE_EVERY_S", "ProgressLines", "progress_bar"]

#: Seconds between two progress lines when the output is not a terminal.
LINE_EVERY_S = 10.0


def progress_bar(console: Any, *, label: str | None = None, counts: bool = True, transient: bool = False,
                 disable: bool = False) -> Any:
    """A bar for ``console``: rich's at a terminal (with the time left), else :class:`ProgressLines`.

    Parameters
    ----------
    console : rich.console.Console
        Where it is drawn.
    label : str, optional
        A fixed label before the bar (default: each task's description).
    counts : bool
        Show the bar and "done/total" (False: a description and the elapsed time only).
    transient : bool
        Remove the bar when it stops (at a terminal).
    disable : bool
        Show nothing (``--quiet``).

    Returns
    -------
    rich.progress.Progress or ProgressLines
        Both have ``start``, ``stop``, ``add_task``, ``update`` and ``advance``.
    """
    if not console.is_terminal:
        return ProgressLines(console, label=label, disable=disable)
    from rich.progress import (BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn,
                               TimeRemainingColumn)

    text = TextColumn(label if label is not None else "[progress.description]{task.description}")
    extra = (BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(), TextColumn("left"),
             TimeRemainingColumn()) if counts else (TimeElapsedColumn(),)
    return Progress(text, *extra, console=console, transient=transient, disable=disable)


class ProgressLines:
    """rich's ``Progress`` methods as plain lines: ``done/total description (elapsed, about N left)``.

    A line is printed when a task starts, at most every :data:`LINE_EVERY_S` seconds as it
    moves, and when it completes; each line is flushed, so a log shows it at once.
    """

    def __init__(self, console: Any, *, label: str | None = None, disable: bool = False,
                 every_s: float = LINE_EVERY_S, clock: Any = time.monotonic) -> None:
        self.console, self.label, self.disable, self.every_s, self.clock = console, label, disable, every_s, clock
        self._tasks: dict[int, dict[str, Any]] = {}

    def start(self) -> None:  # noqa: D102 - rich's Progress
        pass

    def stop(self) -> None:  # noqa: D102 - rich's Progress
        for task_id, task in self._tasks.items():
            if task["printed_done"] != task["completed"]:
                self._line(task_id, force=True)

    def __enter__(self) -> "ProgressLines":
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def add_task(self, description: str, total: float | None = None, **_: Any) -> int:  # noqa: D102
        task_id = len(self._tasks)
        self._tasks[task_id] = {"description": description, "total": total, "completed": 0, "start": self.clock(),
                                "printed_at": None, "printed_done": None}
        return task_id

    def update(self, task_id: int, *, completed: float | None = None, total: float | None = None,
               description: str | None = None, advance: float | None = None, **_: Any) -> None:  # noqa: D102
        task = self._tasks[task_id]
        if total is not None:
            task["total"] = total
        if description is not None:
            task["description"] = description
        if completed is not None:
            task["completed"] = completed
        if advance is not None:
            task["completed"] += advance
        self._line(task_id)

    def advance(self, task_id: int, advance: float = 1) -> None:  # noqa: D102 - rich's Progress
        self.update(task_id, advance=advance)

    def _line(self, task_id: int, *, force: bool = False) -> None:
        task = self._tasks[task_id]
        now = self.clock()
        done, total = task["completed"], task["total"]
        finished = total is not None and done >= total
        due = task["printed_at"] is None or now - task["printed_at"] >= self.every_s
        if self.disable or not (force or finished or due) or task["printed_done"] == done and not force:
            return
        elapsed = now - task["start"]
        where = f"{done:g}/{total:g} " if total else ""
        left = ""
        if total and 0 < done < total:
            left = f", about {_duration(elapsed * (total - done) / done)} left"
        name = self.label or task["description"]
        self.console.print(f"{where}{name} ({_duration(elapsed)} elapsed{left})", markup=False, highlight=False)
        self.console.file.flush()
        task["printed_at"], task["printed_done"] = now, done


def _duration(seconds: float) -> str:
    """``42 s``, ``3 min 05 s``, ``1 h 02 min``."""
    s = int(round(seconds))
    if s < 60:
        return f"{s} s"
    if s < 3600:
        return f"{s // 60} min {s % 60:02d} s"
    return f"{s // 3600} h {s % 3600 // 60:02d} min"
