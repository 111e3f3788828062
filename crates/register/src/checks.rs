//! Checks of what a registration is given: its settings and its point clouds.

use mesh::Point;

use crate::{RegisterError, Result};

/// `Ok` when a setting is `ok` and finite, else an error naming it, its value and the `rule`
/// it breaks ("capture_decay = 1.5 must be in (0, 1]").
pub(crate) fn check_setting(name: &str, value: f64, ok: bool, rule: &str) -> Result<()> {
    match ok && value.is_finite() {
        true => Ok(()),
        false => Err(RegisterError::Invalid(format!("{name} = {value} must be {rule}"))),
    }
}

/// Rejects an empty cloud or one with a non-finite coordinate, or one beyond
/// [`mesh::MAX_MEASURED_COORDINATE`] (a damaged file).
pub fn check_cloud(cloud: &[Point]) -> Result<()> {
    if cloud.is_empty() {
        return Err(RegisterError::Invalid("no points (the point cloud is empty)".into()));
    }
    if let Some((i, fault)) = mesh::measured_fault(cloud) {
        return Err(RegisterError::Invalid(format!("point {i} {fault}")));
    }
    Ok(())
}
