//! File reading with errors that name the file (atomic writes are [`mesh::io::write_atomic`]).

use std::path::Path;

use crate::{LearnError, Result};

/// Reads a whole file.
pub(crate) fn read(path: &Path) -> Result<Vec<u8>> {
    std::fs::read(path).map_err(|e| LearnError::io(path, e))
}
