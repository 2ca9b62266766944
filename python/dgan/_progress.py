"""A progress bar on stderr for long work: tqdm where installed, a counter otherwise."""

from __future__ import annotations

import sys
from collections.abc import Iterator, Sequence
from typing import TypeVar

T = TypeVar("T")


def progress(items: Sequence[T], what: str) -> Iterator[T]:
    """Iterates ``items`` with a progress bar on stderr labelled ``what`` (a plural noun: ``"scenes"``)."""
    try:
        from tqdm import tqdm
    except ImportError:
        return _counted(items, what)
    bar: Iterator[T] = tqdm(items, unit=what.split()[0][:-1], desc=what, file=sys.stderr, disable=None)
    return bar


def _counted(items: Sequence[T], what: str) -> Iterator[T]:
    for i, item in enumerate(items, 1):
        yield item
        print(f"\r{what}: {i}/{len(items)}", end="\n" if i == len(items) else "", file=sys.stderr)
