"""Moved to :mod:`dgan.datasets.hdmaps` (dataset readers are outside the runtime's import path). This name still
works and warns; it will be removed in a later release."""

from __future__ import annotations

import warnings
from typing import Any

warnings.warn("dgan.hdmaps moved to dgan.datasets.hdmaps; import it from there", DeprecationWarning, stacklevel=2)


def __getattr__(name: str) -> Any:
    from dgan.datasets import hdmaps

    return getattr(hdmaps, name)
