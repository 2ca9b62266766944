"""The engine against a bare ONNX Runtime session and the PyTorch-eager pipeline, measured in one run, one thread.

    python benches/bench.py [--models zara1 hdmap] [--agents 8 32 128 256] [--repeat 30]     # or: ./dev bench py
    python benches/bench.py --main-only --plot latency.png --json run.json    # the main table, drawn

For every bundled model, the real bundled scene of its time base (`dgan.demo.scene_for`) is tiled to N agents
(copies of the scene shifted by 60 m, so each copy keeps its own neighbourhood and map), and each figure is the
median over ``--repeat`` runs after warm-up, the figures of a row timed in interleaved rounds (`interleaved_ms`), so
that their ratios hold on a machine whose speed drifts:

- ``predict``: `dgan.Predictor.predict` (preprocessing, the network in ONNX Runtime, decoding), one intra-op thread;
- ``preprocess``: `dgan.preprocess` alone (traffic state, graph, map crops, prior), on one thread as `predict`;
- ``bare ORT``: an `onnxruntime.InferenceSession` (one thread) on the same preprocessed tensors;
- ``torch``: the training code's model from the same checkpoint (`training/checkpoints/<name>.pt`), eager, one
  thread, on the same tensors, plus `decode_torch`; ``torch pipeline`` adds the engine's preprocessing to it;
- ``vs torch``: torch pipeline / predict (above 1: the engine is faster); for a model that keeps its map features
  (contract 13), ``preprocess`` is predict's own (its kept tiles' reading included: ``last_timings``) and torch runs
  on the tensors the network then gets, every tile kept;
- ``research``: the research-style pipeline (`benches/research.py`: preprocessing in numpy from the contract, the
  same network in eager PyTorch, decoding in numpy; what a researcher would run instead), on the same frame;
  ``vs research``: research / predict;
- ``MFLOP/agent``: the network's operations per agent on this call, counted node by node from the shapes it runs
  (`benches/flops.py`), and ``GFLOP/s`` of the bare session: those operations over its time, against the same run's
  single-thread float32 sgemm (numpy, 1024², printed first).

``--session-options``: the bare session under other ONNX Runtime options (no memory arena, no memory pattern, fewer
graph optimisations, two intra-op threads, the parallel executor on two inter-op threads) as multiples of the engine's
options' time.

Then one `predict` on 1 and 2 threads (also as multiples of the run's single-thread 512³ matmul, and beside the floor
two side-by-side matmul loops set for evenly split work on this machine), the
throughput of one `Predictor` shared by 1 and 2 Python threads, and of `predict_batch` against a loop of `predict`
(on one thread, and with ``threads=2`` against the loop on one and on two threads).
The machine's load average is printed before and after, and the share of CPU time the hypervisor stole during the
run (`benches/machine.py`; flagged over 2%): run it on a quiet machine. This is a benchmark, not a test;
no figure here is asserted anywhere.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import threading
import time
from collections.abc import Callable
from functools import partial
from pathlib import Path
from typing import Any

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # numpy's sgemm reference on one thread, as the sessions run
os.environ.setdefault("OMP_NUM_THREADS", "1")
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import dgan  # noqa: E402
from benches import plot, research  # noqa: E402
from benches.flops import graph_flops, sgemm_gflops, two_core_slowdown  # noqa: E402
from benches.machine import machine_report  # noqa: E402
from dgan.contract import KEPT_INPUTS, KEPT_OUTPUT  # noqa: E402
from dgan.demo import scene_for  # noqa: E402

SPACING_M = 60.0


def tiled(frame: dgan.Frame, n: int) -> dgan.Frame:
    """``n`` agents: copies of ``frame`` side by side, ``SPACING_M`` apart, cut to ``n``."""
    k = -(-n // len(frame))
    side = int(np.ceil(np.sqrt(k)))
    shifts = np.array([[SPACING_M * (i % side), SPACING_M * (i // side)] for i in range(k)])
    pos = np.concatenate([frame.positions + s for s in shifts])[:n]

    def rep(a: np.ndarray) -> np.ndarray:
        return np.concatenate([a] * k)[:n]

    return dgan.Frame(
        pos,
        mask=rep(frame.mask),
        classes=rep(np.array(frame.classes)).tolist(),
        headings=rep(frame.headings),
        velocities=rep(frame.velocities),
        lengths=rep(frame.lengths),
        widths=rep(frame.widths),
        map=frame.map,
    )


def median_ms(fn: Callable[[], Any], repeat: int, warmup: int = 3) -> float:
    for _ in range(warmup):
        fn()
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return 1e3 * statistics.median(times)


def interleaved_ms(
    fns: dict[str, Callable[[], Any]], repeat: int, warmup: int = 3, every: dict[str, int] | None = None
) -> dict[str, float]:
    """The median milliseconds of each of ``fns``, timed in interleaved rounds (each round calls every one once, in
    turn), so that a machine whose speed drifts over a row (another job, a noisy neighbour on a VM) moves all of the
    row's figures alike and their ratios stay fair; ``every[key] = k`` times ``key`` only in every k-th round (a slow
    pipeline), at least 3 times."""
    every = every or {}
    times: dict[str, list[float]] = {k: [] for k in fns}
    for r in range(warmup + repeat):
        for key, fn in fns.items():
            k = every.get(key, 1)
            if (0 < r < warmup and k > 1) or (r >= warmup and (r - warmup) % k and len(times[key]) >= 3):
                continue  # a slow one: warmed up once, timed in every k-th round
            t0 = time.perf_counter()
            fn()
            if r >= warmup:
                times[key].append(time.perf_counter() - t0)
    return {key: 1e3 * statistics.median(v) for key, v in times.items()}


def torch_pipeline(name: str, device: str = "cpu") -> Callable[[dict[str, np.ndarray]], Any] | None:
    """The training code's model from the bundled checkpoint, eager, with `decode_torch`; None without torch. On
    ``device`` (``"cuda"``: the preprocessed tensors are copied there and the decoded modes back, as the engine's CUDA
    provider does); on one thread on the CPU."""
    try:
        import torch

        from training.data.batches import INPUTS
        from training.export import load_checkpoint
        from training.losses import DecodingKeys, decode_torch
        from training.modules.consensus import ConsensusEnsemble
    except ImportError:
        return None
    torch.set_num_threads(1)
    ckpt = ROOT / "training" / "checkpoints" / f"{name}.pt"
    model, spec, anchors, class_of, _, cal = load_checkpoint(ckpt)
    model = model.to(device)
    a, c = torch.from_numpy(anchors).to(device), torch.from_numpy(class_of).long().to(device)
    # The contract's decoding keys, as the engine applies them (a consensus's top-mode scale is in its forward).
    declared = dgan.Predictor(name, sessions=1).contract
    keys = DecodingKeys.of(declared, spec.classes, isinstance(model, ConsensusEnsemble), device)

    def run(x: dict[str, np.ndarray]) -> Any:
        with torch.no_grad():
            named = {k: torch.from_numpy(x[k]).to(device) for k in (*INPUTS, *KEPT_INPUTS) if k in x}
            out = model(**named) if "map_patches" in named else model(*named.values())
            cl, al, off = out[0], out[1], out[2]
            prior = torch.from_numpy(x["prior"]).to(device)
            t = cal.anchor_temperatures(prior, spec.dt_s)
            still, scale, power = keys.still(x), keys.top_scale, keys.top_mean
            modes, p = decode_torch(cl, al, off, a, c, prior, t, cal.class_temperature, still, scale, power)
            return modes.cpu().numpy(), p.cpu().numpy()

    return run


def bare_session(path: Path, options: dict[str, Any] | None = None) -> Any:
    """An ONNX Runtime session on one thread, with ``options`` (``SessionOptions`` attributes; a graph optimisation
    level by its name) set beside ONNX Runtime's defaults."""
    import onnxruntime as ort  # type: ignore[import-untyped]

    opts = ort.SessionOptions()
    opts.intra_op_num_threads = 1
    opts.inter_op_num_threads = 1
    enums = {"execution_mode": ort.ExecutionMode, "graph_optimization_level": ort.GraphOptimizationLevel}
    for key, value in (options or {}).items():
        setattr(opts, key, getattr(enums[key], value) if isinstance(value, str) else value)  # a member by its name
    return ort.InferenceSession(str(path), opts, providers=["CPUExecutionProvider"])


def warm_inputs(session: Any, x: dict[str, np.ndarray], spec: dgan.InputSpec) -> dict[str, np.ndarray]:
    """A kept-features model's network inputs (contract 13) once its tiles are kept, from ``dgan.preprocess``'s
    ``x`` (every tile to compute): no tile, each agent's reading of the tiles' features (``dgan.read_kept``), as
    ``predict`` feeds its network on every call after the map's first."""
    m = spec.map
    assert m is not None
    sc, grid = m.scene, m.scene_grid
    assert sc is not None
    assert grid is not None
    names = [i.name for i in session.get_inputs()]
    blank = np.zeros((len(x["trajectory"]), sc.channels, *grid), np.float32)
    (rows,) = session.run([KEPT_OUTPUT], {k: blank if k == "map_patches" else x[k] for k in names})
    patches = dgan.read_kept(np.concatenate([x["map_rows"], rows]), x["map_index"], x["map_weight"], grid)
    return {k: x[k] for k in names if k != "map_patches"} | {"map": x["map"][:0], "map_patches": patches}


def call_inputs(predictor: dgan.Predictor, frame: dgan.Frame) -> dict[str, np.ndarray]:
    """``dgan.preprocess``'s tensors of ``frame`` as ``predict`` feeds them to the network: of a kept-features model
    (contract 13) once the map's tiles are kept (:func:`warm_inputs`)."""
    x = dgan.preprocess(frame, predictor.spec)
    return x | warm_inputs(bare_session(predictor.path), x, predictor.spec) if "map_rows" in x else x


def bench_model(name: str, agents: list[int], repeat: int) -> list[dict[str, Any]]:
    predictor = dgan.Predictor(name)
    spec = predictor.spec
    frame = scene_for(spec).frame
    session = bare_session(predictor.path)
    names = [i.name for i in session.get_inputs()]
    torch_run = torch_pipeline(name)
    research_run = research.pipeline(name)
    rows = []
    for n in agents:
        f = tiled(frame, n)
        x = dgan.preprocess(f, spec)
        row: dict[str, Any] = {"model": name, "N": n, "E": len(x["edge_index"])}
        if "map_rows" in x:  # kept features (contract 13): every call after the first reads the map's tiles
            x = x | warm_inputs(session, x, spec)
        feed = {k: x[k] for k in names}
        kept: list[float] = []  # a kept-features model's own preprocessing in predict (its tiles' reading included)

        def predict_timed(f: dgan.Frame = f, kept: list[float] = kept, reads: bool = "map_rows" in x) -> None:
            predictor.predict(f)
            t = predictor.last_timings
            if t is not None and reads:
                kept.append(t["preprocess"] + t["crops"])

        fns: dict[str, Callable[[], Any]] = {
            "predict": predict_timed,
            "preprocess": partial(dgan.preprocess, f, spec, threads=1),
            "ort": partial(session.run, None, feed),
        }
        if torch_run is not None:
            fns["torch"] = partial(torch_run, x)
        if research_run is not None:
            fns["research"] = partial(research_run, f)
        row.update(interleaved_ms(fns, repeat, every={"research": 5}))
        if kept:  # dgan.preprocess draws every tile; predict, once the map's tiles are kept, reads them
            row["preprocess"] = statistics.median(kept)
        flops = graph_flops(predictor.path, feed).total
        row["mflop_per_agent"] = flops / n / 1e6
        row["gflops"] = flops / (row["ort"] * 1e-3) / 1e9
        if torch_run is not None:
            row["torch_pipeline"] = row["preprocess"] + row["torch"]
            row["vs_torch"] = row["torch_pipeline"] / row["predict"]
        if research_run is not None:
            row["vs_research"] = row["research"] / row["predict"]
        rows.append(row)
        print(fmt_row(row), flush=True)
    return rows


def fmt_row(r: dict[str, Any]) -> str:
    cells = [r["model"], str(r["N"]), str(r["E"])]
    cells += [f"{r[k]:.2f}" for k in ("predict", "preprocess", "ort")]
    cells += [f"{r[k]:.2f}" if k in r else "-" for k in ("torch", "torch_pipeline")]
    cells.append(f"{r['vs_torch']:.2f}×" if "vs_torch" in r else "-")
    cells.append(f"{r['research']:.1f}" if "research" in r else "-")
    cells.append(f"{r['vs_research']:.1f}×" if "vs_research" in r else "-")
    cells += [f"{r['mflop_per_agent']:.2f}", f"{r['gflops']:.1f}"]
    return "| " + " | ".join(cells) + " |"


def throughput(name: str, n: int, calls: int, rounds: int = 5) -> None:
    """Predictions per second of one Predictor shared by 1 and 2 threads (medians of ``rounds`` alternating
    rounds)."""
    predictor = dgan.Predictor(name)
    frame = tiled(scene_for(predictor.spec).frame, n)
    predictor.predict(frame)

    def per_second(threads: int) -> float:
        def work() -> None:
            for _ in range(calls // threads):
                predictor.predict(frame)

        ts = [threading.Thread(target=work) for _ in range(threads)]
        t0 = time.perf_counter()
        for t in ts:
            t.start()
        for t in ts:
            t.join()
        return (calls // threads) * threads / (time.perf_counter() - t0)

    # Alternating rounds, medians: one round of a second or so is at the mercy of the machine's noise.
    ones, twos = [], []
    for _ in range(rounds):
        ones.append(per_second(1))
        twos.append(per_second(2))
    one, two = float(np.median(ones)), float(np.median(twos))
    print(f"| {name} | {n} | {one:.0f} | {two:.0f} | {two / one:.2f}× |", flush=True)


def largest_component(n: int, edges: np.ndarray) -> int:
    """The most agents in one component of a frame's attention graph (a frame splits across threads by them)."""
    parent = list(range(n))

    def root(x: int) -> int:
        while parent[x] != x:
            parent[x] = parent[parent[x]]
            x = parent[x]
        return x

    for a, b in edges.tolist():
        parent[root(a)] = root(b)
    roots = [root(i) for i in range(n)]
    return max((roots.count(r) for r in set(roots)), default=0)


def latency(name: str, agents: list[int], repeat: int, matmul_ms: float) -> None:
    """One `predict` on 1 and on 2 threads (``Predictor(threads=...)``: a frame whose graph's components share out
    evenly as two concurrent single-threaded calls, any other on two intra-op threads), and each as a multiple of the
    same run's single-thread 512³ float32 matrix product, so that the figure travels between machines."""
    by_threads = {t: dgan.Predictor(name, threads=t, sessions=1) for t in (1, 2) if t <= (os.cpu_count() or 1)}
    frame = scene_for(by_threads[1].spec).frame
    for n in agents:
        f = tiled(frame, n)
        ms = {
            int(t): v
            for t, v in interleaved_ms({str(t): partial(p.predict, f) for t, p in by_threads.items()}, repeat).items()
        }
        two = ms.get(2, float("nan"))
        cells = [
            str(largest_component(n, by_threads[1].predict(f).edges)),
            f"{ms[1]:.2f}",
            f"{two:.2f}",
            f"{two / ms[1]:.2f}",
            f"{ms[1] / matmul_ms:.2f}",
            f"{two / matmul_ms:.2f}",
        ]
        print(f"| {name} | {n} | " + " | ".join(cells) + " |", flush=True)


def latency_table(models: list[str], repeat: int, matmul_ms: float) -> None:
    print(
        "\n| model | N | largest component | predict ms, 1 thread | 2 threads | 2 / 1 | 1 thread / 512³ matmul "
        "| 2 threads / matmul |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for name in models:
        latency(name, [32, 256], repeat, matmul_ms)
    slow = two_core_slowdown()
    print(
        f"\nTwo single-thread 512³ matmul loops side by side: each {slow:.2f}× as long as one alone, so evenly split "
        f"work takes at least {slow / 2:.2f} of its one-thread time on two threads here."
    )


def matched_difference(a: dgan.Prediction, b: dgan.Prediction) -> tuple[float, float]:
    """Largest difference of two predictions of the same frame, robust to near-tied modes that change order: each
    mode of ``a`` against the nearest mode of ``b`` (metres), and the sorted mode probabilities."""
    ta, tb = a.trajectories, b.trajectories  # (N, K, T, 2)
    gap = np.abs(ta[:, :, None] - tb[:, None]).max(axis=(3, 4))  # (N, K, K)
    return float(gap.min(axis=2).max()), float(np.abs(a.probabilities - b.probabilities).max())


def large(name: str, library: str, provider: str, threads: int) -> dgan.Predictor:
    """A Predictor with the limits on edges and input bytes raised for thousands of tiled agents."""
    return dgan.Predictor(
        name,
        onnxruntime_library=library,
        execution_provider=provider,
        threads=threads,
        max_edges=50_000_000,
        max_input_bytes=16 << 30,
    )


def cuda_table(models: list[str], agents: list[int], repeat: int, library: str) -> None:
    """The engine on ONNX Runtime's CUDA provider against the same checkpoint in eager PyTorch on CUDA (and the
    engine on the CPU with the same library), at large N; medians over ``repeat`` calls (a quarter of them on the
    CPU). The engine's preprocessing (and so each pipeline's) runs on one thread and on every core."""
    import torch

    # Plain float32 on both sides, as the engine asks of ONNX Runtime (TF32 moves the outputs by about 1e-3 m).
    torch.backends.cuda.matmul.allow_tf32 = False
    torch.backends.cudnn.allow_tf32 = False
    cores = os.cpu_count() or 1
    print(f"\nGPU: {torch.cuda.get_device_name(0)}; torch {torch.__version__}; ONNX Runtime library {library}")
    print(
        f"\n| model | N | E | preprocess ms, 1 / {cores} threads | predict ms, CUDA, 1 / {cores} threads "
        f"| predict ms, CPU 1 / {cores} threads | torch CUDA ms | torch CUDA pipeline ms, 1 / {cores} threads "
        f"| vs torch CUDA, 1 / {cores} | CUDA vs CPU: modes m, p |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|")
    for name in models:
        gpu = {t: large(name, library, "cuda", t) for t in (1, cores)}
        cpu = large(name, library, "cpu", 1)
        cpu_all = large(name, library, "cpu", cores)
        eager = torch_pipeline(name, device="cuda")
        frame = scene_for(cpu.spec).frame
        for n in agents:
            f = tiled(frame, n)
            x = dgan.preprocess(f, cpu.spec, threads=1)
            pre = {t: median_ms(partial(dgan.preprocess, f, cpu.spec, threads=t), repeat) for t in gpu}
            on_gpu = {t: median_ms(partial(p.predict, f), repeat) for t, p in gpu.items()}
            on_cpu = median_ms(partial(cpu.predict, f), max(3, repeat // 4), warmup=1)
            on_cpu_all = median_ms(partial(cpu_all.predict, f), max(3, repeat // 4), warmup=1)
            modes_m, p_diff = matched_difference(gpu[1].predict(f), cpu.predict(f))
            cells = [str(n), str(len(x["edge_index"])), f"{pre[1]:.1f} / {pre[cores]:.1f}"]
            cells += [f"{on_gpu[1]:.1f} / {on_gpu[cores]:.1f}", f"{on_cpu:.1f} / {on_cpu_all:.1f}"]
            if eager is not None:
                eager_ms = median_ms(partial(eager, x), repeat)
                pipe = {c: pre[c] + eager_ms for c in gpu}
                cells += [f"{eager_ms:.2f}", f"{pipe[1]:.1f} / {pipe[cores]:.1f}"]
                cells.append(f"{pipe[1] / on_gpu[1]:.2f}× / {pipe[cores] / on_gpu[cores]:.2f}×")
            else:
                cells += ["-", "-", "-"]
            cells.append(f"{modes_m:.1e}, {p_diff:.1e}")
            print(f"| {name} | " + " | ".join(cells) + " |", flush=True)


def phases_ms(predictor: dgan.Predictor, frame: dgan.Frame, repeat: int) -> dict[str, float]:
    """Median of each phase of ``Predictor.last_timings`` (and of the whole ``predict`` seen from Python, ``predict``)
    over ``repeat`` calls after three of warm-up."""
    for _ in range(3):
        predictor.predict(frame)
    seen: dict[str, list[float]] = {}
    for _ in range(repeat):
        t0 = time.perf_counter()
        predictor.predict(frame)
        seen.setdefault("predict", []).append(1e3 * (time.perf_counter() - t0))
        for key, ms in (predictor.last_timings or {}).items():
            seen.setdefault(key, []).append(ms)
    return {key: statistics.median(v) for key, v in seen.items()}


def phase_table(
    models: list[str], agents: list[int], threads: list[int], repeat: int, library: str | None, provider: str
) -> None:
    """Where ``predict``'s time goes (``Predictor.last_timings``) on ``provider``, per model, N and thread count:
    medians over ``repeat`` calls; ``rest`` is the Python side (the frame handed over, the prediction wrapped)."""
    print(f"\nWhere the time goes ({provider}; medians of {repeat} calls; ms)")
    print("\n| model | N | threads | predict | preprocess | crops | network | decode | split parts | rest |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for name in models:
        for t in threads:
            predictor = large(name, library, provider, t) if library else dgan.Predictor(name, threads=t)
            frame = scene_for(predictor.spec).frame
            for n in agents:
                m = phases_ms(predictor, tiled(frame, n), repeat)
                cells = [name, str(n), str(t)] + [f"{m[k]:.2f}" for k in ("predict", "preprocess", "crops")]
                cells += [f"{m[k]:.2f}" for k in ("network", "decode", "parts")]
                cells.append(f"{m['predict'] - m['total']:.2f}")
                print("| " + " | ".join(cells) + " |", flush=True)


def real_frames(predictor: dgan.Predictor, count: int) -> list[dgan.Frame]:
    """``count`` real frames of the bundled scene at successive times (cycling when the scene is shorter)."""
    first = scene_for(predictor.spec)
    frames = []
    for k in range(count):
        try:
            frames.append(scene_for(predictor.spec, first.default_now + k * first.time_step).frame)
        except dgan.DganError:
            break
    return [frames[k % len(frames)] for k in range(count)]


def batch_throughput(name: str, count: int, repeat: int) -> None:
    """`predict_batch` of ``count`` real frames against a loop of `predict` over them, with one thread and, where the
    machine has two cores, with ``threads=2`` (the batch's network calls concurrently on two lanes) against the loop
    on one thread and on two."""
    by_threads = {t: dgan.Predictor(name, threads=t) for t in (1, 2) if t <= (os.cpu_count() or 1)}
    frames = real_frames(by_threads[1], count)
    agents = sum(len(f) for f in frames) / len(frames)

    def loop_of(p: dgan.Predictor) -> list[dgan.Prediction]:
        return [p.predict(f) for f in frames]

    fns: dict[str, Callable[[], Any]] = {f"loop {t}": partial(loop_of, p) for t, p in by_threads.items()}
    fns.update({f"batch {t}": partial(p.predict_batch, frames) for t, p in by_threads.items()})
    ms = interleaved_ms(fns, repeat)
    loop = {t: ms[f"loop {t}"] for t in by_threads}
    batch = {t: ms[f"batch {t}"] for t in by_threads}
    row = f"| {name} | {count} | {agents:.1f} | {loop[1]:.2f} | {batch[1]:.2f} | {loop[1] / batch[1]:.2f}×"
    if 2 in by_threads:
        row += f" | {loop[2]:.2f} | {batch[2]:.2f} | {loop[1] / batch[2]:.2f}× | {loop[2] / batch[2]:.2f}×"
    print(row + " |", flush=True)


def flops_table(models: list[str], agents: list[int]) -> None:
    """MFLOP per agent of each model's network on its bundled scene tiled to each N (counted, not timed)."""
    print("| model | N | MFLOP per agent (dense + other) |\n|---|---|---|")
    for name in models:
        p = dgan.Predictor(name, sessions=1)
        for n in agents:
            f = graph_flops(p.path, call_inputs(p, tiled(scene_for(p.spec).frame, n)))
            print(f"| {name} | {n} | {f.total / n / 1e6:.2f} ({f.dense / n / 1e6:.2f} + {f.other / n / 1e6:.2f}) |")


#: ONNX Runtime session options against the engine's (all graph optimisations, the memory arena and patterns on).
SESSION_VARIANTS: dict[str, dict[str, Any]] = {
    "no memory arena": {"enable_cpu_mem_arena": False},
    "no memory pattern": {"enable_mem_pattern": False},
    "extended optimisations only": {"graph_optimization_level": "ORT_ENABLE_EXTENDED"},
    "basic optimisations only": {"graph_optimization_level": "ORT_ENABLE_BASIC"},
    # What a frame that does not split has on two cores: one call on two intra-op threads, or the parallel executor
    # running independent branches (the trajectory LSTM beside the map CNN) on two inter-op threads.
    "two intra-op threads": {"intra_op_num_threads": 2},
    "parallel executor, two inter-op threads": {"execution_mode": "ORT_PARALLEL", "inter_op_num_threads": 2},
}


def session_options_table(models: list[str], agents: list[int], repeat: int) -> None:
    """The bare session (the engine's options, one thread) under each of :data:`SESSION_VARIANTS` (one thread unless
    the variant names more), as a multiple of the engine's options' time (above 1: slower), every session of a row
    timed in interleaved rounds on the same inputs."""
    print("\n| model | N | engine's options ms | " + " | ".join(SESSION_VARIANTS) + " |")
    print("|---|---|---|" + "---|" * len(SESSION_VARIANTS))
    for name in models:
        p = dgan.Predictor(name, sessions=1)
        for n in agents:
            x = call_inputs(p, tiled(scene_for(p.spec).frame, n))  # a kept-features model's: its tiles kept
            sessions = {"engine": bare_session(p.path)}
            sessions.update({label: bare_session(p.path, options) for label, options in SESSION_VARIANTS.items()})
            feed = {i.name: x[i.name] for i in sessions["engine"].get_inputs()}
            times: dict[str, list[float]] = {k: [] for k in sessions}
            for k in range(repeat + 3):
                for label, s in sessions.items():
                    t = time.perf_counter()
                    s.run(None, feed)
                    if k >= 3:
                        times[label].append(time.perf_counter() - t)
            base = statistics.median(times["engine"])
            cells = " | ".join(f"{statistics.median(times[k]) / base:.2f}" for k in SESSION_VARIANTS)
            print(f"| {name} | {n} | {base * 1e3:.2f} | {cells} |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--models", nargs="*", default=list(dgan.models.list()))
    ap.add_argument("--agents", nargs="*", type=int, default=[8, 32, 128, 256])
    ap.add_argument("--repeat", type=int, default=30)
    ap.add_argument("--calls", type=int, default=200, help="predictions per throughput measurement")
    ap.add_argument("--flops", action="store_true", help="only the operations per agent (no timing)")
    ap.add_argument("--plot", type=Path, help="also draw the main table's times against N into this PNG")
    ap.add_argument("--json", type=Path, help="also write the main table's rows (and the run's sgemm) as JSON")
    ap.add_argument("--main-only", action="store_true", help="only the main table (no threads, throughput, batches)")
    ap.add_argument("--latency", action="store_true", help="only one predict on 1 and 2 threads")
    ap.add_argument("--session-options", action="store_true", help="only ONNX Runtime's options against the engine's")
    ap.add_argument(
        "--phases",
        action="store_true",
        help="only where predict's time goes, on 1 and 2 threads (with --cuda: on CUDA, 1 to every core)",
    )
    ap.add_argument(
        "--cuda",
        metavar="LIBONNXRUNTIME",
        help="only the CUDA provider (absolute path of onnxruntime-gpu's libonnxruntime.so) against eager PyTorch on "
        "CUDA, at --agents (e.g. 256 1024 4096)",
    )
    a = ap.parse_args()
    with machine_report():
        run(a)


def run(a: argparse.Namespace) -> None:
    """The tables ``a`` asks for (:func:`main`'s options)."""
    if a.cuda:
        if not a.phases:
            cuda_table(a.models, a.agents, a.repeat, a.cuda)
        phase_table(a.models, a.agents, sorted({1, 2, 4, 8, os.cpu_count() or 1}), a.repeat, a.cuda, "cuda")
        return
    if a.flops:
        flops_table(a.models, a.agents)
        return
    if a.phases:
        phase_table(a.models, a.agents, [1, 2], a.repeat, None, "cpu")
        return
    sgemm = sgemm_gflops()
    print(f"single-thread sgemm (numpy float32, 1024²): {sgemm:.1f} GFLOP/s")
    matmul_ms = 2 * 512**3 / sgemm_gflops(512, 15) / 1e6
    print(f"single-thread 512³ float32 matmul: {matmul_ms:.2f} ms")
    if a.session_options:
        session_options_table(a.models, a.agents, a.repeat)
        return
    if a.latency:
        latency_table(a.models, a.repeat, matmul_ms)
        return
    print(
        "\n| model | N | E | predict ms | preprocess ms | bare ORT ms | torch ms | torch pipeline ms | vs torch "
        "| research ms | vs research | MFLOP/agent | bare ORT GFLOP/s |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    rows = [row for name in a.models for row in bench_model(name, a.agents, a.repeat)]
    about = {"date": time.strftime("%Y-%m-%d %H:%M"), "sgemm_gflops": sgemm, "repeat": a.repeat}
    if a.json:
        plot.save_run(rows, about, a.json)
    if a.plot:
        plot.latency_figure(rows, plot.title_of(about)).savefig(a.plot, dpi=110)
    if a.main_only:
        return
    latency_table(a.models, a.repeat, matmul_ms)
    print("\n| model | N | 1 thread /s | 2 threads /s | 2 vs 1 |")
    print("|---|---|---|---|---|")
    for name in a.models:
        throughput(name, 32, a.calls)
    print(
        "\n| model | frames | agents per frame | loop of predict ms | predict_batch ms | batch vs loop "
        "| loop, 2 threads | predict_batch, 2 threads | vs the 1-thread loop | vs the 2-thread loop |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|")
    for name in a.models:
        batch_throughput(name, 64, max(3, a.repeat // 5))


if __name__ == "__main__":
    main()
