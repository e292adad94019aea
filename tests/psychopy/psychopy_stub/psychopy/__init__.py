"""A STUB of PsychoPy for vibrofocus's tests: not PsychoPy (see ../README.md)."""

__version__ = "0.0.0-vibrofocus-stub"
__stub__ = True


class _Inert:
    """Any attribute, call, item or comparison: inert (for the parts of a compiled Builder
    script that a headless run does not need: dialogs, devices, logging, preferences)."""

    def __init__(self, *args, **kwargs):
        pass

    def __getattr__(self, name):
        if name.startswith("__"):
            raise AttributeError(name)
        return _Inert()

    def __call__(self, *args, **kwargs):
        return _Inert()

    def __getitem__(self, key):
        return _Inert()

    def __setitem__(self, key, value):
        pass

    def __bool__(self):
        return False

    def __iter__(self):
        return iter(())

    def __str__(self):
        return ""

    def __eq__(self, other):
        return isinstance(other, _Inert)

    def __hash__(self):
        return 0


def inert_module(name):
    """A module whose every attribute is inert."""
    import sys
    import types

    module = types.ModuleType(name)
    module.__getattr__ = lambda attr: _Inert()
    sys.modules[name] = module
    return module
