"""A user id as people read it (standard library only: the terminal stop uses it)."""

from __future__ import annotations

__all__ = ["owner_name"]


def owner_name(uid: int) -> str:
    """A user id as people read it: ``user alice (uid 1000)``."""
    try:
        import pwd

        return f"user {pwd.getpwuid(uid).pw_name} (uid {uid})"
    except (ImportError, KeyError):
        return f"uid {uid}"
