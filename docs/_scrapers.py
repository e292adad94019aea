"""sphinx-gallery scraper for the figures vibrofocus builds without pyplot."""

from __future__ import annotations


def figures_in_globals(block, block_vars, gallery_conf):
    """Save the matplotlib Figures an example holds in a variable and that pyplot does
    not manage (the analysis figures are built without pyplot, so matplotlib's scraper
    does not see them)."""
    from matplotlib.figure import Figure
    from sphinx_gallery.scrapers import figure_rst

    shown = block_vars.setdefault("_vibrofocus_shown", set())
    paths = []
    for value in list(block_vars["example_globals"].values()):
        if isinstance(value, Figure) and id(value) not in shown and value.canvas.manager is None:
            shown.add(id(value))
            path = next(block_vars["image_path_iterator"])
            value.savefig(path, dpi=90)
            paths.append(path)
    return figure_rst(paths, gallery_conf["src_dir"])
