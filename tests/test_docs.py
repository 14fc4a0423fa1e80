"""The documentation names only things that exist.

Every dotted ``nbcalib.xxx`` name in README.md, docs/*.md and notebooks/README.md must import (a
module) or resolve (an attribute of one), and every relative link and every repository path in
backticks or code blocks (``docs/conventions.md``, ``benchmarks/bench_nid.py``) must exist.
"""

from __future__ import annotations

import importlib
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

#: top-level entries of the repository: a word starting with one of these is a repository path
TOP_LEVEL = (
    ".ci",
    "benchmarks",
    "data_manifests",
    "docs",
    "nbcalib",
    "notebooks",
    "scripts",
    "tests",
    "README.md",
    "environment.yml",
    "pyproject.toml",
)


def _documents():
    docs = sorted((ROOT / "docs").glob("*.md"))
    names = [ROOT / "README.md", ROOT / "CHANGELOG.md", *docs, ROOT / "notebooks" / "README.md"]
    return [pytest.param(path, id=path.relative_to(ROOT).as_posix()) for path in names]


DOCUMENTS = _documents()

_DOTTED = re.compile(r"(?<![\w.\-/])nbcalib(?:\.[A-Za-z_]\w*)+")
_FENCE = re.compile(r"^```[^\n]*\n(.*?)^```", re.MULTILINE | re.DOTALL)
_INLINE_CODE = re.compile(r"`([^`\n]+)`")
_LINK = re.compile(r"\[[^\]\n]*\]\(([^)\s]+)\)")
_TRAILING = ".,;:)'\""


def dotted_names(text: str) -> list[str]:
    """The distinct ``nbcalib.a.b`` names of a text, in order of appearance."""
    return list(dict.fromkeys(_DOTTED.findall(text)))


def resolves(name: str) -> bool:
    """Whether ``name`` is an importable module or an attribute reachable from one."""
    parts = name.split(".")
    for n in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:n]))
        except ModuleNotFoundError as exc:
            if exc.name is not None and not ".".join(parts[:n]).startswith(exc.name):
                raise  # a dependency of the module is missing: say so, do not hide it
            continue
        for attr in parts[n:]:
            if not hasattr(obj, attr):
                return False
            obj = getattr(obj, attr)
        return True
    return False


def _repository_word(word: str) -> str | None:
    """``word`` as a repository path if it looks like one, else None."""
    word = word.lstrip("('\"").rstrip(_TRAILING).split("::")[0]
    word = re.sub(r":\d+(-\d+)?$", "", word)  # file.py:120
    if word.startswith("./"):
        word = word[2:]
    head = word.split("/")[0]
    if head not in TOP_LEVEL or (head == word and "." not in word and not word.endswith("/")):
        return None
    if "{" in word or "<" in word:  # a template such as docs/{name}.md
        return None
    return word


def repository_paths(text: str) -> list[str]:
    """Repository paths named in inline code spans and fenced code blocks."""
    spans = _INLINE_CODE.findall(_FENCE.sub("", text)) + _FENCE.findall(text)
    words = (w for span in spans for w in span.split())
    found = (_repository_word(w) for w in words)
    return list(dict.fromkeys(p for p in found if p))


def relative_links(text: str) -> list[str]:
    """Targets of markdown links that are files of the repository (no URL, no bare anchor)."""
    targets = (t.split("#")[0] for t in _LINK.findall(_FENCE.sub("", text)))
    return list(dict.fromkeys(t for t in targets if t and not re.match(r"[a-z]+:", t)))


def _exists(path: Path) -> bool:
    if any(c in path.name for c in "*?["):
        return any(path.parent.glob(path.name))
    return path.exists()


def test_the_documents_are_found():
    rel = {p.values[0].relative_to(ROOT).as_posix() for p in DOCUMENTS}
    assert {"README.md", "docs/conventions.md", "docs/BENCHMARKS.md"} <= rel
    assert "notebooks/README.md" in rel
    readme = (ROOT / "README.md").read_text()
    assert len(dotted_names(readme)) >= 10 and len(relative_links(readme)) >= 2


def test_the_extractors_find_what_they_should():
    text = (
        "See `nbcalib.camera.CameraModel`, nbcalib.transforms. and `calib.nbcalib.quality`;\n"
        "CI (`.ci/run`) runs `python benchmarks/bench_nid.py --quick`;\n"
        "`nbcalib/kernels/_jit.py:40`, `docs/`, `work/calib.json`, `nbcalib run` and\n"
        "[the conventions](docs/conventions.md#2-transforms),\n"
        "[site](https://example.org/x.md).\n```bash\npython scripts/gone.sh\n```\n"
    )
    assert dotted_names(text) == ["nbcalib.camera.CameraModel", "nbcalib.transforms"]
    assert repository_paths(text) == [
        ".ci/run",
        "benchmarks/bench_nid.py",
        "nbcalib/kernels/_jit.py",
        "docs/",
        "scripts/gone.sh",
    ]
    assert relative_links(text) == ["docs/conventions.md"]
    assert resolves("nbcalib.transforms.se3_exp") and resolves("nbcalib.kernels._jit")
    assert not resolves("nbcalib.viz") and not resolves("nbcalib.transforms.no_such_name")


@pytest.mark.parametrize("doc", DOCUMENTS)
def test_dotted_names_resolve(doc):
    stale = [name for name in dotted_names(doc.read_text()) if not resolves(name)]
    assert not stale, f"{doc.relative_to(ROOT)} names what does not exist: {stale}"


@pytest.mark.parametrize("doc", DOCUMENTS)
def test_paths_exist(doc):
    text = doc.read_text()
    missing = [p for p in repository_paths(text) if not _exists(ROOT / p)]
    missing += [t for t in relative_links(text) if not _exists(doc.parent / t)]
    assert not missing, f"{doc.relative_to(ROOT)} names files that do not exist: {missing}"
