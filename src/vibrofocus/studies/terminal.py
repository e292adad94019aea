"""A participant answering at the terminal on a numeric keypad."""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from typing import Any

from ..errors import StudyError
from .engine import ABORT, PAUSE, Presentation, Response
from .protocol import parse_response
from .staircase import parse_detection

__all__ = ["TerminalResponder", "InputEnded"]


class InputEnded(StudyError):
    """The answers' input ended (end of file: stdin closed or redirected) before the session did."""


class TerminalResponder:
    """Read answers typed on a keypad: digits then Enter; ``p`` pauses, ``q`` aborts.

    Parameters
    ----------
    console : rich.console.Console, optional
        Where prompts go.
    input_fn : callable, optional
        Reads one line (default :func:`input`); end of input raises :class:`InputEnded`
        (nobody is answering: ``vibrofocus study run`` pauses the session, it does not
        abort it).
    n_trials : int, optional
        Shown in the prompt.

    Notes
    -----
    The response time runs from the stimulus onset to the Enter key of a valid answer,
    s. An invalid answer is explained and asked again; it is never stored. Keys typed
    before a prompt appears (ahead, during the stimulus) are discarded when the keypad is
    a terminal, so one line typed three times is one answer, not three trials' answers.
    """

    def __init__(self, console: Any = None, input_fn: Callable[[str], str] | None = None, n_trials: int | None = None):
        if console is None:
            from rich.console import Console

            console = Console()
        self.console = console
        self.input_fn = input_fn if input_fn is not None else input
        self.n_trials = n_trials

    def _read(self, prompt: str) -> str:
        if self.input_fn is input:
            _discard_typed_ahead()
        self.console.print(prompt, end="")
        try:
            return self.input_fn("")
        except EOFError:
            raise InputEnded("the keypad input ended (end of file) before the session did") from None

    def respond(self, presentation: Presentation) -> Response | str:
        t = presentation.trial
        of = f"/{self.n_trials}" if self.n_trials else ""
        several = "one or more locations, e.g. 45" if presentation.design.multi_select else "one location"
        question = f"where did you feel it? {several}"
        if presentation.design.detection:  # a threshold block
            question = "did you feel it? 1 yes, 0 no"
        prompt = f"[bold]trial {t.trial_index + 1}{of}[/] ({t.phase}) — {question}, Enter (p pause, q abort): "
        while True:
            line = self._read(prompt)
            rt = time.monotonic() - presentation.onset_s
            text = line.strip().lower()
            if text == "p":
                return PAUSE
            if text == "q":
                return ABORT
            try:
                locations = ((parse_detection(text),) if presentation.design.detection
                             else parse_response(text, presentation.design))
            except StudyError as exc:
                self.console.print(f"[red]{exc}[/] — try again")
                continue
            return Response(locations, rt)

    def cooling(self, trial: Any, wait_s: float) -> None:
        """Say that the trial waits for the actuators to cool (the rig's limits over time)."""
        self.console.print(f"trial {trial.trial}: waiting {wait_s:.1f} s for the actuators to cool "
                           "(the rig's RMS limit over time)")

    def xrun(self, trial: Any, n: int, limit: int) -> None:
        """Say that the trial's stimulus lost samples and is presented again."""
        self.console.print(f"trial {trial.trial}: the audio stream lost samples during the stimulus; presenting it "
                           f"again ({n} of at most {limit})")

    def wait_resume(self) -> bool:
        line = self._read("[yellow]paused[/] — Enter to resume (the trial is played again), q to abort: ")
        return line.strip().lower() != "q"


def _discard_typed_ahead() -> None:
    """Drop what was typed at the terminal and not read yet (POSIX terminals; nothing elsewhere)."""
    try:
        import termios
    except ImportError:  # Windows: its console has no line buffer to flush here
        return
    try:
        if sys.stdin is not None and sys.stdin.isatty():
            termios.tcflush(sys.stdin.fileno(), termios.TCIFLUSH)
    except (OSError, ValueError, termios.error):
        pass  # not a terminal after all (a closed or redirected stdin): nothing typed ahead to drop
