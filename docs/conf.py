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
html_theme_options = {"navigation_with_keys": False, "show_toc_level": 2}

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
}

# ---------------------------------------------------------------------------------------
# API pages: one per subpackage, listing its __all__ (written before the build reads them).
API_PACKAGES = {
    "vibrofocus": "Top level",
    "vibrofocus.layout": "Array layouts",
    "vibrofocus.io": "File formats",
    "vibrofocus.signals": "Signals",
    "vibrofocus.rendering": "Rendering",
    "vibrofocus.skin": "Simulated forearm",
    "vibrofocus.calibration": "Calibration",
    "vibrofocus.rigs": "Rigs",
    "vibrofocus.studies": "Studies",
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
