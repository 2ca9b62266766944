"""Benchmarks: ``python benches/bench.py`` (latency, FLOPs), ``benches/soak.py`` (memory over many predicts)."""
