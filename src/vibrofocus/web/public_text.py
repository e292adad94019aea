"""What a page or a response may say about files: their names, never where they are.

Messages of the layers below (the study store, the calibration reader) name files by
their absolute paths, which tell a participant's screen or a script the account's
folders. Everything the app sends goes through :func:`public_text`.
"""

from __future__ import annotations

import re

__all__ = ["public_text"]

# An absolute POSIX or Windows path of at least one folder: its last part is kept.
_PATH = re.compile(r"""(?<![\w.~])(?:[A-Za-z]:)?[\\/](?:[^\s'"\\/<>]+[\\/])+([^\s'"\\/<>]+)""")


def public_text(text: str) -> str:
    """``text`` with every absolute path cut down to its file name.

    Parameters
    ----------
    text : str
        A message.

    Returns
    -------
    str
        The message, e.g. ``"file /home/lab/P01.h5 changed"`` becomes ``"file P01.h5 changed"``.
    """
    return _PATH.sub(lambda m: m.group(1), str(text))
