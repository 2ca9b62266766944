"""benches/machine.py: the share of CPU time stolen over a run, read from /proc/stat's counters, and its report."""

from __future__ import annotations

from pathlib import Path

import pytest

from benches.machine import NOISY_STEAL, cpu_times, machine_report, stolen_share


def stat(tmp_path: Path, name: str, steal: int, idle: int) -> Path:
    """A /proc/stat whose every-CPU line has ``steal`` and ``idle`` ticks, guest time beside them (inside user)."""
    p = tmp_path / name
    p.write_text(f"cpu  100 5 50 {idle} 3 0 2 {steal} 40 0\ncpu0 50 2 25 10 1 0 1 0 20 0\nintr 1 2 3\n")
    return p


def test_stolen_ticks_come_from_the_every_cpu_line_without_guest_time(tmp_path: Path) -> None:
    assert cpu_times(stat(tmp_path, "a", steal=7, idle=840)) == (7, 100 + 5 + 50 + 840 + 3 + 0 + 2 + 7)


def test_the_share_is_of_the_time_between_two_readings() -> None:
    assert stolen_share((10, 1000), (35, 1100)) == pytest.approx(0.25)
    assert stolen_share((10, 1000), (10, 1000)) is None  # no time passed
    assert stolen_share(None, (35, 1100)) is None


def test_an_unreadable_or_foreign_stat_gives_none(tmp_path: Path) -> None:
    assert cpu_times(tmp_path / "missing") is None
    short = tmp_path / "short"
    short.write_text("cpu  1 2 3 4\n")
    assert cpu_times(short) is None
    (tmp_path / "garbled").write_text("cpu  a b c d e f g h\n")
    assert cpu_times(tmp_path / "garbled") is None


def test_a_run_with_time_stolen_is_flagged(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = stat(tmp_path, "s", steal=0, idle=800)
    with machine_report(path):
        stat(tmp_path, "s", steal=100, idle=800)  # 100 of 100 new ticks stolen
    out = capsys.readouterr().out
    assert "load average before:" in out
    assert "load average after:" in out
    assert "stolen by the hypervisor during the run: 100.0% (over 2%: not a quiet machine" in out
    with machine_report(path):
        stat(tmp_path, "s", steal=101, idle=899)  # 1 of 100
    assert NOISY_STEAL > 0.01
    assert "1.0%\n" in capsys.readouterr().out
