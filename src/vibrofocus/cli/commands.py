"""The command modules, in the order ``vibrofocus --help`` lists them, and their registration on the app.

Registration is one-way: :mod:`.main` calls :func:`register`, which imports each module
of :data:`COMMAND_MODULES` and adds what it marks (:func:`._command.command`) and its
sub-apps (``SUB_APPS``, name to :class:`typer.Typer`). Command modules never import
:mod:`.main`.
"""

from __future__ import annotations

import importlib

import typer

from ._command import marked_commands

__all__ = ["COMMAND_MODULES", "register"]

#: Command modules of this package, in ``--help`` order.
COMMAND_MODULES = ("demo", "calibrate", "render", "serve", "serve_osc", "analyze", "study", "simulate_study", "export",
                   "power", "play", "latency", "devices")


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
            app.command(command_name, **options)(fn)
        for sub_name, sub_app in getattr(module, "SUB_APPS", {}).items():
            app.add_typer(sub_app, name=sub_name)
