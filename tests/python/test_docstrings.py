"""Every example in the package's docstrings runs as written (``>>>`` lines, ``doctest: +SKIP`` aside)."""

from __future__ import annotations

import doctest
import importlib
import pkgutil

import pytest

import dgan

#: The package's Python modules, but the extension, the command line's entry point and ``dgan.hdmaps`` (a deprecated
#: alias of ``dgan.datasets.hdmaps`` that warns when imported).
MODULES = sorted(
    m.name
    for m in pkgutil.walk_packages(dgan.__path__, "dgan.")
    if not m.name.endswith(("._dgan", ".__main__")) and m.name != "dgan.hdmaps"
)


def test_the_modules_with_examples_are_found() -> None:
    assert {"dgan.evaluation", "dgan.layouts", "dgan.metrics", "dgan.series"} <= set(MODULES)


@pytest.mark.parametrize("name", MODULES)
def test_the_examples_run(name: str) -> None:
    result = doctest.testmod(importlib.import_module(name), optionflags=doctest.ELLIPSIS, report=True)
    assert result.failed == 0, f"{result.failed} of {name}'s {result.attempted} examples failed (printed above)"
