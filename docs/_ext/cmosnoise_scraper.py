"""sphinx-gallery's picture scraper for cmosnoise's figure records (``cmosnoise.app.figures.Figure``: a PNG and
its caption): the library draws on ``matplotlib.figure.Figure`` objects, never through pyplot, so the matplotlib
scraper would find nothing."""

from __future__ import annotations


def figure_records(block, block_vars, gallery_conf):
    from sphinx_gallery.scrapers import figure_rst

    from cmosnoise.app.figures import Figure

    seen = block_vars.setdefault("_cmosnoise_seen", set())
    paths = []
    for value in list(block_vars["example_globals"].values()):
        if isinstance(value, Figure) and id(value) not in seen:
            seen.add(id(value))
            path = next(block_vars["image_path_iterator"])
            with open(path, "wb") as fh:
                fh.write(value.png)
            paths.append(path)
    return figure_rst(paths, gallery_conf["src_dir"])
