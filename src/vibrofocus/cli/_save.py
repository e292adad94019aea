"""Saving a measurement that cannot be measured again for free: never lose it on a failed save."""

from __future__ import annotations

import datetime as _dt
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path

import typer

from ..errors import OutputError
from ._errors import print_error


def fallback_paths(out: Path) -> list[Path]:
    """Where a measurement goes when ``out`` cannot be written: the current folder, then the temp folder."""
    stamp = _dt.datetime.now().strftime("%Y%m%d-%H%M%S")
    name = f"{out.stem}.unsaved-{stamp}{out.suffix or '.nc'}"
    places = [Path.cwd(), Path(tempfile.gettempdir())]
    seen: list[Path] = []
    for folder in places:
        candidate = folder / name
        if candidate.parent.resolve() != out.parent.resolve() and candidate not in seen:
            seen.append(candidate)
    return seen


def _interactive() -> bool:
    try:
        return sys.stdin is not None and sys.stdin.isatty() and sys.stdout.isatty()
    except (AttributeError, ValueError):
        return False


def save_or_offer_another_path(
    save: Callable[[Path], Path], out: Path, *, what: str = "calibration", interactive: bool | None = None
) -> Path:
    """Call ``save(out)``; if it cannot be written, save elsewhere instead of losing the data.

    At a terminal the user is asked for another path (repeatedly, until one works or
    the answer is empty, which falls back as below). Otherwise the data goes to
    :func:`fallback_paths` and the command fails with one line naming that file.

    Parameters
    ----------
    save : callable
        ``save(path) -> path``; raises :class:`OutputError` when the path cannot take it.
    out : Path
        Where the user asked for the file.
    what : str
        For messages.
    interactive : bool, optional
        Ask at the terminal; default: when stdin and stdout are terminals.

    Returns
    -------
    Path
        Where the data was saved, when that is ``out`` or a path the user gave.

    Raises
    ------
    OutputError
        When the data could only be saved to a fallback path (named in the message), or
        nowhere at all.
    """
    try:
        return save(out)
    except OutputError as first:
        failure = first
    if _interactive() if interactive is None else interactive:
        print_error(str(failure))
        while True:
            answer = typer.prompt(
                f"The {what} is still in memory. Save it to (empty: a fallback file)", default="", show_default=False
            ).strip()
            if not answer:
                break
            try:
                return save(Path(answer).expanduser())
            except OutputError as exc:
                print_error(str(exc))
    for candidate in fallback_paths(out):
        try:
            saved = save(candidate)
        except OutputError:
            continue
        raise OutputError(
            f"{failure}; the {what} just measured was saved to {saved} instead (move it where it belongs)",
            errno=failure.errno, path=str(saved),
        ) from failure
    raise OutputError(
        f"{failure}; the {what} could not be saved anywhere (also tried {', '.join(map(str, fallback_paths(out)))})",
        errno=failure.errno, path=failure.path,
    ) from failure
