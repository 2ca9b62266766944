"""The README's Python snippets cannot drift from the API: each one parses, every ``dgan.…`` name it uses or imports
exists, every attribute it reads off a predictor, frame, prediction, tracker or scenario exists on that type, and
what it says ``dgan.models.list()`` returns is what it returns."""

from __future__ import annotations

import ast
import dataclasses
import importlib
import re
from pathlib import Path
from typing import Any

import pytest

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


def snippets() -> list[str]:
    """The bodies of the README's fenced ``python`` blocks."""
    return re.findall(r"^```python\n(.*?)^```", README.read_text(), flags=re.S | re.M)


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
