"""How quiet the machine was while a benchmark ran: the load average before and after, and the share of CPU time the
hypervisor stole from this virtual machine over the run (``steal`` in ``/proc/stat``; Linux only). A shared VM loses
time to its neighbours without any load of its own, which the load average does not show: a run with more than
:data:`NOISY_STEAL` stolen is flagged, and its times are not ones to publish (its ratios within a row are less
affected, since a row's figures are timed in interleaved rounds)."""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

#: Above this share of CPU time stolen during a run, its times are flagged as not from a quiet machine.
NOISY_STEAL = 0.02
#: Where Linux counts every CPU's time by state.
PROC_STAT = Path("/proc/stat")


def cpu_times(stat: Path = PROC_STAT) -> tuple[int, int] | None:
    """``(stolen, total)`` clock ticks of every CPU since boot from ``stat``'s ``cpu`` line (user, nice, system, idle,
    iowait, irq, softirq, steal; guest time is already inside user and nice), or None where it cannot be read."""
    try:
        line = next(x for x in stat.read_text().splitlines() if x.startswith("cpu "))
        ticks = [int(v) for v in line.split()[1:9]]
    except (OSError, StopIteration, ValueError):
        return None
    if len(ticks) < 8:
        return None
    return ticks[7], sum(ticks)


def stolen_share(before: tuple[int, int] | None, after: tuple[int, int] | None) -> float | None:
    """The share of CPU time stolen between two :func:`cpu_times` readings; None if either is missing or no time
    passed."""
    if before is None or after is None or after[1] <= before[1]:
        return None
    return (after[0] - before[0]) / (after[1] - before[1])


def load() -> str:
    """The 1, 5 and 15 minute load averages, as printed."""
    return " ".join(f"{v:.2f}" for v in os.getloadavg())


@contextmanager
def machine_report(stat: Path = PROC_STAT) -> Iterator[None]:
    """Prints the load average and the number of cores before the block, and after it the load average and the share
    of CPU time stolen while it ran, flagged above :data:`NOISY_STEAL`."""
    print(f"load average before: {load()}; {os.cpu_count()} cores")
    start = cpu_times(stat)
    yield
    share = stolen_share(start, cpu_times(stat))
    print(f"\nload average after: {load()}")
    if share is not None:
        flag = f" (over {NOISY_STEAL:.0%}: not a quiet machine; compare ratios within a row only)"
        flag = flag if share > NOISY_STEAL else ""
        print(f"CPU time stolen by the hypervisor during the run: {100 * share:.1f}%{flag}")
