"""Compile a Builder experiment (``.psyexp``) that uses the tap component, from a shell.

PsychoPy's own shell compiler (``python -m psychopy.scripts.psyexpCompile``) does not load
plugins: it writes ``# Unknown component ignored: tap`` and exits 0, and the script then
fails at run time. :func:`compile_experiment` activates PsychoPy's plugins first (as the
Builder app does at start), checks that the tap component was loaded, compiles through
PsychoPy's :class:`~psychopy.experiment.Experiment`, and refuses a script that still
ignores a component. ``vibrofocus psychopy compile FILE.psyexp`` calls it.

This module imports PsychoPy when called; importing it does not.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

from ..errors import ValidationError
from ..io import write_text

__all__ = ["compile_experiment", "COMPONENT"]

#: The component's class name, as PsychoPy's component registry lists it.
COMPONENT = "VibrofocusTapComponent"

# What PsychoPy writes for a component it does not know.
_IGNORED = re.compile(r"#\s*Unknown component ignored:\s*(\S+)")


def compile_experiment(psyexp: str | os.PathLike, out: str | os.PathLike | None = None) -> Path:
    """Compile ``psyexp`` to a Python script with vibrofocus's component loaded.

    Parameters
    ----------
    psyexp : path-like
        A Builder experiment file (``.psyexp``).
    out : path-like, optional
        The script to write (default: beside ``psyexp``, ``<stem>.py``, as PsychoPy's
        compiler names it). Written atomically; replacing an existing file follows the
        package's output rules (``--force``).

    Returns
    -------
    Path
        The script written.

    Raises
    ------
    ValidationError
        PsychoPy is not installed in this Python, its plugins do not include
        vibrofocus's component, ``psyexp`` is not a readable ``.psyexp`` file, or the
        compiled script ignores a component.
    """
    psyexp = Path(psyexp)
    if psyexp.suffix != ".psyexp" or not psyexp.is_file():
        raise ValidationError(f"not a Builder experiment file (.psyexp): {psyexp}")
    out = psyexp.with_suffix(".py") if out is None else Path(out)
    if out.suffix != ".py":
        raise ValidationError(f"the compiled script must be a .py file, got {out}")
    try:
        from psychopy import plugins
    except ImportError as exc:
        raise ValidationError("compiling a Builder experiment needs PsychoPy in this Python: pip install "
                              f"'vibrofocus[psychopy]', or install vibrofocus into PsychoPy's own Python ({exc})"
                              ) from None
    # The Builder app activates plugins at start; PsychoPy's shell compiler does not.
    plugins.activatePlugins()
    from psychopy.experiment import Experiment, components

    if COMPONENT not in components.getAllComponents():
        raise ValidationError(f"PsychoPy did not load vibrofocus's {COMPONENT}: is vibrofocus installed in the "
                              "Python that runs PsychoPy (its entry point psychopy.experiment.components)?")
    exp = Experiment()
    try:
        exp.loadFromXML(str(psyexp))
    except Exception as exc:  # noqa: BLE001 - PsychoPy raises many kinds for a bad file
        raise ValidationError(f"PsychoPy could not read {psyexp}: {exc}") from None
    script = exp.writeScript(expPath=str(out), target="PsychoPy")
    text = script if isinstance(script, str) else script.getvalue()
    ignored = sorted(set(_IGNORED.findall(text)))
    if ignored:
        raise ValidationError(f"PsychoPy ignored component(s) {', '.join(ignored)} of {psyexp}: their plugin is not "
                              "installed in this Python; nothing was written")
    write_text(out, text, what="compiled experiment")
    return out
