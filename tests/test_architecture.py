"""The house's rules, read from the code itself: imports go one way, modules stay small.

Every ``import`` in ``nbcalib/`` counts, wherever it is: at module level, inside a function (a
deferred import is still a dependency) and under ``if TYPE_CHECKING:`` (a reader follows it
too). docs/architecture.md draws the rooms and the direction of the arrows.
"""

from __future__ import annotations

import ast
import functools
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "nbcalib"
MAX_LINES = 700


def module_name(path: Path, package: Path = PACKAGE) -> str:
    parts = list(path.relative_to(package.parent).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


@functools.cache
def import_graph(package: Path = PACKAGE) -> dict[str, dict[str, int]]:
    """Module -> {module it imports: line}, for every import of an ``nbcalib`` module.

    ``from a.b import c`` depends on ``a.b.c`` when that is a module, else on ``a.b``;
    ``import a.b.c`` on ``a.b.c``. A package's ``__init__`` is the package's name.
    """
    paths = {module_name(p, package): p for p in package.rglob("*.py")}
    root = package.name

    def resolve(name: str) -> str | None:
        while name and name not in paths:
            name = name.rpartition(".")[0]
        return name or None

    graph: dict[str, dict[str, int]] = {}
    for name, path in paths.items():
        edges = graph.setdefault(name, {})
        here = name if path.name == "__init__.py" else name.rpartition(".")[0]
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            targets = []
            if isinstance(node, ast.Import):
                targets = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    base = here.split(".")[: len(here.split(".")) - node.level + 1]
                    module = ".".join(base + ([node.module] if node.module else []))
                else:
                    module = node.module or ""
                for alias in node.names:
                    full = f"{module}.{alias.name}"
                    targets.append(full if full in paths else module)
            for target in targets:
                if target == root or target.startswith(root + "."):
                    found = resolve(target)
                    if found and found != name:
                        edges.setdefault(found, node.lineno)
    return graph


def circles(graph: dict[str, dict[str, int]]) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph.get(v, {}):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def _describe(graph, component) -> str:
    inside = set(component)
    arrows = [
        f"  {a} -> {b} (line {line})"
        for a in component
        for b, line in sorted(graph[a].items())
        if b in inside
    ]
    return "\n".join([" <-> ".join(component), *arrows])


def test_the_walker_finds_a_circle(tmp_path):
    """The test below can fail: a planted circle, deferred and type-only imports included."""
    pkg = tmp_path / "nbcalib"
    (pkg / "sub").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "sub" / "__init__.py").write_text("")
    (pkg / "low.py").write_text("def f():\n    from nbcalib.sub import high\n")
    (pkg / "sub" / "high.py").write_text(
        "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from .. import low\n"
    )
    (pkg / "top.py").write_text("import nbcalib.low\nfrom nbcalib.sub.high import x\n")
    graph = import_graph(pkg)
    assert graph["nbcalib.top"] == {"nbcalib.low": 1, "nbcalib.sub.high": 2}
    assert circles(graph) == [["nbcalib.low", "nbcalib.sub.high"]]


def test_no_import_circles():
    graph = import_graph()
    found = circles(graph)
    assert not found, "import circles:\n" + "\n".join(_describe(graph, c) for c in found)


@pytest.mark.parametrize(
    ("low", "high"),
    [
        ("nbcalib.report", "nbcalib.pipeline"),
        ("nbcalib.matching", "nbcalib.pipeline"),
        ("nbcalib.registration", "nbcalib.report"),
        ("nbcalib.io", "nbcalib.pipeline"),
        ("nbcalib.preprocess", "nbcalib.pipeline"),
        ("nbcalib.kernels", "nbcalib.registration"),
    ],
)
def test_the_stages_do_not_import_the_pipeline_above_them(low, high):
    """A stage is a room below the pipeline: nothing in it imports the pipeline (or a later
    room that reads its products), so the report renders from products and records."""
    graph = import_graph()
    wrong = [
        f"{a} -> {b} (line {line})"
        for a, edges in graph.items()
        if a == low or a.startswith(low + ".")
        for b, line in edges.items()
        if b == high or b.startswith(high + ".")
    ]
    assert not wrong, "\n".join(wrong)


def test_no_module_over_700_lines():
    long = {
        str(p.relative_to(PACKAGE.parent)): n
        for p in PACKAGE.rglob("*.py")
        if (n := len(p.read_text().splitlines())) > MAX_LINES
    }
    assert not long, f"modules over {MAX_LINES} lines (split along a seam): {long}"


# ---------------------------------------------------------------------------------------------
# Messages below the command line name settings as the API does (nbcalib.wording)

#: Strings below the command line that may hold a flag: whole commands to type in a shell, the
#: same for every user (there is no setting to name), each with why.
FLAG_ALLOWED = {
    ("matching/onnx_matcher.py", "--models"): "the shell command that exports a model",
    ("matching/onnx_matcher.py", "--help"): "the shell command that says how to export one",
    ("config.py", "--config"): "the header of a settings file: the command that reads it",
    ("io/camera_file.py", "--camera"): "the header of a camera file: the command that reads it",
}


def _messages(path: Path):
    """(line, text) of the string constants of a module, docstrings left out."""
    tree = ast.parse(path.read_text())
    docs = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
            first = node.body[0] if node.body else None
            if isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant):
                docs.add(id(first.value))
    for node in ast.walk(tree):
        if isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in docs:
            yield node.lineno, node.value


def _below_the_command_line():
    for path in sorted(PACKAGE.rglob("*.py")):
        rel = path.relative_to(PACKAGE).as_posix()
        if not (rel.startswith("commands/") or rel == "cli.py"):
            yield rel, path


@functools.cache
def _cli_flags() -> frozenset[str]:
    import argparse

    from nbcalib.cli import build_parser

    flags, parsers = set(), [build_parser()]
    while parsers:
        parser = parsers.pop()
        for action in parser._actions:
            flags.update(s for s in action.option_strings if s.startswith("--"))
            if isinstance(action, argparse._SubParsersAction):
                parsers.extend(action.choices.values())
    return frozenset(flags)


def test_no_cli_flag_in_a_message_below_the_command_line():
    import re

    flags = _cli_flags()
    assert {"--every", "--frames", "--max-outer", "--init"} <= flags  # the walk found them
    pattern = re.compile(r"(?<![\w-])--[a-z][a-z0-9-]*")
    found = [
        f"nbcalib/{rel}:{line}: {flag} in {text[:70]!r}"
        for rel, path in _below_the_command_line()
        for line, text in _messages(path)
        for flag in pattern.findall(text)
        if flag in flags and (rel, flag) not in FLAG_ALLOWED
    ]
    assert not found, "name the setting (nbcalib.wording), not the flag:\n" + "\n".join(found)


def test_every_setting_a_message_names_has_a_flag():
    """Each API name in a message below the command line is one the command line spells: a
    misspelt name would reach the command line's user as it is."""
    from nbcalib.commands._options import flag_names
    from nbcalib.config import SECTIONS
    from nbcalib.wording import API_NAME

    known = flag_names()
    rooms = {*SECTIONS, "inputs", "run"}
    found = [
        f"nbcalib/{rel}:{line}: {m.group(1)}.{m.group(2)}"
        for rel, path in _below_the_command_line()
        for line, text in _messages(path)
        for m in API_NAME.finditer(text)
        if m.group(1) in rooms and f"{m.group(1)}.{m.group(2)}" not in known
    ]
    assert not found, "names without a flag:\n" + "\n".join(found)


def test_the_benchmarks_page_states_today_in_800_lines():
    """docs/BENCHMARKS.md holds today's figures; their history goes to the CHANGELOG."""
    page = PACKAGE.parent / "docs" / "BENCHMARKS.md"
    assert len(page.read_text().splitlines()) <= 800
