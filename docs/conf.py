"""Sphinx configuration: the pages are Markdown (MyST), the tables that the code owns are made from it at build
time (``_ext/ckesc_docs.py``). Build: ``python -m sphinx -W --keep-going -b html docs docs/_build/html``."""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent / "_ext"))

import ckesc  # noqa: E402

project = "ckesc-conformance"
author = "the ckesc-conformance authors"
copyright = "the ckesc-conformance authors"
version = release = ckesc.__version__

extensions = ["myst_parser", "ckesc_docs"]
source_suffix = {".md": "markdown"}
exclude_patterns = ["_build"]
myst_enable_extensions = ["colon_fence", "deflist"]
myst_heading_anchors = 3
# command lines in prose keep their "--": no typographic dashes or quotes
smartquotes = False

html_theme = "furo"
html_title = f"ckesc-conformance {release}"
html_static_path: list[str] = []
