# Sphinx configuration of the moreau documentation site. Build it with `scripts/docs` (which runs
# docs/_tools/build_site.py: Doxygen for the C++ API, then Sphinx with warnings as errors); the
# test suite builds it the same way (ctest: docs.site).
#
# Environment set by build_site.py:
#   MOREAU_DOXYGEN_XML  Doxygen's XML output for breathe (the C++ API pages)
#   PYTHONPATH          the built Python package (autodoc imports `moreau`)
import os
import sys
from pathlib import Path

DOCS = Path(__file__).resolve().parent
ROOT = DOCS.parent
sys.path.insert(0, str(DOCS / "_ext"))

project = "moreau"
author = "the moreau authors"
copyright = "2026, the moreau authors (BSD 3-Clause licence)"
release = (ROOT / "VERSION").read_text().strip()  # the one version number
version = release

extensions = [
    "myst_parser",
    "breathe",
    "sphinx.ext.autodoc",
    "moreau_docs",  # docs/_ext/moreau_docs.py: coverage checks, the `output` lexer
]

source_suffix = {".md": "markdown", ".rst": "restructuredtext"}
root_doc = "index"
# report/report.md is the work-precision report as scripts/report writes it; the benchmarks page
# carries the same section. _tools holds the build and tutorial-runner scripts.
exclude_patterns = ["_build", "_tools", "_ext", "report/report.md", "**/README.md"]

# Markdown: heading anchors for links like [x](page.md#a-section), ::: fences, definition lists.
myst_heading_anchors = 4
myst_enable_extensions = ["colon_fence", "deflist"]

# C++ API reference: breathe over Doxygen's XML.
breathe_projects = {"moreau": os.environ.get("MOREAU_DOXYGEN_XML", str(ROOT / "build/docs/xml"))}
breathe_default_project = "moreau"
breathe_default_members = ("members",)
breathe_show_include = True
cpp_index_common_prefix = ["moreau::"]

# Python API reference: autodoc over the built package, in source order.
autodoc_member_order = "bysource"
autodoc_typehints = "signature"
autodoc_default_options = {"members": True, "undoc-members": True, "show-inheritance": False}

html_theme = "furo"
html_title = f"moreau {release}"
html_static_path = []
html_last_updated_fmt = None
html_show_sourcelink = False
pygments_style = "friendly"
