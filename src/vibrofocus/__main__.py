"""``python -m vibrofocus`` and the ``vibrofocus`` command: a plain ``stop`` first, then the CLI."""

import sys


def main() -> None:
    """Run the command line; ``vibrofocus stop [--db PATH]`` answers before typer and the CLI load."""
    from ._stop_client import main as stop_now

    code = stop_now(sys.argv[1:])
    if code is not None:
        sys.exit(code)
    from .cli.main import app

    app(prog_name="vibrofocus")


if __name__ == "__main__":
    main()
