"""benches/bench.py times the figures of a row in interleaved rounds, the slow ones in fewer of them."""

from __future__ import annotations

from itertools import pairwise

from benches.bench import interleaved_ms


def test_rounds_interleave_and_slow_pipelines_run_less_often() -> None:
    calls: list[str] = []
    ms = interleaved_ms(
        {"a": lambda: calls.append("a"), "b": lambda: calls.append("b"), "slow": lambda: calls.append("slow")},
        repeat=20,
        warmup=2,
        every={"slow": 5},
    )
    assert set(ms) == {"a", "b", "slow"}
    assert all(v >= 0 for v in ms.values())
    assert calls[:4] == ["a", "b", "slow", "a"]  # the slow one warmed up once
    assert calls.count("a") == calls.count("b") == 22
    timed_slow = calls.count("slow") - 1
    assert 3 <= timed_slow <= 20 // 5 + 3  # its first three timed rounds, then every fifth
    # Every round calls the fast ones in turn: never twice in a row.
    fast = [c for c in calls if c != "slow"]
    assert all(x != y for x, y in pairwise(fast))
