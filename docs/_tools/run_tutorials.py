#!/usr/bin/python3
"""Runs every code block of the tutorial pages and checks what they print, so the docs cannot rot.

    run_tutorials.py --build-dir build/release [PAGE.md ...]

Without pages: README.md, docs/getting-started.md and docs/tutorials/*.md. Each page runs in a fresh
directory, its blocks in order, with the build's `moreau` first on PATH, `python3` meaning
Debian's /usr/bin/python3, the build's Python package on PYTHONPATH, and moreau installed into a
private prefix on CMAKE_PREFIX_PATH (for `find_package(moreau)`). The conventions, which the
pages follow:

* ```` ```console ````: lines starting with ``$ `` are shell commands (a trailing backslash
  continues a command on the next line); the lines after a command are its expected output.
  A command must exit with status 0, unless the block is preceded by ``<!-- exit: N -->``.
  Commands run in the page's directory, unless the block is preceded by
  ``<!-- cwd: repository -->``: then in the repository's root, as a reader who runs the
  repository's own examples does (such commands must not write into the repository).
* ```` ```python ````: run in one interpreter per page (later blocks see earlier names).
* ```` ```output ````: the expected output of the block just before it.
* Any other language (toml, cpp, cmake, ...): a file, preceded by ``<!-- file: NAME -->``; the
  block's text is written to NAME in the page's directory.
* ``<!-- skip: reason -->`` before a block: not run (reported; for commands that set up the
  machine, which the test suite has done already).

Expected output is matched loosely, so that the docs claim what the program guarantees and no
more: the expected lines must appear in the output in the same order (other lines may come
between); within a line, ``...`` matches any text; an integer must be equal; any other number
matches if it agrees with the printed one to one unit in its last digit shown (``3.4657...``
or ``3.4657`` accepts 3.46574 and 3.46566, not 3.4659). So a tutorial shows exactly the digits
it claims.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import textwrap
import time
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
DOCS = ROOT / "docs"
COMMAND_TIMEOUT = 600  # seconds; a tutorial command that takes longer is a bug in the tutorial

FENCE = re.compile(r"^(?P<indent> {0,3})(?P<fence>`{3,}|~{3,})(?P<info>[^`\n]*)$")
MARKER = re.compile(r"^<!--\s*(?P<key>file|skip|exit|cwd)\s*:\s*(?P<value>.*?)\s*-->$")
NUMBER = re.compile(r"[-+]?(?:\d+\.\d*|\.\d+|\d+)(?:[eE][-+]?\d+)?")


@dataclass
class Block:
    page: Path
    line: int  # 1-based line of the opening fence
    language: str
    text: str
    markers: dict = field(default_factory=dict)

    def where(self) -> str:
        return f"{self.page.relative_to(ROOT)}:{self.line}"


def parse_blocks(page: Path) -> list[Block]:
    lines = page.read_text(encoding="utf-8").split("\n")
    blocks: list[Block] = []
    i = 0
    while i < len(lines):
        m = FENCE.match(lines[i])
        if not m:
            i += 1
            continue
        fence, info = m.group("fence"), m.group("info").strip()
        start = i
        body: list[str] = []
        i += 1
        while i < len(lines) and not (lines[i].strip().startswith(fence[0] * len(fence))
                                      and lines[i].strip().strip(fence[0]) == ""):
            body.append(lines[i])
            i += 1
        i += 1
        language = info.split()[0] if info else ""
        if language.startswith("{"):  # a MyST directive (toctree, eval-rst, ...): not code
            continue
        markers = {}
        j = start - 1
        while j >= 0 and (not lines[j].strip() or MARKER.match(lines[j].strip())):
            mm = MARKER.match(lines[j].strip())
            if mm:
                markers[mm.group("key")] = mm.group("value")
            j -= 1
        blocks.append(Block(page, start + 1, language, "\n".join(body) + "\n", markers))
    return blocks


# ---- output matching ---------------------------------------------------------------------------

# Version numbers (1.2.3) are text, not numbers.
_TOKEN = re.compile(r"(?P<version>\d+(?:\.\d+){2,})|(?P<number>" + NUMBER.pattern + r")|"
                    r"(?P<dots>\.\.\.)|(?P<space>\s+)|(?P<text>.)")
_NUMBER_GROUP = r"(?<![\d.])(" + NUMBER.pattern + r")"


def _line_pattern(expected: str) -> tuple[re.Pattern, list[tuple[float, float]]]:
    """A regex for one expected line and, per number in it, (value, tolerance): one unit in the
    last digit shown."""
    parts: list[str] = []
    numbers: list[tuple[float, float]] = []
    for m in _TOKEN.finditer(expected.strip()):
        if m.group("number"):
            token = m.group("number")
            mantissa, exponent = (re.split(r"[eE]", token) + ["0"])[:2]
            decimals = len(mantissa.split(".")[1]) if "." in mantissa else 0
            exact = "." not in token and not re.search(r"[eE]", token)  # counts: exactly
            numbers.append((float(token), 0.0 if exact else 10.0 ** (int(exponent) - decimals)))
            parts.append(_NUMBER_GROUP)
        elif m.group("version"):
            parts.append(re.escape(m.group("version")))
        elif m.group("dots"):
            parts.append(r".*?")
        elif m.group("space"):
            parts.append(r"\s+")
        else:
            parts.append(re.escape(m.group("text")))
    return re.compile("".join(parts)), numbers


def _line_matches(expected: str, actual: str) -> bool:
    pattern, numbers = _line_pattern(expected)
    start = 0
    while True:
        m = pattern.search(actual, start)
        if m is None:
            return False
        if all(abs(float(g) - v) <= t * (1 + 1e-9) for (v, t), g in zip(numbers, m.groups())):
            return True
        start = m.start() + 1


def check_output(expected: str, actual: str) -> str | None:
    """None if every expected line matches an output line, in order; else a description."""
    wanted = [line for line in expected.split("\n") if line.strip() and line.strip() != "..."]
    lines = actual.split("\n")
    k = 0
    for line in wanted:
        while k < len(lines) and not _line_matches(line, lines[k]):
            k += 1
        if k == len(lines):
            return f"expected a line matching\n    {line.strip()}\nin the output (after the " \
                   f"lines matched before it):\n{textwrap.indent(actual.rstrip(), '    | ')}"
        k += 1
    return None


# ---- execution ---------------------------------------------------------------------------------

PYTHON_DRIVER = r"""
import contextlib, io, json, os, sys, traceback
namespace = {"__name__": "__main__"}
for request in sys.stdin:
    code = json.loads(request)["code"]
    out = io.StringIO()
    error = None
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(out):
        try:
            exec(compile(code, "<tutorial block>", "exec"), namespace)
        except BaseException:
            error = traceback.format_exc()
    sys.__stdout__.write(json.dumps({"output": out.getvalue(), "error": error}) + "\n")
    sys.__stdout__.flush()
"""


class Page:
    def __init__(self, path: Path, env: dict[str, str], workdir: Path):
        self.path = path
        self.env = env
        self.workdir = workdir
        self.python: subprocess.Popen | None = None
        self.sessions: list[int] = []

    def run_python(self, code: str) -> tuple[str, str | None]:
        if self.python is None:
            self.python = subprocess.Popen(
                ["/usr/bin/python3", "-u", "-c", PYTHON_DRIVER], cwd=self.workdir, env=self.env,
                stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
        assert self.python.stdin and self.python.stdout
        self.python.stdin.write(json.dumps({"code": code}) + "\n")
        self.python.stdin.flush()
        reply = self.python.stdout.readline()
        if not reply:
            return "", "the Python interpreter died"
        answer = json.loads(reply)
        return answer["output"], answer["error"]

    def run_shell(self, command: str, cwd: Path | None = None) -> tuple[int, str]:
        # Each command in a session of its own, so that whatever it leaves running in the
        # background (a Dask scheduler) can be stopped with the page.
        process = subprocess.Popen(["bash", "-c", command], cwd=cwd or self.workdir, env=self.env,
                                   stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                                   start_new_session=True)
        self.sessions.append(process.pid)
        try:
            output, _ = process.communicate(timeout=COMMAND_TIMEOUT)
        except subprocess.TimeoutExpired:
            os.killpg(process.pid, signal.SIGKILL)
            output, _ = process.communicate()
            return 124, output + f"\n(killed after {COMMAND_TIMEOUT} s)"
        return process.returncode, output

    def close(self) -> None:
        if self.python is not None:
            self.python.stdin.close()  # type: ignore[union-attr]
            self.python.wait(timeout=60)
        for session in self.sessions:  # background processes the page left running
            try:
                os.killpg(session, signal.SIGTERM)
            except ProcessLookupError:
                pass


def console_commands(block: Block) -> list[tuple[str, str]]:
    """(command, expected output) pairs of a console block."""
    pairs: list[tuple[str, list[str]]] = []
    lines = block.text.rstrip("\n").split("\n")
    i = 0
    while i < len(lines):
        line = lines[i]
        if line.startswith("$ "):
            command = line[2:]
            while command.endswith("\\") and i + 1 < len(lines):
                i += 1
                command = command[:-1] + " " + lines[i].strip()
            pairs.append((command, []))
        elif pairs:
            pairs[-1][1].append(line)
        elif line.strip():
            raise ValueError(f"{block.where()}: console output before the first `$ ` command")
        i += 1
    return [(command, "\n".join(out)) for command, out in pairs]


def run_page(path: Path, base_env: dict[str, str], keep: bool) -> tuple[int, int, list[str]]:
    """Runs one page; returns (blocks run, blocks skipped, failures)."""
    blocks = parse_blocks(path)
    workdir = Path(tempfile.mkdtemp(prefix=f"moreau-tutorial-{path.stem}-"))
    page = Page(path, base_env, workdir)
    failures: list[str] = []
    run = skipped = 0
    previous: tuple[Block, str] | None = None  # the last executable block and its output
    try:
        for block in blocks:
            if "skip" in block.markers:
                skipped += 1
                print(f"  skip   {block.where()} ({block.markers['skip']})")
                previous = None
                continue
            if block.language == "output":
                if previous is None:
                    failures.append(f"{block.where()}: an output block must follow a console or "
                                    "python block")
                    continue
                problem = check_output(block.text, previous[1])
                if problem:
                    failures.append(f"{block.where()}: output of {previous[0].where()}: {problem}")
                previous = None
                continue
            started = time.monotonic()
            if block.language == "console":
                expected_exit = int(block.markers.get("exit", "0"))
                cwd = block.markers.get("cwd")
                if cwd not in (None, "repository"):
                    failures.append(f"{block.where()}: <!-- cwd: {cwd} -->: the only directory "
                                    "a block may name is `repository`")
                    continue
                output_all = ""
                for command, expected in console_commands(block):
                    code, output = page.run_shell(command, ROOT if cwd else None)
                    output_all += output
                    if code != expected_exit:
                        failures.append(f"{block.where()}: `{command}` exited with {code} "
                                        f"(expected {expected_exit}):\n"
                                        f"{textwrap.indent(output.rstrip(), '    | ')}")
                        break
                    if expected.strip():
                        problem = check_output(expected, output)
                        if problem:
                            failures.append(f"{block.where()}: `{command}`: {problem}")
                previous = (block, output_all)
            elif block.language == "python":
                output, error = page.run_python(block.text)
                if error:
                    failures.append(f"{block.where()}: the Python block raised:\n"
                                    f"{textwrap.indent(error.rstrip(), '    | ')}\n"
                                    f"  its output:\n{textwrap.indent(output.rstrip(), '    | ')}")
                previous = (block, output)
            elif "file" in block.markers:
                target = workdir / block.markers["file"]
                target.parent.mkdir(parents=True, exist_ok=True)
                target.write_text(block.text)
                previous = None
            else:
                failures.append(f"{block.where()}: a ```{block.language or '(no language)'} "
                                "block that is neither run nor saved: add <!-- file: NAME --> "
                                "(or use console/python/output)")
                continue
            run += 1
            print(f"  ran    {block.where()} ({block.language}, "
                  f"{time.monotonic() - started:.1f} s)")
            if failures and failures[-1].startswith(block.where()):
                break  # later blocks depend on this one
    finally:
        page.close()
        if not keep:
            shutil.rmtree(workdir, ignore_errors=True)
        else:
            print(f"  kept   {workdir}")
    return run, skipped, failures


def make_environment(build: Path, prefix: Path | None, shim: Path) -> dict[str, str]:
    env = dict(os.environ)
    # `python3` in the tutorials is Debian's interpreter (the one that sees python3-* packages).
    shim.mkdir(parents=True, exist_ok=True)
    (shim / "python3").unlink(missing_ok=True)
    (shim / "python3").symlink_to("/usr/bin/python3")
    env["PATH"] = os.pathsep.join([str(build / "tools"), str(shim), env.get("PATH", "")])
    env["PYTHONPATH"] = str(build / "python")
    env["PYTHONDONTWRITEBYTECODE"] = "1"
    env["MPLBACKEND"] = "Agg"
    if prefix is not None:
        env["CMAKE_PREFIX_PATH"] = str(prefix)
    env.pop("MAKEFLAGS", None)
    return env


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--build-dir", required=True, type=Path, help="a built moreau tree")
    parser.add_argument("--keep", action="store_true", help="keep each page's directory")
    parser.add_argument("--no-install", action="store_true",
                        help="do not install moreau into a private prefix (pages that use "
                             "find_package(moreau) then need it installed elsewhere)")
    parser.add_argument("pages", nargs="*", type=Path)
    args = parser.parse_args()
    build = args.build_dir.resolve()
    pages = [p.resolve() for p in args.pages] or (
        [ROOT / "README.md", DOCS / "getting-started.md"] +
        sorted((DOCS / "tutorials").glob("*.md")))
    scratch = Path(tempfile.mkdtemp(prefix="moreau-tutorials-"))
    started = time.monotonic()
    try:
        prefix = None
        if not args.no_install:
            prefix = scratch / "prefix"
            subprocess.run(["cmake", "--install", str(build), "--prefix", str(prefix)],
                           check=True, stdout=subprocess.DEVNULL)
        env = make_environment(build, prefix, scratch / "shim")
        total_run = total_skipped = 0
        all_failures: list[str] = []
        for page in pages:
            print(f"{page.relative_to(ROOT)}")
            run, skipped, failures = run_page(page, env, args.keep)
            total_run += run
            total_skipped += skipped
            all_failures += failures
        print(f"run_tutorials: {total_run} blocks run, {total_skipped} skipped, "
              f"{len(all_failures)} failed, {time.monotonic() - started:.0f} s")
        for failure in all_failures:
            print(f"FAILED {failure}", file=sys.stderr)
        return 1 if all_failures else 0
    finally:
        shutil.rmtree(scratch, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
