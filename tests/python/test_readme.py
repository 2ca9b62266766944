"""The README's Python snippets cannot drift from the API: each one parses, every ``dgan.…`` name it uses or imports
exists, every attribute it reads off a predictor, frame, prediction, tracker or scenario exists on that type, and
what it says ``dgan.models.list()`` returns is what it returns."""

from __future__ import annotations

import ast
import dataclasses
import importlib
import os
import re
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
from conftest import shared_data

import dgan
from dgan.datasets import hdmaps

README = Path(__file__).resolve().parents[2] / "README.md"

#: The README's variable names and the type each stands for.
TYPES: dict[str, type] = {
    "predictor": dgan.Predictor,
    "frame": dgan.Frame,
    "prediction": dgan.Prediction,
    "tracker": dgan.Tracker,
    "scenario": hdmaps.Scenario,
}


DOCS = sorted((README.parent / "docs").glob("*.md"))
EXAMPLES = sorted((README.parent / "docs" / "examples").glob("*.py"))


def snippets(page: Path = README) -> list[str]:
    """The bodies of a page's fenced ``python`` blocks (the README's by default)."""
    return re.findall(r"^```python\n(.*?)^```", page.read_text(), flags=re.S | re.M)


def chain(node: ast.expr) -> list[str] | None:
    """``a.b.c`` as ``["a", "b", "c"]``; None for anything that is not a plain dotted name."""
    parts: list[str] = []
    while isinstance(node, ast.Attribute):
        parts.append(node.attr)
        node = node.value
    if not isinstance(node, ast.Name):
        return None
    return [node.id, *reversed(parts)]


def resolve(names: list[str]) -> Any:
    """Follows ``dgan.x.y`` through modules (importing submodules such as ``dgan.datasets.hdmaps``) and attributes."""
    obj: Any = dgan
    path = "dgan"
    for name in names[1:]:
        path = f"{path}.{name}"
        # A submodule not imported yet is imported; anything else raises.
        obj = getattr(obj, name) if hasattr(obj, name) else importlib.import_module(path)
    return obj


def has(cls: type, name: str) -> bool:
    """Whether instances of ``cls`` have ``name``: a method, property or class attribute, or a dataclass field."""
    fields = {f.name for f in dataclasses.fields(cls)} if dataclasses.is_dataclass(cls) else set()
    return hasattr(cls, name) or name in fields


def test_there_are_snippets() -> None:
    assert len(snippets()) >= 4


@pytest.mark.parametrize("index", range(len(snippets())))
def test_a_snippet_names_only_what_exists(index: int) -> None:
    tree = ast.parse(snippets()[index])
    seen = 0
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and (node.module or "").split(".")[0] == "dgan":
            module = importlib.import_module(node.module or "")
            for alias in node.names:
                assert hasattr(module, alias.name), f"README imports {alias.name} from {node.module}, which lacks it"
                seen += 1
        if not isinstance(node, ast.Attribute) or isinstance(getattr(node, "ctx", None), ast.Store):
            continue
        names = chain(node)
        if names is None:
            continue
        if names[0] == "dgan":
            resolve(names)
            seen += 1
        elif names[0] in TYPES and len(names) == 2:
            assert has(TYPES[names[0]], names[1]), f"README uses {'.'.join(names)}, which does not exist"
            seen += 1
    assert seen > 0, "a snippet that names nothing of dgan's"


def test_the_listed_models_are_the_bundled_ones() -> None:
    said = re.search(r"^dgan\.models\.list\(\)\s+# (\(.*?\))$", README.read_text(), flags=re.M)
    assert said is not None
    assert dgan.models.list() == ast.literal_eval(said.group(1))


def test_a_missing_name_is_caught() -> None:
    with pytest.raises(ModuleNotFoundError):
        resolve(["dgan", "no_such_thing"])
    assert has(TYPES["prediction"], "trajectories")
    assert not has(TYPES["prediction"], "trajectory")


@pytest.mark.slow
def test_the_snippets_run_on_bundled_data(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Every Python block of the README, in order and in one namespace (a later block may use an earlier one's
    names), run as a user would paste them, in an empty folder."""
    monkeypatch.chdir(tmp_path)
    namespace: dict[str, Any] = {"__name__": "readme"}
    for i, code in enumerate(snippets()):
        exec(compile(code, f"README.md, Python block {i + 1}", "exec"), namespace)
    assert (tmp_path / "prediction.parquet").is_file()
    assert (tmp_path / "prediction.png").is_file()
    assert isinstance(namespace["prediction"], dgan.Prediction)


@pytest.mark.parametrize("page", [p for p in DOCS if snippets(p)], ids=lambda p: p.name)
def test_the_docs_snippets_run(page: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Each page of ``docs/`` runs its Python blocks in order, in a namespace of its own."""
    monkeypatch.chdir(tmp_path)
    namespace: dict[str, Any] = {"__name__": page.stem}
    for i, code in enumerate(snippets(page)):
        exec(compile(code, f"{page.name}, Python block {i + 1}", "exec"), namespace)


def test_the_docs_have_snippets() -> None:
    assert any(snippets(p) for p in DOCS)


@pytest.mark.slow
@pytest.mark.parametrize("example", EXAMPLES, ids=lambda p: p.name)
def test_the_examples_run(example: Path, tmp_path: Path) -> None:
    """``docs/examples/*.py`` as a user runs them (on the shared data's Argoverse 2 scenes), writing into a folder."""
    shared_data("argoverse2")
    env = dict(os.environ, MPLBACKEND="Agg")
    out = subprocess.run(
        [sys.executable, str(example), "--out", str(tmp_path)], env=env, capture_output=True, text=True, timeout=600
    )
    assert out.returncode == 0, out.stderr[-4000:]
    assert any(tmp_path.iterdir()), "the example wrote nothing"


def test_the_readme_is_short_and_the_changelog_entries_too() -> None:
    """A README of at most 220 lines for users, and a Keep-a-Changelog file whose entries are at most 4 lines."""
    assert len(README.read_text().splitlines()) <= 220
    changelog = (README.parent / "CHANGELOG.md").read_text().splitlines()
    assert "## [Unreleased]" in changelog
    entries: list[list[str]] = []
    for line in changelog:
        if line.startswith("- "):
            entries.append([line])
        elif line.startswith("  ") and entries:
            entries[-1].append(line)
    long = [e[0] for e in entries if len(e) > 4]
    assert not long, f"CHANGELOG entries over 4 lines: {long}"
    assert len(entries) > 10
