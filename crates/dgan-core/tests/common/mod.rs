//! Helpers shared by the integration tests.
#![allow(dead_code)]

use std::path::PathBuf;
use std::process::Command;

/// The crate's folder as cargo gives it to the running test (`CARGO_MANIFEST_DIR` at run time; the compile-time
/// value only as a fallback), so that a test binary reused from a checkout elsewhere still finds the repository.
pub fn manifest_dir() -> PathBuf {
    std::env::var_os("CARGO_MANIFEST_DIR").map_or_else(|| env!("CARGO_MANIFEST_DIR").into(), Into::into)
}

/// The repository's `tests/fixtures` folder.
pub fn fixture(name: &str) -> PathBuf {
    manifest_dir().join("../../tests/fixtures").join(name)
}

/// The ONNX Runtime library: `ORT_DYLIB_PATH`, else the one in the onnxruntime wheel of `$DGAN_PYTHON` (or
/// `python3`). The README's test command sets `ORT_DYLIB_PATH`.
pub fn onnxruntime_library() -> PathBuf {
    if let Some(p) = std::env::var_os("ORT_DYLIB_PATH") {
        return PathBuf::from(p);
    }
    let python = std::env::var("DGAN_PYTHON").unwrap_or_else(|_| "python3".into());
    let script = "import glob, importlib.util, os\n\
                  spec = importlib.util.find_spec('onnxruntime')\n\
                  d = os.path.join(spec.submodule_search_locations[0], 'capi')\n\
                  print(sorted(glob.glob(os.path.join(d, 'libonnxruntime.so.*')))[-1])";
    let out = Command::new(&python).args(["-c", script]).output();
    match out {
        Ok(o) if o.status.success() => PathBuf::from(String::from_utf8_lossy(&o.stdout).trim()),
        _ => panic!(
            "set ORT_DYLIB_PATH to the libonnxruntime.so.* of the onnxruntime wheel (or install onnxruntime for \
             {python}); the README's test command does this"
        ),
    }
}
