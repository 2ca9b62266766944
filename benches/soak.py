"""Soak: does memory stay flat over a million predicts and a thousand predictors made and dropped?

    python benches/soak.py [--predicts 1000000] [--cycles 1000]   (./dev bench soak)

Prints the resident set size (RSS, from /proc/self/status) after warm-up and at checkpoints, and the growth per
1,000 calls after warm-up. Not a timed test: a long run, reported in the README and the closing notes.
"""

from __future__ import annotations

import argparse
import gc
import os
import time

import numpy as np

import dgan
from dgan.demo import apollo_scene


def rss_mib() -> float:
    """The process's resident set size in MiB."""
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    return float("nan")


def soak_predicts(n: int) -> tuple[float, float]:
    predictor = dgan.Predictor("apolloscape", sessions=1)
    frame = apollo_scene(predictor.spec.t_obs, predictor.spec.t_f, None).frame
    warm = min(50_000, n // 10)
    for _ in range(warm):
        predictor.predict(frame)
    gc.collect()
    start, t0 = rss_mib(), time.perf_counter()
    print(f"predict: {len(frame)} agents of a real ApolloScape frame; RSS after {warm:,} warm-up calls {start:.1f} MiB")
    step = max(1, (n - warm) // 5)
    for done in range(warm, n, step):
        for _ in range(min(step, n - done)):
            predictor.predict(frame)
        print(
            f"  after {min(done + step, n):>9,} predicts: RSS {rss_mib():7.1f} MiB ({time.perf_counter() - t0:.0f} s)"
        )
    gc.collect()
    return start, rss_mib()


def soak_cycles(n: int) -> tuple[float, float]:
    warm = min(100, n // 10)
    frame = dgan.Frame(np.cumsum(np.full((3, 8, 2), 0.4), axis=1))
    for _ in range(warm):
        dgan.Predictor("zara1", sessions=1).predict(frame)
    gc.collect()
    start = rss_mib()
    print(f"create/predict/drop: RSS after {warm} warm-up cycles {start:.1f} MiB")
    for k in range(warm, n):
        dgan.Predictor("zara1", sessions=1).predict(frame)
        if (k + 1) % max(1, n // 5) == 0:
            gc.collect()
            print(f"  after {k + 1:>6,} cycles: RSS {rss_mib():7.1f} MiB")
    gc.collect()
    return start, rss_mib()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--predicts", type=int, default=1_000_000)
    ap.add_argument("--cycles", type=int, default=1_000)
    a = ap.parse_args()
    print(f"load average before: {os.getloadavg()[0]:.2f}")
    p0, p1 = soak_predicts(a.predicts)
    c0, c1 = soak_cycles(a.cycles)
    print(f"load average after: {os.getloadavg()[0]:.2f}")
    print(
        f"summary: {a.predicts:,} predicts {p0:.1f} -> {p1:.1f} MiB ({p1 - p0:+.1f}); "
        f"{a.cycles:,} create/drop cycles {c0:.1f} -> {c1:.1f} MiB ({c1 - c0:+.1f})"
    )


if __name__ == "__main__":
    main()
