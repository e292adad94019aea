"""What serve-osc says on stderr while it starts (about a minute on the simulated rig)."""

import re

STARTING = re.compile(r"(serve-osc: (starting|opening|computing|evaluating)|\d+/\d+ rows of the /tap_xy grid)")


def problems(err: str) -> list[str]:
    """stderr's lines but those of the start."""
    return [line for line in err.strip().splitlines() if not STARTING.match(line)]
