"""Deprecated names kept for one release, each warning when used (one rule for every module).

A module lists its former names and where they went; its ``__getattr__`` (PEP 562) is
:func:`module_getattr`, which warns with a :class:`DeprecationWarning` naming the new name
and returns it. Former names never appear in ``__all__``. Why each was renamed or
deprecated: DEVELOPING.md, "Names".
"""

from __future__ import annotations

import importlib.abc
import importlib.util
import sys
import types
import warnings
from collections.abc import Callable
from importlib import import_module
from pathlib import Path
from typing import Any

__all__ = ["REMOVED_IN", "module_getattr", "warn_deprecated", "warn_if_imported_from_outside", "alias_submodules"]

#: The release that drops the deprecated names.
REMOVED_IN = "0.3"


def warn_deprecated(old: str, new: str, *, stacklevel: int = 3) -> None:
    """Warn that ``old`` is deprecated in favour of ``new`` (a :class:`DeprecationWarning`)."""
    warnings.warn(f"{old} is deprecated and will be removed in vibrofocus {REMOVED_IN}; use {new}",
                  DeprecationWarning, stacklevel=stacklevel)


def module_getattr(module: str, former: dict[str, tuple[str, str, str]],
                   fallback: Callable[[str], Any] | None = None) -> Callable[[str], Any]:
    """A module ``__getattr__`` that serves former names with a warning.

    Parameters
    ----------
    module : str
        The module's dotted name (``__name__``), for messages.
    former : dict
        ``{old_name: (new_module, new_name, advice)}``: the object ``new_name`` of the
        module ``new_module`` (absolute, dotted), and what the warning tells to use.
    fallback : callable, optional
        The module's own look-up for other names; without it they raise AttributeError.
    """

    def __getattr__(name: str) -> Any:
        if name in former:
            new_module, new_name, advice = former[name]
            warn_deprecated(f"{module}.{name}", advice)
            return getattr(import_module(new_module), new_name)
        if fallback is not None:
            return fallback(name)
        raise AttributeError(f"module {module!r} has no attribute {name!r}")

    return __getattr__


def warn_if_imported_from_outside(module: str, new: str) -> None:
    """Warn that the module ``module`` is deprecated for ``new``, when a module outside vibrofocus imports it.

    Called from a module's body. The project's own code (the package, ``vibrofocus_tools``
    and the checkout's ``scripts/``) may still import the former path: code that other work
    is editing moves later. A user's ``import`` of it warns. Like any module-level
    deprecation, it warns at the module's first import in a process.
    """
    frame = sys._getframe(2)
    while frame is not None and frame.f_code.co_filename.startswith("<frozen importlib"):
        frame = frame.f_back
    if frame is None or not _is_the_projects(frame.f_globals):
        # warn_deprecated, this function, the module's body, then the importer (the
        # warnings module skips importlib's own frames).
        warn_deprecated(module, new, stacklevel=4)


#: The checkout's scripts (src/vibrofocus/_deprecated.py -> the repository root); absent from a wheel.
_SCRIPTS = Path(__file__).resolve().parents[2] / "scripts"


def _is_the_projects(module_globals: dict[str, Any]) -> bool:
    """Whether an importing module is the project's own: vibrofocus, its tools or one of its scripts."""
    name = str(module_globals.get("__name__", ""))
    if name.split(".")[0] in ("vibrofocus", "vibrofocus_tools"):
        return True
    path = module_globals.get("__file__")
    return isinstance(path, str) and Path(path).resolve().parent == _SCRIPTS


class _AliasFinder(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Imports ``new.x`` as a view of ``old.x``: a module whose attributes are the real one's."""

    def __init__(self, new: str, old: str) -> None:
        self.new, self.old = new, old

    def find_spec(self, fullname: str, path: Any = None, target: Any = None):
        if not fullname.startswith(self.new + "."):
            return None
        real = import_module(self.old + fullname[len(self.new):])
        return importlib.util.spec_from_loader(fullname, self, is_package=hasattr(real, "__path__"))

    def exec_module(self, module: types.ModuleType) -> None:
        real = import_module(self.old + module.__name__[len(self.new):])
        module.__doc__ = real.__doc__
        module.__dict__.update({k: v for k, v in vars(real).items() if not k.startswith("__") or k == "__all__"})
        module.__getattr__ = lambda name: getattr(real, name)  # names the real module gains later


def alias_submodules(new: str, old: str) -> None:
    """Make ``import new.sub`` give the objects of ``old.sub`` (same classes and functions).

    For a package renamed while its files stay under the former name: ``new`` is a thin
    package that re-exports ``old``; its submodules are views of ``old``'s.
    """
    if not any(isinstance(f, _AliasFinder) and f.new == new for f in sys.meta_path):
        sys.meta_path.insert(0, _AliasFinder(new, old))
