"""Finding the ONNX Runtime shared library that the ``onnxruntime`` wheel ships, without importing it."""

from __future__ import annotations

import glob
import importlib.util
import os
import sys
from pathlib import Path

from dgan.exceptions import RuntimeLibraryError

ENV_VARS = ("DGAN_ONNXRUNTIME_LIBRARY", "ORT_DYLIB_PATH")


def _patterns() -> tuple[str, ...]:
    if sys.platform == "darwin":
        return ("libonnxruntime.*.dylib", "libonnxruntime.dylib")
    if sys.platform == "win32":
        return ("onnxruntime.dll",)
    return ("libonnxruntime.so.*", "libonnxruntime.so")


def onnxruntime_library() -> Path:
    """The absolute path of the ONNX Runtime library the engine loads.

    ``DGAN_ONNXRUNTIME_LIBRARY`` or ``ORT_DYLIB_PATH`` win; otherwise the library inside the installed
    ``onnxruntime`` package (``onnxruntime/capi/``).
    """
    for var in ENV_VARS:
        value = os.environ.get(var)
        if value:
            path = Path(value).expanduser().resolve()
            if not path.is_file():
                raise RuntimeLibraryError(f"{var}={value} does not name a file")
            return path
    spec = importlib.util.find_spec("onnxruntime")
    if spec is None or not spec.submodule_search_locations:
        raise RuntimeLibraryError(
            "the onnxruntime package is not installed: `pip install onnxruntime` "
            "(or set ORT_DYLIB_PATH to a libonnxruntime shared library)"
        )
    for location in spec.submodule_search_locations:
        capi = Path(location) / "capi"
        for pattern in _patterns():
            found = sorted(glob.glob(str(capi / pattern)))
            if found:
                return Path(found[-1]).resolve()
    raise RuntimeLibraryError(
        f"no ONNX Runtime library in {list(spec.submodule_search_locations)}/capi; reinstall onnxruntime"
    )
