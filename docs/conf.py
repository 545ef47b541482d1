"""Sphinx configuration of the mjcodesign documentation (``sphinx-build -W docs docs/_build/html``)."""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent / "_ext"))

project = "mjcodesign"
author = "mjcodesign contributors"
copyright = "2026, mjcodesign contributors"  # noqa: A001 (Sphinx's name)

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.mathjax",
    "sphinxarg.ext",
    "mjdocs",
]
source_suffix = {".md": "markdown", ".rst": "restructuredtext"}
exclude_patterns = ["_build", "_ext"]
myst_enable_extensions = ["colon_fence"]
myst_heading_anchors = 3

html_theme = "furo"
html_title = "mjcodesign"
html_static_path = ["_static"]

autodoc_typehints = "none"  # shapes and units are in the docstrings; signatures stay readable
autodoc_member_order = "bysource"
autodoc_default_options = {"undoc-members": False}
nitpicky = True
