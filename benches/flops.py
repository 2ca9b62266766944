"""Floating-point operations of an ONNX graph on given inputs, counted node by node from the shapes it really runs.

Every intermediate tensor is made a graph output and the graph is run once in ONNX Runtime on ``feed``, so the count
follows the shapes of this call (N agents, E edges, the neighbour degree), whatever is dynamic in the graph. A
multiply-add counts 2:

- ``MatMul``: 2 · (output elements) · K; ``Gemm``: 2 · M · N · K (+ M · N for the bias);
- ``Conv``: 2 · (output elements) · C_in / groups · kernel area (+ output elements for the bias);
- ``LSTM`` / ``GRU``: per step and direction 2 · gates · H · (input + H) per sequence, plus the gate arithmetic;
- everything else: one per output element (a softmax or reduction: per input element), counted apart as ``other``.

    python benches/bench.py --flops [--models ...] [--agents 32]   # MFLOP per agent on the bundled scenes
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

DENSE = frozenset({"MatMul", "Gemm", "Conv", "LSTM", "GRU", "ConvTranspose", "MatMulInteger", "Einsum"})
#: Operators that move or index data without arithmetic.
FREE = frozenset(
    {
        "Reshape", "Transpose", "Gather", "GatherElements", "GatherND", "Concat", "Slice", "Squeeze", "Unsqueeze",
        "Shape", "Cast", "Identity", "Expand", "Flatten", "Split", "ScatterND", "ScatterElements", "Constant",
        "ConstantOfShape", "Range", "NonZero", "Tile", "Pad", "Size", "Where", "Equal", "Less", "Greater", "Not",
        "And", "Or", "LessOrEqual", "GreaterOrEqual", "ArgMax", "TopK", "OneHot", "Trilu",
    }
)  # fmt: skip


@dataclass(frozen=True)
class Flops:
    """A graph's operations on one input: ``dense`` (matrix products, convolutions, recurrent cells) and ``other``
    (elementwise, reductions)."""

    dense: int
    other: int

    @property
    def total(self) -> int:
        return self.dense + self.other


def _shapes(model: Any, feed: dict[str, np.ndarray]) -> dict[str, tuple[int, ...]]:
    """The shape of every tensor of the graph on ``feed``: initializers and inputs as given, the rest as run."""
    import onnx
    import onnxruntime as ort  # type: ignore[import-untyped]
    from onnx import numpy_helper

    shapes = {i.name: tuple(numpy_helper.to_array(i).shape) for i in model.graph.initializer}
    shapes.update({k: v.shape for k, v in feed.items()})
    outputs = {o.name for o in model.graph.output}
    for node in model.graph.node:
        for name in node.output:
            if name and name not in outputs and name not in shapes:
                model.graph.output.append(onnx.ValueInfoProto(name=name))
                outputs.add(name)
    opts = ort.SessionOptions()
    opts.intra_op_num_threads = 1
    opts.graph_optimization_level = ort.GraphOptimizationLevel.ORT_DISABLE_ALL  # the graph as written
    session = ort.InferenceSession(model.SerializeToString(), opts, providers=["CPUExecutionProvider"])
    names = [o.name for o in session.get_outputs()]
    wanted = {i.name for i in session.get_inputs()}
    for name, value in zip(names, session.run(names, {k: v for k, v in feed.items() if k in wanted}), strict=True):
        shapes[name] = tuple(np.shape(value))
    for node in model.graph.node:  # constants made by Constant nodes
        if node.op_type == "Constant" and node.output[0] not in shapes:
            shapes[node.output[0]] = ()
    return shapes


def _attr(node: Any, name: str, default: Any) -> Any:
    import onnx

    for a in node.attribute:
        if a.name == name:
            return onnx.helper.get_attribute_value(a)
    return default


def _node_flops(node: Any, shapes: dict[str, tuple[int, ...]]) -> int:
    op = node.op_type
    out = shapes.get(node.output[0], ()) if node.output else ()
    n_out = int(np.prod(out)) if out else 1
    ins = [shapes.get(i, ()) for i in node.input]
    if op == "MatMul":
        return 2 * n_out * int(ins[0][-1])
    if op == "Gemm":
        k = ins[0][0] if _attr(node, "transA", 0) else ins[0][-1]
        return 2 * n_out * int(k) + (n_out if len(ins) > 2 else 0)
    if op == "Conv":
        w = ins[1]
        return 2 * n_out * int(np.prod(w[1:])) + (n_out if len(ins) > 2 and node.input[2] else 0)
    if op in ("LSTM", "GRU"):
        seq, batch, size = ins[0]
        dirs, gates_h, _ = ins[1]
        hidden = int(_attr(node, "hidden_size", gates_h // (4 if op == "LSTM" else 3)))
        cell = 2 * gates_h * (size + hidden) + 10 * gates_h  # the two products and the gate arithmetic
        return int(seq * batch * dirs * cell)
    if op in FREE:
        return 0
    if op in ("Softmax", "LogSoftmax", "ReduceSum", "ReduceMean", "ReduceMax", "ReduceLogSumExp"):
        return 5 * int(np.prod(ins[0])) if op.endswith("Softmax") or op == "ReduceLogSumExp" else int(np.prod(ins[0]))
    return n_out


def graph_flops(path: str | Path, feed: dict[str, np.ndarray]) -> Flops:
    """The operations of the ONNX model at ``path`` on the inputs ``feed`` (the engine's preprocessed tensors)."""
    import onnx

    model = onnx.load(str(path))
    shapes = _shapes(model, feed)
    dense = other = 0
    for node in model.graph.node:
        f = _node_flops(node, shapes)
        if node.op_type in DENSE:
            dense += f
        else:
            other += f
    return Flops(dense, other)


def sgemm_gflops(n: int = 1024, repeat: int = 5) -> float:
    """numpy's float32 matrix product of two ``n``×``n`` matrices, GFLOP/s (median; the thread count numpy's BLAS
    runs with: set ``OPENBLAS_NUM_THREADS=1`` before numpy loads for one thread)."""
    import time

    rng = np.random.default_rng(0)
    a, b = rng.random((n, n), dtype=np.float32), rng.random((n, n), dtype=np.float32)
    a @ b
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        a @ b
        times.append(time.perf_counter() - t0)
    return 2 * n**3 / float(np.median(times)) / 1e9


def two_core_slowdown(n: int = 512, calls: int = 100) -> float:
    """How much slower each of two threads runs ``calls`` single-thread ``n``³ float32 products side by side than
    one thread alone (numpy's BLAS on one thread; it releases the GIL): with work split evenly in two, one call on
    two threads can take no less than half this of its one-thread time on this machine."""
    import threading
    import time

    rng = np.random.default_rng(0)
    a, b = rng.random((n, n), dtype=np.float32), rng.random((n, n), dtype=np.float32)

    def loop() -> None:
        for _ in range(calls):
            a @ b

    loop()
    t0 = time.perf_counter()
    loop()
    alone = time.perf_counter() - t0
    threads = [threading.Thread(target=loop) for _ in range(2)]
    t0 = time.perf_counter()
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    return (time.perf_counter() - t0) / alone
