"""The ``vibrofocus`` command line.

Each command lives in its own module of this subpackage; :func:`.commands.register`
adds them to ``app`` in a fixed order (the modules never import this one).
Command modules import only typer at module level; heavy dependencies (matplotlib,
pingouin, FastAPI) are imported inside the command so ``vibrofocus --help`` stays fast.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from typing import Any

import typer
from typer.core import TyperGroup

from .. import __version__
from ._errors import EXIT_INTERRUPTED, EXIT_USER_ERROR, err_console, print_error, report_unexpected, set_debug


class _OneLineErrors(TyperGroup):
    """The root command group: every way a command ends is one line and an exit code.

    - A usage error (``--location abc``) is one ``error:`` line, exit 2; typer draws it
      in a multi-line box, here the message names the command and the option, and
      points at ``--help``.
    - An unexpected exception (a bug, or a case no check foresaw) is one ``error:``
      line naming the log file that holds the traceback, exit 1
      (:func:`._errors.report_unexpected`); ``vibrofocus --debug`` prints it too.

    - A closed pipe (``vibrofocus --help | head -1``) ends quietly, exit 141.

    Only typer's public exceptions are used: ``typer.Abort``, and
    ``typer.TyperException`` with its ``exit_code`` and ``format_message()`` (a usage
    error has exit code 2 and a context).
    """

    def main(
        self,
        args: Sequence[str] | None = None,
        prog_name: str | None = None,
        complete_var: str | None = None,
        standalone_mode: bool = True,
        windows_expand_args: bool = True,
        **extra: Any,
    ) -> Any:
        _plain_help(self)
        _line_buffered()
        if not standalone_mode:
            return super().main(args, prog_name, complete_var, standalone_mode, windows_expand_args, **extra)
        try:
            rv = super().main(args, prog_name, complete_var, False, windows_expand_args, **extra)
        except typer.Abort as exc:  # raised by click for Ctrl-C or end of input at a prompt
            cause = exc.__cause__ or exc.__context__
            if isinstance(cause, KeyboardInterrupt):
                err_console.print("[bold yellow]interrupted[/]", highlight=False)
                sys.exit(EXIT_INTERRUPTED)
            if isinstance(cause, EOFError):
                typer.echo()  # end the prompt's line
                print_error("the input ended (end of file) while a prompt waited for an answer; run it at a terminal")
                sys.exit(EXIT_USER_ERROR)
            err_console.print("aborted", highlight=False)
            sys.exit(1)
        except typer.TyperException as exc:  # click's ClickException and UsageError
            ctx = getattr(exc, "ctx", None)
            if exc.exit_code == EXIT_USER_ERROR:
                where = ctx.command_path if ctx is not None else "vibrofocus"
                print_error(f"{where}: {exc.format_message()}{_hint(where, exc)} (see '{where} --help')")
            else:
                print_error(exc.format_message())
            sys.exit(exc.exit_code)
        except KeyboardInterrupt:
            err_console.print("[bold yellow]interrupted[/]", highlight=False)
            sys.exit(EXIT_INTERRUPTED)
        except BrokenPipeError:
            _quiet_after_closed_pipe()
        except Exception:  # noqa: BLE001 - the last resort: one line and a log, never a bare traceback
            sys.exit(report_unexpected())
        sys.exit(rv if isinstance(rv, int) else 0)


#: Options people look for under another command: (command path's end, option) -> where it is.
_OPTION_HINTS = {
    ("study export", "--bids"): "a BIDS dataset is written by 'vibrofocus export SRC --bids DIR' (SRC: the study "
                                "database or a trials CSV)",
}


def _hint(where: str, exc: Exception) -> str:
    """``"; <hint>"`` for an unknown option that another command has, else ``""``."""
    option = getattr(exc, "option_name", None)
    for (command_end, name), hint in _OPTION_HINTS.items():
        if option == name and where.endswith(command_end):
            return f"; {hint}"
    return ""


#: Exit status of a command whose reader closed the pipe (128 + SIGPIPE, as ``git log | head``).
EXIT_CLOSED_PIPE = 141


def _quiet_after_closed_pipe() -> None:
    """End quietly when the reader of stdout went away (``vibrofocus --help | head -1``).

    What is still buffered for stdout goes to /dev/null, so Python's own flush at exit
    cannot print a second error either.
    """
    import os

    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError):  # stdout is not a real file (a test runner's capture)
        pass
    sys.exit(EXIT_CLOSED_PIPE)


def _line_buffered() -> None:
    """Flush each line of output when it is not a terminal (a log, CI, ``| tee``): Python
    buffers such output in blocks, so a long command showed nothing for minutes."""
    for stream in (sys.stdout, sys.stderr):
        reconfigure = getattr(stream, "reconfigure", None)
        try:
            if reconfigure is not None and not stream.isatty():
                reconfigure(line_buffering=True)
        except (OSError, ValueError):  # a closed or detached stream: nothing to buffer
            pass


def _plain_help(group: Any) -> None:
    """Help that shows what it says: brackets kept, no value placeholder after a flag.

    - Typer reads help texts as Rich markup, so ``pip install 'vibrofocus[lsl]'`` lost
      its ``[lsl]`` and ``[seed, N, j]`` vanished; no help here uses markup, so every
      command's and option's help is escaped (:func:`rich.markup.escape`).
    - A flag takes no value: ``--force <bool>`` reads as if it wanted one. An empty
    ``metavar`` (the option's public attribute, which typer's help shows in place of the
    type) leaves the column blank, for every command, sub-command and their ``--help``.
    Typer carries its own copy of click, so the options are recognised by their
    attributes, not by class.
    """
    from rich.markup import escape

    todo = [group]
    while todo:
        cmd = todo.pop()
        if getattr(cmd, "_vibrofocus_plain", False):
            continue  # escaped once: a second pass would escape the escapes
        cmd._vibrofocus_plain = True
        if cmd.help:
            cmd.help = escape(cmd.help)
        help_option = cmd.get_help_option(cmd.context_class(cmd))
        for param in [*cmd.params, *([help_option] if help_option is not None else [])]:
            if getattr(param, "help", None):
                param.help = escape(param.help)
            if getattr(param, "is_flag", False) and getattr(param, "metavar", "") is None:
                param.metavar = ""
        todo.extend(getattr(cmd, "commands", {}).values())


app = typer.Typer(
    cls=_OneLineErrors,
    name="vibrofocus",
    help="Focused vibrotactile stimuli on sparse actuator arrays: calibrate, render, run studies, analyse.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_show_locals=False,
)


def _version_callback(value: bool) -> None:
    if value:
        typer.echo(f"vibrofocus {__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    version: bool = typer.Option(
        False, "--version", callback=_version_callback, is_eager=True, help="Print the version and exit."
    ),
    debug: bool = typer.Option(
        False, "--debug", help="Show the Python traceback under an error message (for bug reports)."
    ),
) -> None:
    """Focused vibrotactile stimuli on sparse actuator arrays."""
    set_debug(debug)


from .commands import register  # noqa: E402

register(app)
