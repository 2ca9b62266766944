"""Finding and loading the ONNX Runtime library."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

import dgan
from dgan import exceptions as exc
from dgan._runtime import onnxruntime_library


def test_library_comes_from_the_onnxruntime_wheel(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("DGAN_ONNXRUNTIME_LIBRARY", raising=False)
    monkeypatch.delenv("ORT_DYLIB_PATH", raising=False)
    lib = onnxruntime_library()
    assert lib.is_absolute()
    assert lib.is_file()
    assert lib.parent.name == "capi"
    assert lib.name.startswith("libonnxruntime")


def test_environment_variable_must_name_a_file(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setenv("DGAN_ONNXRUNTIME_LIBRARY", str(tmp_path / "nope.so"))
    with pytest.raises(exc.RuntimeLibraryError, match="does not name a file"):
        onnxruntime_library()


def test_a_second_library_in_one_process_is_refused(nomap_model: Path, tmp_path: Path) -> None:
    dgan.Predictor(nomap_model)  # loads the wheel's library
    other = tmp_path / "libonnxruntime.so.9"
    other.write_bytes(b"\0")
    with pytest.raises(exc.RuntimeLibraryError, match="already loaded"):
        dgan.Predictor(nomap_model, onnxruntime_library=other)


@pytest.mark.parametrize("content", [None, b"this is not a shared library"])
def test_a_bad_library_is_a_typed_error(nomap_model: Path, tmp_path: Path, content: bytes | None) -> None:
    lib = tmp_path / "libonnxruntime.so.1"
    if content is not None:
        lib.write_bytes(content)
    script = (
        "import dgan, sys\n"
        "try:\n"
        f"    dgan.Predictor({str(nomap_model)!r}, onnxruntime_library={str(lib)!r})\n"
        "except dgan.exceptions.RuntimeLibraryError as e:\n"
        "    print('RuntimeLibraryError:', e); sys.exit(0)\n"
        "sys.exit(3)\n"
    )
    env = {k: v for k, v in os.environ.items() if k not in ("ORT_DYLIB_PATH", "DGAN_ONNXRUNTIME_LIBRARY")}
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, env=env, timeout=120)
    assert out.returncode == 0, out.stdout + out.stderr
    assert "RuntimeLibraryError" in out.stdout


def test_threads_must_be_positive(nomap_model: Path) -> None:
    with pytest.raises(exc.InvalidSpecError, match="threads"):
        dgan.Predictor(nomap_model, threads=0)
