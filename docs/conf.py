"""Sphinx configuration of the vibrofocus documentation.

Build: ``.venv/bin/python -m sphinx -W --keep-going -b html docs docs/_build/html`` (the
test suite does this, failing on warnings: tests/test_docs.py). The API pages are written
at build time from each subpackage's ``__all__``, so the reference lists exactly the public
API; the gallery runs the scripts in ``examples/``.
"""

from __future__ import annotations

import importlib
import shutil
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")

DOCS = Path(__file__).resolve().parent
ROOT = DOCS.parent
if (ROOT / "src" / "vibrofocus").is_dir():  # a checkout; a copy of docs/ uses the installed package
    sys.path.insert(0, str(ROOT / "src"))
sys.path.insert(0, str(DOCS))

import vibrofocus  # noqa: E402

project = "vibrofocus"
author = "the vibrofocus developers"
copyright = "the vibrofocus developers, GPL-3.0-or-later"  # noqa: A001
release = vibrofocus.__version__
version = release

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.mathjax",
    "numpydoc",
    "myst_parser",
    "sphinx_gallery.gen_gallery",
]
source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
exclude_patterns = ["_build", "figures/README.md"]
templates_path = ["_templates"]
root_doc = "index"

html_theme = "pydata_sphinx_theme"
html_title = "vibrofocus"
# A few links in the bar, the rest under "More": the bar fits on one line at 1280 px
# (checked in a real browser by tests/test_docs.py).
html_theme_options = {"navigation_with_keys": False, "show_toc_level": 2, "header_links_before_dropdown": 3}

myst_heading_anchors = 3
# Pages written for GitHub link to files outside the docs (the README, source files): those
# links stay links, not cross-references.
suppress_warnings = ["myst.xref_missing"]

autosummary_generate = True
autodoc_default_options = {"members": False}
numpydoc_show_class_members = False
numpydoc_class_members_toctree = False
numpydoc_xref_param_type = False

sphinx_gallery_conf = {
    # Before matplotlib's scraper, which closes pyplot figures (docs/_scrapers.py).
    "image_scrapers": ("_scrapers.figures_in_globals", "matplotlib"),
    "examples_dirs": str(ROOT / "examples"),
    "gallery_dirs": "auto_examples",
    "filename_pattern": r"/plot_",
    "download_all_examples": False,
    "remove_config_comments": True,
    "within_subsection_order": "FileNameSortKey",
    "abort_on_example_error": True,
    "show_memory": False,
    "min_reported_time": 1000,
    # The examples run two at a time, each in a process of its own (joblib): the docs phase
    # has the machine's two cores to itself.
    "parallel": 2,
}

# ---------------------------------------------------------------------------------------
# API pages: one per subpackage, listing its __all__ (written before the build reads them).
API_PACKAGES = {
    "vibrofocus": "Top level",
    "vibrofocus.layout": "Array layouts",
    "vibrofocus.io": "File formats",
    "vibrofocus.signals": "Signals",
    "vibrofocus.rendering": "Rendering",
    "vibrofocus.skin": "Simulated forearm (the physics)",
    "vibrofocus.calibration": "Calibration",
    "vibrofocus.rigs": "Rigs",
    "vibrofocus.studies": "Studies",
    "vibrofocus.participant_models": "Participant models (simulated participants)",
    "vibrofocus.realtime": "Real time (OSC taps, latency)",
    "vibrofocus.psychopy": "PsychoPy (taps in experiments)",
    "vibrofocus.analysis": "Analysis",
    "vibrofocus.demo": "Demo",
    "vibrofocus.errors": "Errors",
}


def _write_api_pages() -> None:
    api = DOCS / "api"
    # Stubs of names that left an __all__ would otherwise be read again (and fail to import).
    shutil.rmtree(api, ignore_errors=True)
    api.mkdir()
    toc = []
    for name, title in API_PACKAGES.items():
        module = importlib.import_module(name)
        public = sorted(getattr(module, "__all__", []), key=str.lower)
        if name == "vibrofocus":
            public = sorted(vibrofocus.__all__, key=str.lower)
        callables = [n for n in public if callable(getattr(module, n, None))]
        # The top level re-exports names documented on their subpackage's page: listed
        # here, described there (no second description).
        toctree = [] if name == "vibrofocus" else ["   :toctree: generated"]
        lines = [title, "=" * len(title), "", f".. currentmodule:: {name}", "",
                 f".. automodule:: {name}", "   :no-members:", "", ".. autosummary::", *toctree,
                 "   :nosignatures:", ""] + [f"   {n}" for n in callables] + [""]
        (api / f"{name}.rst").write_text("\n".join(lines), encoding="utf-8")
        toc.append(f"   {name}")
    index = "\n".join(["API reference", "=============", "",
                       "Everything a subpackage exports in ``__all__``; the numpydoc docstrings state units and "
                       "array shapes.", "", ".. toctree::", "   :maxdepth: 1", ""] + toc + [""])
    (api / "index.rst").write_text(index, encoding="utf-8")


_write_api_pages()


# ---------------------------------------------------------------------------------------
# The command-line reference, written from the CLI itself at build time so it cannot drift.
def _option_row(param) -> str:
    import click

    names = ", ".join(f"`{o}`" for o in [*param.opts, *param.secondary_opts])
    if isinstance(param, click.Argument):
        names = f"`{param.human_readable_name}`"
    default = param.default
    shown = "" if default is None or callable(default) or param.required else f"`{default}`"
    if isinstance(default, bool) and param.secondary_opts:
        shown = f"`{param.opts[0] if default else param.secondary_opts[0]}`"
    helptext = " ".join((getattr(param, "help", None) or "").split()).replace("|", "\\|")
    return f"| {names} | {helptext} | {'required' if param.required else shown} |"


def _write_cli_page() -> None:
    import typer.main

    from vibrofocus.cli.main import app

    root = typer.main.get_command(app)
    lines = ["# Command-line reference", "",
             "Written at build time from the command line itself (`vibrofocus COMMAND --help` says the "
             "same). Every command prints one `error:` line and exits 2 on bad input.", ""]
    for name, cmd in root.commands.items():
        lines += [f"## `vibrofocus {name}`", "", " ".join((cmd.help or "").split("\n\n")[0].split()), ""]
        rest = "\n\n".join(p.strip() for p in (cmd.help or "").split("\n\n")[1:])
        if rest:
            lines += [" ".join(par.split()) + "\n" for par in rest.split("\n\n")]
        params = [p for p in cmd.params if p.name != "help"]
        if params:
            lines += ["| option | what | default |", "|---|---|---|", *[_option_row(p) for p in params], ""]
        if cmd.epilog:
            lines += [" ".join(cmd.epilog.split()), ""]
    (DOCS / "cli.md").write_text("\n".join(lines), encoding="utf-8")


_write_cli_page()
