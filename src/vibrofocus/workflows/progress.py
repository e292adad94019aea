"""The one progress-and-cancellation interface a workflow reports through."""

from __future__ import annotations

from typing import Any, Protocol, runtime_checkable

from ..errors import VibrofocusError

__all__ = ["Progress", "QuietProgress", "WorkflowCancelled"]


class WorkflowCancelled(VibrofocusError):
    """The front-end cancelled a workflow (:meth:`Progress.cancelled` turned true)."""


@runtime_checkable
class Progress(Protocol):
    """What a workflow reports to its front-end, and how it learns of a cancel.

    The command line renders it as a progress bar and printed lines, the web app as a
    job's live card. A workflow calls :meth:`cancelled` after every :meth:`step` and
    raises :class:`WorkflowCancelled` when it is true.
    """

    def step(self, done: int, total: int, message: str) -> None:
        """``done`` of ``total`` steps are over; ``message`` says what runs now."""

    def note(self, message: str, **details: Any) -> None:
        """A line to show (the plan, the strap forces, a file written).

        ``details`` carry the objects behind the line for a front-end that shows more
        than the line (``straps``: the :class:`~vibrofocus.rigs.force.StrapReading`).
        """

    def judged(self, result: Any) -> None:
        """The measurement is estimated and judged (``result`` has ``quality``), not yet saved."""

    def cancelled(self) -> bool:
        """Whether the front-end asks the workflow to stop."""


class QuietProgress:
    """A :class:`Progress` that shows nothing and is never cancelled; a base to override."""

    def step(self, done: int, total: int, message: str) -> None:  # noqa: D102 - Progress
        pass

    def note(self, message: str, **details: Any) -> None:  # noqa: D102 - Progress
        pass

    def judged(self, result: Any) -> None:  # noqa: D102 - Progress
        pass

    def cancelled(self) -> bool:  # noqa: D102 - Progress
        return False
