#!/usr/bin/python3
"""Builds the documentation site: Doxygen (C++ API, XML for breathe), then Sphinx (HTML).

    build_site.py --build-dir build/release --out build/release/docs/html

Every warning is an error: Doxygen's (an undocumented public function, class or member, a
malformed comment) and Sphinx's (a broken link or reference, a page in no table of contents, a
missing page, an undocumented Python object or an unrendered public header: docs/_ext/), and
a README link to a missing file or heading (the README is no page of the site). The
build is always complete (no incremental state), so that a warning is never hidden by a cache.
Used by `scripts/docs`, the CMake target `docs` and the test `docs.site`. Debian packages only:
doxygen, python3-sphinx, python3-breathe, python3-myst-parser, furo (scripts/bootstrap).
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
DOCS = ROOT / "docs"

DOXYFILE = """
PROJECT_NAME           = moreau
INPUT                  = {include}/moreau {generated}/moreau/version.hpp
FILE_PATTERNS          = *.hpp *.h
RECURSIVE              = YES
STRIP_FROM_PATH        = {include} {generated}
STRIP_FROM_INC_PATH    = {include} {generated}
FULL_PATH_NAMES        = YES
OUTPUT_DIRECTORY       = {work}
GENERATE_HTML          = NO
GENERATE_LATEX         = NO
GENERATE_XML           = YES
XML_OUTPUT             = xml
XML_PROGRAMLISTING     = NO
EXTRACT_ALL            = NO
EXTRACT_PRIVATE        = NO
EXTRACT_STATIC         = YES
HIDE_UNDOC_CLASSES     = NO
WARN_IF_UNDOCUMENTED   = YES
WARN_IF_DOC_ERROR      = YES
WARN_IF_INCOMPLETE_DOC = NO
WARN_NO_PARAMDOC       = NO
WARN_LOGFILE           = {work}/doxygen-warnings.txt
QUIET                  = YES
JAVADOC_AUTOBRIEF      = YES
MARKDOWN_SUPPORT       = YES
DISTRIBUTE_GROUP_DOC   = YES
ENABLE_PREPROCESSING   = YES
MACRO_EXPANSION        = YES
EXPAND_ONLY_PREDEF     = NO
SKIP_FUNCTION_MACROS   = YES
# The C header's `typedef enum moreau_status ... moreau_status;`: one entity, not an enum and
# a typedef of the same name (a duplicate declaration for Sphinx).
TYPEDEF_HIDES_STRUCT   = YES
# Implementation details and the using-declarations that put moreau's math into namespace std
# (dual.hpp) are not API: they stay out of the reference.
EXCLUDE_SYMBOLS        = internal moreau::internal std Eigen detail MOREAU_DECLARE_MATH_IN_STD \
                         MOREAU_DUAL_* MOREAU_TRACER_* MOREAU_INTERVAL_*
"""


def _slug(heading: str) -> str:
    """GitHub's (and MyST's) anchor of a Markdown heading."""
    text = re.sub(r"[^\w\- ]", "", heading.strip().lower())
    return text.replace(" ", "-")


def check_readme_links() -> list[str]:
    """The README is GitHub's front page, not a page of the site: Sphinx does not see it, so
    its relative links (files, and headings of Markdown files) are checked here."""
    problems = []
    readme = ROOT / "README.md"
    for number, line in enumerate(readme.read_text(encoding="utf-8").splitlines(), 1):
        for target in re.findall(r"\]\(([^)\s]+)\)", line):
            if re.match(r"[a-z]+:", target):
                continue  # an absolute URL
            path, _, anchor = target.partition("#")
            file = ROOT / path
            if not file.exists():
                problems.append(f"README.md:{number}: link to a missing file: {target}")
            elif anchor and file.suffix == ".md":
                headings = {_slug(h.lstrip("#")) for h in file.read_text(encoding="utf-8")
                            .splitlines() if h.startswith("#")}
                if anchor not in headings:
                    problems.append(f"README.md:{number}: no heading #{anchor} in {path}")
    return problems


def run(command: list[str], env: dict[str, str] | None = None) -> None:
    result = subprocess.run(command, env=env, check=False)
    if result.returncode != 0:
        sys.exit(f"build_site: failed ({result.returncode}): {' '.join(command)}")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--build-dir", required=True, type=Path,
                        help="a configured and built moreau build tree (its python/ package and "
                             "its generated include/moreau/version.hpp)")
    parser.add_argument("--out", required=True, type=Path, help="HTML output directory")
    args = parser.parse_args()
    build = args.build_dir.resolve()
    out = args.out.resolve()
    generated = build / "include"
    if not (generated / "moreau" / "version.hpp").is_file():
        sys.exit(f"build_site: {generated}/moreau/version.hpp is missing: configure {build} first")
    if not (build / "python" / "moreau").is_dir():
        sys.exit(f"build_site: {build}/python/moreau is missing: build the Python package first")
    for tool in ("doxygen", "sphinx-build"):
        if shutil.which(tool) is None:
            sys.exit(f"build_site: {tool} not found: run scripts/bootstrap (Debian packages "
                     "doxygen, python3-sphinx, python3-breathe, python3-myst-parser, furo)")

    problems = check_readme_links()
    if problems:
        sys.exit("build_site: broken links in the README:\n" + "\n".join(problems))

    work = out.parent / (out.name + "-work")
    shutil.rmtree(work, ignore_errors=True)
    work.mkdir(parents=True)
    started = time.monotonic()

    (work / "Doxyfile").write_text(
        DOXYFILE.format(include=ROOT / "include", generated=generated, work=work))
    run(["doxygen", str(work / "Doxyfile")])
    warnings = (work / "doxygen-warnings.txt").read_text().strip()
    if warnings:
        print(warnings, file=sys.stderr)
        count = len(warnings.splitlines())
        sys.exit(f"build_site: Doxygen reported {count} warning line(s) (above): every public "
                 "function, class and member of include/moreau/ needs a /// comment")

    env = dict(os.environ)
    env["MOREAU_DOXYGEN_XML"] = str(work / "xml")
    env["PYTHONPATH"] = os.pathsep.join(
        [str(build / "python")] + ([env["PYTHONPATH"]] if env.get("PYTHONPATH") else []))
    env["PYTHONDONTWRITEBYTECODE"] = "1"
    shutil.rmtree(out, ignore_errors=True)
    run(["sphinx-build", "-b", "html", "-W", "--keep-going", "-E", "-q",
         "-d", str(work / "doctrees"), str(DOCS), str(out)], env=env)
    print(f"build_site: {out}/index.html ({time.monotonic() - started:.0f} s, no warnings)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
