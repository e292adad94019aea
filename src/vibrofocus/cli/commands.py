"""Explicit list of the command modules; importing each registers its commands on ``app``."""

# One import per command module, in the order ``--help`` should list them.
from . import serve  # noqa: E402,F401
from . import analyze  # noqa: F401
