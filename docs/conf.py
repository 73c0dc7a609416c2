"""Sphinx configuration of bark's documentation site: the user guide (the Markdown pages of docs/,
read by MyST), the API reference from the docstrings (autodoc) and a gallery of examples executed at
each build (sphinx-gallery).  Built by ``sphinx-build -W -b html docs docs/_build/html`` (warnings
are errors), as ``tests/test_docs.py`` does."""

from __future__ import annotations

import os

from bark.version import __version__

project = "bark"
author = "The bark developers"
copyright = "2026, the bark developers"
release = __version__
version = ".".join(__version__.split(".")[:2])

extensions = ["myst_parser", "sphinx.ext.autodoc", "sphinx_gallery.gen_gallery"]
source_suffix = {".md": "markdown", ".rst": "restructuredtext"}
exclude_patterns = ["_build", "gallery/README.txt"]
myst_heading_anchors = 3
autodoc_member_order = "bysource"
autodoc_typehints = "none"  # the signatures carry the names; the docstrings say the units
html_theme = "alabaster"
html_title = f"bark {release}"

sphinx_gallery_conf = {
    "examples_dirs": "gallery",
    "gallery_dirs": "auto_examples",
    "filename_pattern": r"/plot_",
    "download_all_examples": False,
    "remove_config_comments": True,
    "matplotlib_animations": False,
}
os.environ.setdefault("MPLBACKEND", "Agg")
