"""The registry of rendering methods: names to :class:`~.method.Method` classes.

The six methods of docs/method.md ("Rendering methods") are registered when the package loads. A lab adds its own
with :func:`register_method`, or from an installed package through the entry-point group
``vibrofocus.methods`` (each entry point names a ``Method`` subclass; its name is the
method's name), read the first time the registry is asked. :func:`render`, the CLI, the
web app, the study engine and the demo list and find methods here.
"""

from __future__ import annotations

import dataclasses
import warnings
from importlib.metadata import entry_points
from typing import Any

from .._validation import check_choice, check_positive
from ..defaults import METHODS
from ..errors import ValidationError
from ._checks import check_regularization
from .method import Method
from .methods import CONTROL_SETS, Combination, Constrained, Contrast, Funneling, Inverse, Minimax, TimeReversal

__all__ = ["ENTRY_POINT_GROUP", "register_method", "method_class", "available_methods", "default_methods",
           "make_method"]

#: Entry-point group of the methods installed packages add.
ENTRY_POINT_GROUP = "vibrofocus.methods"

_REGISTRY: dict[str, type[Method]] = {}
_entry_points_read = False

#: The keyword arguments ``render`` took before methods were objects: given to a method
#: that has no such option, they are ignored as they were then (callers pass one set of
#: options to every method), apart from the few that only made sense for some methods.
LEGACY_OPTIONS = frozenset({
    "limit_v", "on_limit", "sigma", "target_peak_m", "regularization", "reg_param", "band", "t0", "control",
    "funneling_law", "funneling_amplitude_v", "taper_octaves", "form", "check_wraparound", "wraparound_tol",
    "guard_weight", "scale_to_limit", "exact_target", "contrast_weight", "min_contrast_db", "acc_reg", "field",
    "field_xy", "field_exclusion_m", "bounds", "min_fidelity", "support_s", "drive_budget", "taper_ends",
})


def register_method(name: str, cls: type[Method] | None = None, *, replace: bool = False):
    """Register a :class:`~.method.Method` subclass under ``name``.

    Parameters
    ----------
    name : str
        The name users give (``render(name, ...)``, ``--method name``).
    cls : type, optional
        The class; omitted, ``register_method(name)`` is a class decorator.
    replace : bool
        Allow replacing a method already registered under ``name``.

    Returns
    -------
    type
        ``cls``; its ``name`` (what ``Design.method`` says) is ``name`` unless the class
        was registered under another name before.
    """
    if not isinstance(name, str) or not name.isidentifier():
        raise ValidationError(f"a method's name must be an identifier (letters, digits, _), got {name!r}")

    def add(cls: type[Method]) -> type[Method]:
        if not (isinstance(cls, type) and issubclass(cls, Method) and dataclasses.is_dataclass(cls)):
            raise ValidationError(f"method {name!r} must be a dataclass subclass of vibrofocus.rendering.Method, "
                                  f"got {cls!r}")
        if name in _REGISTRY and _REGISTRY[name] is not cls and not replace:
            raise ValidationError(f"a method named {name!r} is registered already ({_REGISTRY[name].__name__}); "
                                  "pass replace=True to replace it")
        if "name" not in vars(cls):  # its first name (a subclass names itself anew)
            cls.name = name
        _REGISTRY[name] = cls
        return cls

    return add if cls is None else add(cls)


def _read_entry_points() -> None:
    """Register the methods of installed packages (once); a broken one is skipped with a warning."""
    global _entry_points_read
    if _entry_points_read:
        return
    _entry_points_read = True
    for ep in entry_points(group=ENTRY_POINT_GROUP):
        if ep.name in _REGISTRY:
            continue
        try:
            register_method(ep.name, ep.load())
        except Exception as exc:  # a third-party package must not break the toolkit
            warnings.warn(f"rendering method {ep.name!r} from entry point {ep.value!r} was not loaded: {exc}",
                          RuntimeWarning, stacklevel=2)


def available_methods() -> tuple[str, ...]:
    """Names of the registered methods: the built-in ones first, in the
    order docs/method.md gives them."""
    _read_entry_points()
    return tuple(_REGISTRY)


def default_methods() -> tuple[str, ...]:
    """Names of the registered methods a default run (the demo's table) renders: all but the
    opt-in ones (:attr:`~.method.Method.opt_in`, e.g. ``"minimax"``)."""
    return tuple(name for name in available_methods() if not _REGISTRY[name].opt_in)


def method_class(name: str) -> type[Method]:
    """The class registered under ``name``.

    Parameters
    ----------
    name : str
        A registered method's name.

    Returns
    -------
    type
        Its :class:`~.method.Method` subclass.

    Raises
    ------
    ValidationError
        For a name nothing is registered under (the message lists the known names).
    """
    check_choice(name, "method", available_methods())
    return _REGISTRY[name]


def make_method(name: str, **options: Any) -> Method:
    """An instance of the method ``name`` with ``options``.

    Parameters
    ----------
    name : str
        A registered method's name.
    **options
        Its options (fields of its class). Options of the former ``render`` that this
        method does not have are ignored (``LEGACY_OPTIONS``), their values still checked;
        any other unknown option is refused.

    Returns
    -------
    Method
    """
    cls = method_class(name)
    fields = {f.name for f in dataclasses.fields(cls) if f.init}
    if name != "constrained" and "contrast_weight" not in fields and (
            options.get("contrast_weight") is not None or options.get("min_contrast_db") is not None):
        raise ValidationError("contrast_weight and min_contrast_db are options of method='constrained'")
    if options.get("control") == "field" and "field" not in fields:
        raise ValidationError(f"control='field' is for the contrast designs (contrast, constrained), not {name!r}")
    unknown = sorted(set(options) - fields - LEGACY_OPTIONS)
    if unknown:
        raise ValidationError(f"method {name!r} has no option {', '.join(unknown)}; its options are "
                              f"{', '.join(sorted(fields))}")
    _check_ignored({k: v for k, v in options.items() if k not in fields})
    return cls(**{k: v for k, v in options.items() if k in fields})


def _check_ignored(ignored: dict[str, Any]) -> None:
    """Refuse a bad value of an option the method ignores, as ``render`` always did: a
    typo there is a mistake in the caller's settings whichever method it meets first."""
    if "regularization" in ignored or "reg_param" in ignored:
        check_regularization(ignored.get("regularization"), ignored.get("reg_param"))
    if "control" in ignored and ignored["control"] is not None:
        check_choice(ignored["control"], "control", CONTROL_SETS)
    if "guard_weight" in ignored:
        check_positive(ignored["guard_weight"], "guard_weight")
    if "acc_reg" in ignored:
        check_positive(ignored["acc_reg"], "acc_reg", allow_zero=True)


for _name, _cls in zip(METHODS, (Funneling, Inverse, Combination, TimeReversal, Contrast, Constrained)):
    register_method(_name, _cls)
register_method("minimax", Minimax)
