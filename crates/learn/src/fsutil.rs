//! Atomic file writes: write a temporary file in the same directory, sync it, rename it.

use std::io::Write;
use std::path::Path;

use crate::{LearnError, Result};

/// Writes `bytes` to `path` atomically (a reader sees the old file or the new one, never a part).
pub(crate) fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    write_atomic_with(path, |file| file.write_all(bytes))
}

/// Writes `path` atomically with a writer callback.
pub(crate) fn write_atomic_with(
    path: &Path,
    fill: impl FnOnce(&mut std::io::BufWriter<std::fs::File>) -> std::io::Result<()>,
) -> Result<()> {
    mesh::io::write_file_atomic(path, fill).map_err(|e| LearnError::io(path, e))
}

/// Reads a whole file.
pub(crate) fn read(path: &Path) -> Result<Vec<u8>> {
    std::fs::read(path).map_err(|e| LearnError::io(path, e))
}
