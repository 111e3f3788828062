//! Per-iteration traces of the filter and their CSV / JSON output (atomic writes).

use std::fmt::Write as _;
use std::path::Path;

use mesh::io::{csv_field, write_atomic_bytes};
use serde::{Deserialize, Serialize};

use crate::{FilterError, Transform};

/// Estimate of the parameters after one filter iteration (iteration 0 is the prior).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct IterationTrace {
    /// Filter iteration (0 = prior, k = after the k-th observation).
    pub iteration: usize,
    /// Mean μ in filter space.
    pub mean: Vec<f64>,
    /// Standard deviation σ in filter space: square root of the diagonal of `L U^{-1} L^T`, with the model-discrepancy
    /// allowance `(e/d) S^{-1}` added to it when there is one ([`crate::Discrepancy`]).
    pub std: Vec<f64>,
    /// Mean in physical space: `g(μ)` for each parameter's map g = `scale · transform` ([`crate::ParameterSpec`]).
    pub mean_physical: Vec<f64>,
    /// Standard deviation in physical space, first order: `|g'(μ)| σ`.
    pub std_physical: Vec<f64>,
    /// Euclidean norm of the innovation `z - Σ α_i H(x_i)` over the measured components (None for the prior and
    /// for a frame in which nothing was measured).
    pub innovation_norm: Option<f64>,
    /// Wall-clock time of the iteration, seconds (None for the prior).
    pub wall_seconds: Option<f64>,
    /// With a model-discrepancy allowance ([`crate::Discrepancy`]): the physical σ of the observation noise alone
    /// (the filter's own covariance), while `std` and `std_physical` include the allowance.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub noise_std_physical: Option<Vec<f64>>,
    /// With a model-discrepancy allowance: the reduced misfit χ²/ν at this estimate of the frames whose sampled
    /// region reaches it (about 1 when the model and the nominal observation noise are right); `None` until one
    /// does.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub misfit: Option<f64>,
    /// Measured components the validation gate left out at this iteration ([`crate::RoukfConfig::gate`]).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub gated: usize,
    /// Which: their indices in the measurement vector.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub gated_components: Vec<usize>,
}

fn is_zero(n: &usize) -> bool {
    *n == 0
}

/// The whole history of a filter run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Trace {
    /// Parameter names, in reduced-state order.
    pub parameter_names: Vec<String>,
    /// Transform of each parameter.
    pub transforms: Vec<Transform>,
    /// Scale of each parameter: its physical value is `scale · transform(v)`.
    pub scales: Vec<f64>,
    /// One record per iteration, starting with the prior.
    pub records: Vec<IterationTrace>,
}

impl Trace {
    /// CSV text: header `iteration,innovation_norm,wall_seconds` then `mu_<name>,sigma_<name>,mu_phys_<name>,
    /// sigma_phys_<name>` per parameter; empty fields for the prior's innovation and time. With a model-discrepancy
    /// allowance, also `misfit` and a `noise_sigma_phys_<name>` per parameter (see [`IterationTrace`]).
    pub fn to_csv(&self) -> String {
        let discrepancy = self.records.iter().any(|r| r.noise_std_physical.is_some());
        let mut s = String::from("iteration,innovation_norm,wall_seconds");
        if discrepancy {
            s.push_str(",misfit");
        }
        for name in &self.parameter_names {
            for prefix in ["mu_", "sigma_", "mu_phys_", "sigma_phys_"] {
                s.push(',');
                s.push_str(&csv_field(&format!("{prefix}{name}")));
            }
            if discrepancy {
                s.push(',');
                s.push_str(&csv_field(&format!("noise_sigma_phys_{name}")));
            }
        }
        s.push('\n');
        let opt = |v: Option<f64>| v.map(|x| x.to_string()).unwrap_or_default();
        for r in &self.records {
            let _ = write!(s, "{},{},{}", r.iteration, opt(r.innovation_norm), opt(r.wall_seconds));
            if discrepancy {
                let _ = write!(s, ",{}", opt(r.misfit));
            }
            for j in 0..self.parameter_names.len() {
                let _ = write!(s, ",{},{},{},{}", r.mean[j], r.std[j], r.mean_physical[j], r.std_physical[j]);
                if discrepancy {
                    let _ = write!(s, ",{}", opt(r.noise_std_physical.as_ref().map(|v| v[j])));
                }
            }
            s.push('\n');
        }
        s
    }

    /// Writes [`Trace::to_csv`] to `path` atomically.
    pub fn write_csv(&self, path: &Path) -> Result<(), FilterError> {
        Ok(write_atomic_bytes(path, self.to_csv().as_bytes())?)
    }

    /// Writes the trace as pretty JSON to `path` atomically.
    pub fn write_json(&self, path: &Path) -> Result<(), FilterError> {
        let text =
            serde_json::to_vec_pretty(self).map_err(|error| FilterError::Json { path: path.to_path_buf(), error })?;
        Ok(write_atomic_bytes(path, &text)?)
    }
}
