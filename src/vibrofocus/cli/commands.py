"""The command modules, in the order ``vibrofocus --help`` lists them, and their registration on the app.

Registration is one-way: :mod:`.main` calls :func:`register`, which imports each module
of :data:`COMMAND_MODULES` and adds what it marks (:func:`._command.command`) and its
sub-apps (``SUB_APPS``, name to :class:`typer.Typer`). Command modules never import
:mod:`.main`.
"""

from __future__ import annotations

import importlib
import inspect

import typer

from ._command import marked_commands

__all__ = ["COMMAND_MODULES", "register", "reflowed"]

#: Command modules of this package, in ``--help`` order.
COMMAND_MODULES = ("demo", "calibrate", "render", "serve", "stop", "serve_osc", "analyze", "study", "simulate_study", "export",
                   "power", "design_experiment", "design_layout", "play", "latency", "devices", "psychopy")


def register(app: typer.Typer) -> None:
    """Add every command of :data:`COMMAND_MODULES` to ``app``, in that order.

    Parameters
    ----------
    app : typer.Typer
        The root app.
    """
    for name in COMMAND_MODULES:
        module = importlib.import_module(f"{__package__}.{name}")
        for fn, command_name, options in marked_commands(module):
            app.command(command_name, **{"help": reflowed(fn.__doc__), **options})(fn)
        for sub_name, sub_app in getattr(module, "SUB_APPS", {}).items():
            for info in sub_app.registered_commands:
                if info.help is None and info.callback is not None:
                    info.help = reflowed(info.callback.__doc__)
            app.add_typer(sub_app, name=sub_name)


def reflowed(doc: str | None) -> str | None:
    """A command's docstring as its help: the lines of each paragraph joined, so the terminal
    wraps them (typer keeps the single line breaks of later paragraphs, and a wrapped help then
    shows a short line at each of the source's breaks). A paragraph of indented lines or list
    items stays as written.

    Parameters
    ----------
    doc : str or None

    Returns
    -------
    str or None
    """
    if not doc:
        return doc
    paragraphs = []
    for paragraph in inspect.cleandoc(doc).split("\n\n"):
        lines = paragraph.splitlines()
        if any(line.startswith(("    ", "- ", "* ", "\b", "\f")) for line in lines):
            paragraphs.append(paragraph)
        else:
            paragraphs.append(" ".join(line.strip() for line in lines))
    return "\n\n".join(paragraphs)
