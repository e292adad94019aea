"""What a calibration may replace: a participant's calibration is an hour of a person's time.

Rules shared by :func:`~vibrofocus.calibration.save_calibration`,
:func:`~vibrofocus.calibration.export_sofa`, ``vibrofocus calibrate`` and
``vibrofocus simulate-study``:

- a file of another kind (a study database, a CSV, ...) is never replaced without
  ``force``, in the Python API as in the commands;
- a calibration of another participant is never replaced without ``force``;
- when a calibration is replaced, the previous one is kept under the next free numbered
  name (``P01.nc`` -> ``P01.1.nc``, then ``P01.2.nc``), as a hard link taken before the
  atomic write (or a copy where links are not allowed);
- a new file can be put at a free name reserved atomically (:func:`reserve_free_name`),
  so two processes never pick the same one.
"""

from __future__ import annotations

import contextlib
import errno as _errno
import os
import shutil
from pathlib import Path

from .._validation import shorten
from ..errors import OutputError

__all__ = ["CALIBRATION_KIND", "calibration_owner", "check_calibration_target", "keep_previous", "numbered_name",
           "reserve_free_name"]

#: What :func:`vibrofocus._atomic.file_kind` says of a calibration (netCDF4 is HDF5).
CALIBRATION_KIND = "HDF5/netCDF file (a calibration?)"
_MAX_NUMBER = 10_000


def calibration_owner(path: str | os.PathLike) -> str | None:
    """The participant id of the vibrofocus calibration at ``path``; None if it is none (or unreadable).

    Reads only the file's root attributes (no array is loaded).
    """
    import h5py

    try:
        with h5py.File(path, "r") as fh:
            attrs = fh.attrs
            if not {"participant_id", "schema_version", "method"} <= set(attrs):
                return None
            value = attrs["participant_id"]
    except Exception:  # h5py raises OSError, ValueError, KeyError... for a file that is not HDF5
        return None
    if isinstance(value, bytes):
        value = value.decode("utf-8", "replace")
    return str(value)


def numbered_name(path: Path, number: int) -> Path:
    """``P01.nc`` -> ``P01.<number>.nc``."""
    return path.with_name(f"{path.stem}.{number}{path.suffix}")


def check_calibration_target(path: str | os.PathLike, participant_id: str | None, *, force: bool = False,
                             what: str = "calibration") -> str | None:
    """Refuse to replace a file of another kind or another participant's calibration, unless ``force``.

    Parameters
    ----------
    path : path-like
        Where the calibration (or its SOFA export) would go.
    participant_id : str or None
        Whose the new file is; None for a file that is no calibration (a SOFA export):
        then any existing calibration is refused.
    force : bool
        Replace anyway (the previous file is still kept, see :func:`keep_previous`).
    what : str
        For the message.

    Returns
    -------
    str or None
        The participant of the calibration there (None: no calibration there).

    Raises
    ------
    OutputError
    """
    from .._atomic import file_kind

    path = Path(path)
    if not path.is_file():
        return None  # missing; a folder, device or dangling link is refused by the writer itself
    kind = file_kind(path)
    if kind is None:
        return None
    if kind != CALIBRATION_KIND:
        if force:
            return None
        raise OutputError(f"cannot write the {what} {path}: it holds a {kind}, not a calibration; choose another name, "
                          "or pass --force (force=True) to replace it; nothing was written",
                          errno=_errno.EEXIST, path=str(path))
    owner = calibration_owner(path)
    if owner is not None and owner != participant_id and not force:
        whose = f"participant {shorten(owner)}" if owner else "a participant"
        new = "this is a SOFA export, not a calibration" if participant_id is None else \
            f"the new one is of {shorten(participant_id)}"
        raise OutputError(f"cannot write the {what} {path}: it holds the calibration of {whose} ({new}); a "
                          "participant's calibration is never replaced without --force (force=True); choose another "
                          "name; nothing was written", errno=_errno.EEXIST, path=str(path))
    return owner


def keep_previous(path: str | os.PathLike) -> Path | None:
    """Keep the file at ``path`` under the next free numbered name, before it is replaced.

    Returns
    -------
    Path or None
        Where the previous file is now also found; None when there was none (or it was empty).

    Raises
    ------
    OutputError
        The previous file cannot be kept (then nothing should replace it).
    """
    path = Path(path)
    real = Path(os.path.realpath(path))
    try:
        if not real.is_file() or real.stat().st_size == 0:
            return None
    except OSError:
        return None
    for number in range(1, _MAX_NUMBER):
        backup = numbered_name(path, number)
        if os.path.lexists(backup):
            continue
        try:
            os.link(real, backup)  # atomic and free: the old inode keeps a second name
            return backup
        except FileExistsError:
            continue
        except OSError as exc:
            if exc.errno not in (_errno.EPERM, _errno.EXDEV, _errno.ENOTSUP, _errno.EOPNOTSUPP, _errno.EMLINK):
                raise OutputError(f"cannot keep the previous file {path} as {backup}: {exc.strerror or exc}; "
                                  "nothing was replaced", errno=exc.errno, path=str(backup)) from exc
        try:  # no hard links here: a copy, created exclusively
            with open(real, "rb") as src, open(backup, "xb") as dst:
                shutil.copyfileobj(src, dst)
            shutil.copystat(real, backup)
            return backup
        except FileExistsError:
            continue
        except OSError as exc:
            with contextlib.suppress(OSError):
                os.unlink(backup)
            raise OutputError(f"cannot keep the previous file {path} as {backup}: {exc.strerror or exc}; nothing "
                              "was replaced", errno=exc.errno, path=str(backup)) from exc
    raise OutputError(f"cannot keep the previous file {path}: {_MAX_NUMBER} numbered copies exist; tidy the folder",
                      path=str(path))


def reserve_free_name(path: str | os.PathLike) -> Path:
    """``path``, or the first free ``<stem>.<n><suffix>``, created empty and exclusively.

    Another process reserving at the same time gets another name. The caller writes
    the file over the (empty) reservation, or removes it.
    """
    path = Path(path)
    for number in range(0, _MAX_NUMBER):
        candidate = path if number == 0 else numbered_name(path, number)
        try:
            fd = os.open(candidate, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
        except FileExistsError:
            continue
        except OSError as exc:
            raise OutputError(f"cannot create {candidate}: {exc.strerror or exc}", errno=exc.errno,
                              path=str(candidate)) from exc
        os.close(fd)
        return candidate
    raise OutputError(f"no free name for {path}: {_MAX_NUMBER} numbered files exist; tidy the folder", path=str(path))
