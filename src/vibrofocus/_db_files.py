"""Where a study database's files go: one folder, ``<db stem>-files/``, beside it.

For ``study.sqlite`` it is ``study-files/``, holding ``calibrations/`` (the calibration
files ``serve`` and ``simulate-study`` make), ``reports/``, ``protocols/``, ``stop.sock``
and ``server.lock`` (docs/file-formats.md, "Study database"). Every front-end names these
paths through this module, never on its own.

``simulate-study`` once wrote its calibrations to ``<db>.calibrations/``
(``study.sqlite.calibrations/``). Nothing is moved from there: the database stores each
calibration's absolute path, so those files are read where they are, and
:func:`former_calibrations_dir` lets a front-end say where they lie.
Standard library only (the terminal stop uses it).
"""

from __future__ import annotations

import os
import stat
from pathlib import Path

__all__ = ["files_dir", "calibrations_dir", "former_calibrations_dir", "make_private_dir"]


def files_dir(db_path: str | os.PathLike) -> Path:
    """The database's files folder, ``<db folder>/<db stem>-files`` (not made here).

    Parameters
    ----------
    db_path : path-like
        The study database.
    """
    db = Path(db_path)
    return db.parent / f"{db.stem}-files"


def calibrations_dir(db_path: str | os.PathLike) -> Path:
    """Where new calibration files of the database go: ``<db stem>-files/calibrations``.

    Parameters
    ----------
    db_path : path-like
        The study database.
    """
    return files_dir(db_path) / "calibrations"


def former_calibrations_dir(db_path: str | os.PathLike) -> Path | None:
    """``<db>.calibrations/``, where ``simulate-study`` wrote before, if it is a folder (not a link).

    Parameters
    ----------
    db_path : path-like
        The study database.
    """
    db = Path(db_path)
    old = db.with_name(db.name + ".calibrations")
    try:
        return old if stat.S_ISDIR(os.lstat(old).st_mode) else None
    except OSError:
        return None


def make_private_dir(folder: Path, db_path: str | os.PathLike) -> None:
    """Make ``folder`` and the files folders above it up to the database's, each 0700.

    None may be a link, another user's or open to other users (docs/security.md): a folder
    of ours open to others is closed (the rule of ``serve``'s files folder).

    Parameters
    ----------
    folder : Path
        The folder to make: the files folder of ``db_path`` or a folder in it.
    db_path : path-like
        The study database.

    Raises
    ------
    OutputError
        A folder on the way is a link, not a folder, another user's, or cannot be made.
    """
    from ._safe_folders import private_folder_problem
    from .errors import OutputError

    top = files_dir(db_path)
    chain = [top, *[top.joinpath(*Path(folder).relative_to(top).parts[:i + 1])
                    for i in range(len(Path(folder).relative_to(top).parts))]]
    for path in chain:
        problem = private_folder_problem(path)
        if problem:
            raise OutputError(f"the database's files folder {path} {problem}: refused (it must be yours, "
                              "closed to other users and not a link: docs/security.md)")
