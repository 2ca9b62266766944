//! A model file is untrusted input: its exporter seals it with a SHA-256 digest of the whole file, written into
//! the contract (`"weights_sha256"`), and the engine verifies it before ONNX Runtime sees a byte, so a corrupt or
//! modified file is refused with [`DganError::ModelLoad`] instead of predicting kilometres off. The engine reads the
//! file once ([`read_verified`]) and gives ONNX Runtime the very bytes it verified: a file replaced between the check
//! and the load cannot slip through.
//!
//! The digest covers every byte of the file with the 64 hex characters of the digest itself set to `'0'`: sealing
//! computes it over the file as exported (the contract holding 64 zeros) and writes it in place, so the file keeps
//! its size and layout; verifying zeroes the same 64 bytes again and hashes.

use crate::error::{DganError, Result};
use sha2::{Digest, Sha256};
use std::path::Path;

/// The contract key of the digest.
pub const DIGEST_KEY: &str = "weights_sha256";
/// The largest model file the engine reads (ONNX's protobuf limit).
pub const MAX_MODEL_BYTES: u64 = 2 << 30;

/// Where the 64 hex characters of the digest start in the file, if it declares one: the value of the first
/// `"weights_sha256":` key (any spaces after the colon). A second occurrence is an error.
pub fn digest_offset(bytes: &[u8]) -> Result<Option<usize>> {
    let key = format!("\"{DIGEST_KEY}\":");
    let finder = |from: usize| bytes[from..].windows(key.len()).position(|w| w == key.as_bytes()).map(|p| p + from);
    let Some(at) = finder(0) else { return Ok(None) };
    if finder(at + key.len()).is_some() {
        return Err(DganError::Contract(format!("the key {DIGEST_KEY:?} appears more than once in the model file")));
    }
    let mut i = at + key.len();
    while bytes.get(i) == Some(&b' ') {
        i += 1;
    }
    let hex = bytes.get(i + 1..i + 65);
    if bytes.get(i) != Some(&b'"') || bytes.get(i + 65) != Some(&b'"') || !hex.is_some_and(is_lower_hex) {
        return Err(DganError::ModelLoad {
            path: Default::default(),
            reason: format!("the value of {DIGEST_KEY:?} is not 64 lowercase hex digits"),
        });
    }
    Ok(Some(i + 1))
}

fn is_lower_hex(s: &[u8]) -> bool {
    s.iter().all(|c| c.is_ascii_digit() || (b'a'..=b'f').contains(c))
}

/// The digest of a file's bytes with the 64 bytes at `offset` taken as `'0'`.
pub fn file_digest(bytes: &[u8], offset: usize) -> String {
    let mut h = Sha256::new();
    h.update(&bytes[..offset]);
    h.update([b'0'; 64]);
    h.update(&bytes[offset + 64..]);
    h.finalize().iter().map(|b| format!("{b:02x}")).collect()
}

fn read(path: &Path) -> Result<Vec<u8>> {
    let load = |reason: String| DganError::ModelLoad { path: path.to_path_buf(), reason };
    let len = std::fs::metadata(path).map_err(|e| load(e.to_string()))?.len();
    if len > MAX_MODEL_BYTES {
        return Err(load(format!("the file is {len} bytes; a model may have at most {MAX_MODEL_BYTES}")));
    }
    std::fs::read(path).map_err(|e| load(e.to_string()))
}

/// Verifies a sealed model file; returns its digest, or `None` for a file that declares none (contracts before 4).
pub fn verify(path: &Path) -> Result<Option<String>> {
    read_verified(path).map(|(_, digest)| digest)
}

/// Reads a model file once and verifies it: its bytes and its digest ([`verify`]).
pub fn read_verified(path: &Path) -> Result<(Vec<u8>, Option<String>)> {
    let bytes = read(path)?;
    let at_path = |e: DganError| match e {
        DganError::ModelLoad { reason, .. } => DganError::ModelLoad { path: path.to_path_buf(), reason },
        other => other,
    };
    let Some(offset) = digest_offset(&bytes).map_err(at_path)? else { return Ok((bytes, None)) };
    let declared = String::from_utf8_lossy(&bytes[offset..offset + 64]).into_owned();
    let actual = file_digest(&bytes, offset);
    if declared != actual {
        return Err(DganError::ModelLoad {
            path: path.to_path_buf(),
            reason: format!(
                "its SHA-256 is {actual} but its metadata says {declared}: the file is corrupt or was modified after \
                 export; download or export it again"
            ),
        });
    }
    Ok((bytes, Some(actual)))
}

/// Seals a model file in place: its contract must hold `"weights_sha256": "000…0"` (64 zeros), which becomes the
/// digest of the file. Returns the digest.
pub fn seal(path: &Path) -> Result<String> {
    let mut bytes = read(path)?;
    let offset = digest_offset(&bytes)?.ok_or_else(|| {
        DganError::Contract(format!("{} has no {DIGEST_KEY:?} placeholder in its contract to seal", path.display()))
    })?;
    if bytes[offset..offset + 64] != [b'0'; 64] {
        return Err(DganError::Contract(format!("{} is already sealed", path.display())));
    }
    let digest = file_digest(&bytes, offset);
    bytes[offset..offset + 64].copy_from_slice(digest.as_bytes());
    std::fs::write(path, &bytes)
        .map_err(|e| DganError::ModelLoad { path: path.to_path_buf(), reason: e.to_string() })?;
    Ok(digest)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn file(contents: &[u8]) -> std::path::PathBuf {
        let dir = std::env::temp_dir().join(format!("dgan-integrity-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join(format!("{}.bin", contents.len()));
        std::fs::write(&p, contents).unwrap();
        p
    }

    #[test]
    fn seal_then_verify_and_every_flipped_byte_is_caught() {
        let body = format!("weights\x00\x01{{\"a\": 1, \"{DIGEST_KEY}\": \"{}\"}}tail", "0".repeat(64));
        let p = file(body.as_bytes());
        assert!(verify(&p).is_err(), "the placeholder is not the digest");
        let digest = seal(&p).unwrap();
        assert_eq!(verify(&p).unwrap(), Some(digest.clone()));
        let sealed = std::fs::read(&p).unwrap();
        // The bytes handed on are the ones verified.
        assert_eq!(read_verified(&p).unwrap(), (sealed.clone(), Some(digest)));
        for i in 0..sealed.len() {
            let mut bad = sealed.clone();
            bad[i] ^= 0x01;
            std::fs::write(&p, &bad).unwrap();
            // Refused, or (a flip in the key's name) no digest found: a contract-4 model must declare one, so the
            // contract check refuses it then.
            assert!(!matches!(verify(&p), Ok(Some(_))), "flip at byte {i} not caught");
        }
    }

    #[test]
    fn files_without_a_digest_and_bad_values() {
        assert_eq!(verify(&file(b"no digest here")).unwrap(), None);
        let twice = format!("\"{DIGEST_KEY}\": \"{z}\" \"{DIGEST_KEY}\": \"{z}\"", z = "0".repeat(64));
        assert!(matches!(verify(&file(twice.as_bytes())), Err(DganError::Contract(_))));
        let short = format!("\"{DIGEST_KEY}\": \"abc\"");
        assert!(matches!(verify(&file(short.as_bytes())), Err(DganError::ModelLoad { .. })));
    }
}
