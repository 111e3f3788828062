//! Parameter transforms from filter space (where the Gaussian lives) to physical space (what the model receives).

use serde::{Deserialize, Serialize};

use crate::FilterError;

/// Map from the filter-space value `v` of one parameter to its physical value, applied to every sigma point
/// before it reaches [`crate::Model::step`]. `Exp` and `Abs` keep stiffnesses non-negative.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Transform {
    /// Physical value = `v`.
    #[default]
    Identity,
    /// Physical value = `exp(v)` (strictly positive; the filter works on the logarithm).
    Exp,
    /// Physical value = `|v|` (non-negative; a prior centred on 0 stays usable, as in SOFA/Optimus).
    Abs,
}

impl Transform {
    /// Physical value of the filter-space value `v`.
    pub fn to_physical(self, v: f64) -> f64 {
        match self {
            Transform::Identity => v,
            Transform::Exp => v.exp(),
            Transform::Abs => v.abs(),
        }
    }

    /// Derivative d(physical)/d(filter) at `v`, used to map standard deviations to physical space
    /// (for `Abs` at `v = 0` the one-sided derivative 1 is used).
    pub fn derivative(self, v: f64) -> f64 {
        match self {
            Transform::Identity => 1.0,
            Transform::Exp => v.exp(),
            Transform::Abs => {
                if v < 0.0 {
                    -1.0
                } else {
                    1.0
                }
            }
        }
    }

    /// Filter-space value whose physical value is `physical` (for `Abs`, the non-negative branch).
    /// Errors when `physical` is outside the range of the transform or not finite.
    pub fn to_filter(self, physical: f64) -> Result<f64, FilterError> {
        let ok = physical.is_finite()
            && match self {
                Transform::Identity => true,
                Transform::Exp => physical > 0.0,
                Transform::Abs => physical >= 0.0,
            };
        if !ok {
            return Err(FilterError::InvalidConfig(format!(
                "physical value {physical} is outside the range of the {self:?} transform"
            )));
        }
        Ok(match self {
            Transform::Identity | Transform::Abs => physical,
            Transform::Exp => physical.ln(),
        })
    }
}
