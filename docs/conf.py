"""Sphinx configuration of the cmosnoise documentation (built by .ci/run: ``python -m sphinx -W docs docs/_build/html``).

Sphinx with MyST (the pages are Markdown, read on GitHub as they are), numpydoc (the docstrings' sections),
autosummary (the API reference of everything in ``cmosnoise.__all__``) and sphinx-gallery (the paper's
figures, made by running ``docs/examples``), as scikit-image does: see docs/development.md for why.
"""

import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE / "_ext"))

import cmosnoise  # noqa: E402

project = "cmosnoise"
author = "the cmosnoise developers"
copyright = "2026, the cmosnoise developers"
release = version = cmosnoise.__version__

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.mathjax",
    "numpydoc",
    "sphinx_gallery.gen_gallery",
    "cmosnoise_commands",
]
source_suffix = {".md": "markdown", ".rst": "restructuredtext"}
root_doc = "index"
exclude_patterns = ["_build", "numbers", "Thumbs.db", ".DS_Store", "examples/README.txt"]
myst_enable_extensions = ["colon_fence", "dollarmath"]
myst_heading_anchors = 3
smartquotes = False  # --set stays two hyphens, not a dash
suppress_warnings = ["myst.header"]  # the model document numbers its own sections (it starts at level 2)

autosummary_generate = True
templates_path = ["_templates"]  # a module's page shows every public function and class in full (numpydoc sections)
numpydoc_show_class_members = False
numpydoc_validation_checks = set()  # the doctests are run by tests/test_docs.py

sphinx_gallery_conf = {
    "examples_dirs": "examples",
    "gallery_dirs": "auto_examples",
    "filename_pattern": r"/plot_",
    "download_all_examples": False,
    "remove_config_comments": True,
    "within_subsection_order": "FileNameSortKey",
    "image_scrapers": ("cmosnoise_scraper.figure_records",),
}

html_theme = "pydata_sphinx_theme"
html_title = f"cmosnoise {release}"
html_static_path = []
html_theme_options = {"navigation_depth": 2, "show_toc_level": 2}
