"""Explicit list of the command modules; importing each registers its commands on ``app``."""

# One import per command module, in the order ``--help`` should list them.
from . import demo  # noqa: F401
from . import calibrate  # noqa: F401
from . import render  # noqa: F401
from . import serve  # noqa: E402,F401
from . import analyze  # noqa: F401
from . import study  # noqa: F401
from . import simulate_study  # noqa: F401
from . import power  # noqa: F401
from . import play  # noqa: F401
from . import devices  # noqa: F401
