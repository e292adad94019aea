"""The one Jinja2 set-up for every HTML page (the web app's pages, the analysis report)."""

from __future__ import annotations

from functools import cache
from pathlib import Path
from typing import Any


@cache
def template_environment(folder: Path) -> Any:
    """A Jinja2 environment over the templates in ``folder``, built once per folder.

    Autoescaped, so every value is HTML-escaped (a participant id is always text), and
    strict: a value the template names but was not given is an error, not an empty string.
    """
    import jinja2  # imported here: most of vibrofocus renders no HTML

    return jinja2.Environment(loader=jinja2.FileSystemLoader(folder), autoescape=True, undefined=jinja2.StrictUndefined)
