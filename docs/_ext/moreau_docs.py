"""Sphinx extension of the moreau documentation: the checks that make a gap a build error.

With ``sphinx-build -W`` every warning below fails the build (docs/_tools/build_site.py):

* a public Python object (function, class, method, property, attribute) rendered by autodoc
  without a docstring;
* a public C++ header (include/moreau/**, and the generated moreau/version.hpp) that no
  ``doxygenfile`` directive of the C++ API pages renders. (Undocumented C++ functions and
  classes are Doxygen's own warnings, which build_site.py treats as errors.)

It also registers the ``output`` code-block language: expected output shown after a command
or a Python block in the tutorials, rendered as plain text and checked by
docs/_tools/run_tutorials.py.

And it makes breathe's ``doxygenfile`` render a header's namespace members without a
declaration of the namespace itself. Breathe renders the members of namespace ``moreau``
defined in a file inside a declaration of that namespace, with the same id on every page: with
one page per group of headers that is a duplicate declaration per page (an error under -W).
The members keep their fully qualified names (``moreau::SimulateFesd``), so cross-references
are unchanged. (breathe 4.34, Debian 12; the build fails loudly if a later breathe changes
what this relies on.)
"""

from __future__ import annotations

import re
from pathlib import Path

from breathe.renderer.sphinxrenderer import SphinxRenderer, WithContext
from pygments.lexers.special import TextLexer
from sphinx.domains.cpp import CPPDomain
from docutils import nodes
from sphinx import addnodes
from sphinx.application import Sphinx
from sphinx.util import logging

logger = logging.getLogger(__name__)

_DOCS = Path(__file__).resolve().parent.parent
_ROOT = _DOCS.parent
# ```{doxygenfile} moreau/core/dual.hpp  (MyST)  or  .. doxygenfile:: moreau/core/dual.hpp
_DOXYGENFILE = re.compile(r"(?:\{doxygenfile\}|doxygenfile::)\s+(\S+)")


def _public_headers() -> list[str]:
    include = _ROOT / "include"
    headers = sorted(str(p.relative_to(include)) for p in include.rglob("*.h*") if p.is_file())
    return headers + ["moreau/version.hpp"]  # generated from cmake/version.hpp.in


def _rendered_headers() -> set[str]:
    rendered: set[str] = set()
    for page in (_DOCS / "api").rglob("*.md"):
        rendered.update(_DOXYGENFILE.findall(page.read_text(encoding="utf-8")))
    return rendered


def _check_cpp_coverage(app: Sphinx) -> None:
    rendered = _rendered_headers()
    for header in _public_headers():
        if header not in rendered:
            logger.warning(
                "public header %s is in no C++ API page: add a doxygenfile directive for it "
                "to a page in docs/api/", header, type="moreau", subtype="cpp_coverage")
    for header in sorted(rendered - set(_public_headers())):
        logger.warning("the C++ API pages render %s, which is not a public header", header,
                       type="moreau", subtype="cpp_coverage")


def _check_docstring(app: Sphinx, what: str, name: str, obj, options, lines: list[str]) -> None:
    short = name.rsplit(".", 1)[-1]
    if short.startswith("_") or what == "module":
        return
    if not any(line.strip() for line in lines):
        logger.warning("undocumented Python API: %s %s (add a docstring)", what, name,
                       type="moreau", subtype="python_coverage")


def _run_cpp_directive(self, name: str, argument: str) -> None:
    """Runs the C++ domain's directive `name` (namespace-push or namespace-pop) in the context of
    the doxygenfile directive being rendered."""
    args = self.context.directive_args
    directive = CPPDomain.directives[name](
        f"cpp:{name}", [argument] if argument else [], {}, [], *args[4:])
    directive.run()


def _visit_namespace_members_only(self, node):
    """SphinxRenderer.visit_namespace without the namespace's own declaration (see above): the
    members are rendered as breathe renders them inside that declaration (one nesting level
    down, names relative to the namespace), with the namespace pushed as the C++ scope, as
    `cpp:namespace-push` does, instead of declared."""
    file_data = self.compound_parser.parse(node.refid)
    parent_context = self.context.create_child_context(file_data)
    new_context = parent_context.create_child_context(file_data.compounddef)
    _run_cpp_directive(self, "namespace-push", file_data.compounddef.compoundname)
    self.nesting_level += 1
    try:
        with WithContext(self, new_context):
            rendered = self.render(file_data, parent_context)
        # A member group (`@name ... @{`) of the namespace in another header renders as its
        # title and description with no members here: leave such empty sections out.
        return [n for n in rendered
                if not (isinstance(n, nodes.container) and "breathe-sectiondef" in n["classes"]
                        and not any(True for _ in n.findall(addnodes.desc)))]
    finally:
        self.nesting_level -= 1
        _run_cpp_directive(self, "namespace-pop", "")


def setup(app: Sphinx) -> dict:
    SphinxRenderer.visit_namespace = _visit_namespace_members_only
    app.add_lexer("output", TextLexer)
    app.connect("builder-inited", _check_cpp_coverage)
    app.connect("autodoc-process-docstring", _check_docstring)
    return {"version": "1", "parallel_read_safe": True, "parallel_write_safe": True}
