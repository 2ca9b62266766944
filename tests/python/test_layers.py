"""The house: no import circle in any layer (the engine's modules, ``dgan``, ``training``, ``benches``), the layers in
their order, functions and modules of a size a newcomer can read, and a dataset added in one place."""

from __future__ import annotations

import ast
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
#: The largest function (lines of code, its docstring not counted) and module (lines) in ``python/`` and ``training/``.
MAX_FUNCTION_LINES = 60
MAX_MODULE_LINES = 400


def test_python_layers_and_no_circles() -> None:
    """``lint-imports`` with the contracts of ``pyproject.toml``: benches above training above dgan, and no circle
    between the modules of one package at any depth."""
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT / "python"), str(ROOT)]))
    lint = Path(sys.executable).with_name("lint-imports")
    out = subprocess.run([str(lint), "--no-cache"], cwd=ROOT, env=env, capture_output=True, text=True)
    assert out.returncode == 0, out.stdout + out.stderr
    assert "2 kept, 0 broken" in out.stdout


def rust_imports(src: Path) -> dict[str, set[str]]:
    """Each module of a crate's ``src`` and the crate modules its code names (``use crate::x``, ``crate::x::y``)."""
    graph: dict[str, set[str]] = {}
    for f in src.glob("*.rs"):
        text = re.sub(r"#\[cfg\(test\)\]\s*mod tests \{.*", "", f.read_text(), flags=re.S)  # tests may reach anywhere
        text = re.sub(r"//.*", "", text)  # a doc link names a module without importing it
        uses = set(re.findall(r"\bcrate::(\w+)", text))
        for group in re.findall(r"\bcrate::\{([^}]*)\}", text):
            uses |= {g.strip().split("::")[0] for g in group.split(",") if g.strip()}
        graph[f.stem] = {u for u in uses if u != f.stem and (src / f"{u}.rs").is_file()}
    return graph


def circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one node (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    out: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


@pytest.mark.parametrize("crate", ["dgan-core", "dgan-py"])
def test_no_circle_between_the_engines_modules(crate: str) -> None:
    graph = rust_imports(ROOT / "crates" / crate / "src")
    assert len(graph) > 3
    assert circles(graph) == []


def test_the_circle_check_finds_one() -> None:
    assert circles({"frame": {"history"}, "history": {"map"}, "map": {"frame"}, "raster": {"map"}}) == [
        ["frame", "history", "map"]
    ]


def function_lines(node: ast.FunctionDef | ast.AsyncFunctionDef) -> int:
    start = node.decorator_list[0].lineno if node.decorator_list else node.lineno
    n = (node.end_lineno or node.lineno) - start + 1
    first = node.body[0]
    if isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant) and isinstance(first.value.value, str):
        n -= (first.end_lineno or first.lineno) - first.lineno + 1
    return n


def sources() -> list[Path]:
    return sorted(p for d in ("python/dgan", "training") for p in (ROOT / d).rglob("*.py"))


def test_functions_and_modules_are_short() -> None:
    long_functions = [
        f"{p.relative_to(ROOT)}:{node.lineno} {node.name}: {function_lines(node)} lines"
        for p in sources()
        for node in ast.walk(ast.parse(p.read_text()))
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and function_lines(node) > MAX_FUNCTION_LINES
    ]
    long_modules = [
        f"{p.relative_to(ROOT)}: {n} lines"
        for p in sources()
        if (n := len(p.read_text().splitlines())) > MAX_MODULE_LINES
    ]
    assert not long_functions, "\n".join(long_functions)
    assert not long_modules, "\n".join(long_modules)


def test_a_dataset_is_added_in_one_place(tmp_path: Path) -> None:
    """The worked example of a new training dataset: one :class:`~training.data.datasets.Source` (its files and its
    reader) and its :class:`~training.data.recording.DatasetInfo`, registered; recordings and the windows the
    trainer caches then follow through the same code as every other dataset."""
    pytest.importorskip("torch")
    import dgan
    from training.data import datasets
    from training.data.recording import DatasetInfo, Recording
    from training.data.windows import iter_windows

    table = tmp_path / "walk.csv"
    t = np.arange(30)
    rows = [(s, a, 0.5 * s + a, 0.1 * a * s) for s in t for a in range(3)]
    np.savetxt(table, np.array(rows, dtype=np.float64), delimiter=",")

    def read(path: Path, root: Path, split: str, with_map: bool) -> list[Recording]:
        r = np.loadtxt(path, delimiter=",")
        return [
            Recording.sorted(
                name=path.stem,
                step=r[:, 0].astype(np.int64),
                agent=r[:, 1].astype(np.int64),
                xy=r[:, 2:4],
                label=np.zeros(len(r), np.int64),
            )
        ]

    info = DatasetInfo("walkers", 0.4, 8, 12, ("Walker",), ("pedestrian",), (True,), "m", 1, False)
    source = datasets.Source(lambda root, split, fold: [table], read)
    datasets.register(info, source)
    try:
        assert datasets.source_files("walkers", tmp_path, "train") == [table]
        (rec,) = datasets.recordings("walkers", tmp_path, "test")
        assert rec.xy.shape == (90, 2)
        windows = list(iter_windows(rec, info, info.t_obs, info.t_f))
        assert len(windows) == 30 - 20 + 1  # every step with 8 observed and 12 future steps of all three walkers
        assert dgan.InputSpec(dt_s=info.dt_s, t_obs=8, t_f=12, classes=info.classes).state_dim == 8
        with pytest.raises(ValueError, match="registered already"):
            datasets.register(info, source)
    finally:
        datasets.DATASETS.pop("walkers", None)
        datasets.SOURCES.pop("walkers", None)
