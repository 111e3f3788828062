//! Input corruption: sparse visible inputs and additive Gaussian noise, seeded.
//!
//! Both act on the *nonzero input nodes* (grid nodes whose input vector is not zero: the loaded
//! patch or the visible surface). Sparsity keeps a random sub-domain of them and zeroes the
//! rest; noise then adds `N(0, σ²)` to each channel of every node still visible.

use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, Normal};
use serde::{Deserialize, Serialize};

use crate::data::dataset::{FieldUnit, Samples};
use crate::data::grid::{GridShape, CHANNELS};
use crate::{LearnError, Result};

/// Which part of the nonzero input nodes stays visible.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum Sparsity {
    /// Keep a uniformly random subset: a fraction drawn uniformly in `[min_fraction,
    /// max_fraction]` of the nonzero nodes (at least one node).
    Subset {
        /// Smallest kept fraction, in (0, 1].
        min_fraction: f64,
        /// Largest kept fraction, in [min_fraction, 1].
        max_fraction: f64,
    },
    /// Keep a contiguous patch: a random nonzero node and its nearest nonzero nodes (grid
    /// distance, ties by node index), `min_nodes..=max_nodes` of them in all (uniform; capped
    /// by the number of nonzero nodes).
    Patch {
        /// Smallest patch size (nodes), at least 1.
        min_nodes: usize,
        /// Largest patch size (nodes), at least `min_nodes`.
        max_nodes: usize,
    },
}

/// The nonzero input nodes of an input field (`[3, nx, ny, nz]` on `grid`): the grid nodes whose
/// vector is not zero (the loaded patch or the visible surface), which a corruption acts on.
pub fn nonzero_nodes(input: &[f32], grid: GridShape) -> Vec<usize> {
    let n = grid.nodes();
    (0..n).filter(|&v| (0..CHANNELS).any(|c| input[c * n + v] != 0.0)).collect()
}

/// Input corruption applied at training and/or evaluation time.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Corruption {
    /// Keep only a sub-domain of the nonzero input nodes (none: keep all).
    #[serde(default)]
    pub sparsity: Option<Sparsity>,
    /// Standard deviation σ of the additive Gaussian noise, in the input unit (variance σ²);
    /// 0 for none.
    #[serde(default)]
    pub noise_std: f64,
}

impl Corruption {
    /// No corruption.
    pub fn none() -> Self {
        Corruption::default()
    }

    /// Whether this corruption leaves inputs unchanged.
    pub fn is_identity(&self) -> bool {
        self.sparsity.is_none() && self.noise_std == 0.0
    }

    /// Checks the parameters.
    pub fn validate(&self) -> Result<()> {
        let bad = |m: String| Err(LearnError::InvalidInput(format!("corruption: {m}")));
        if !(self.noise_std >= 0.0 && self.noise_std.is_finite()) {
            return bad(format!("noise_std must be finite and >= 0, got {}", self.noise_std));
        }
        match &self.sparsity {
            Some(Sparsity::Subset { min_fraction, max_fraction })
                if !(*min_fraction > 0.0 && min_fraction <= max_fraction && *max_fraction <= 1.0) =>
            {
                bad(format!("subset fractions must satisfy 0 < min <= max <= 1, got {min_fraction}, {max_fraction}"))
            }
            Some(Sparsity::Patch { min_nodes, max_nodes }) if *min_nodes == 0 || min_nodes > max_nodes => {
                bad(format!("patch sizes must satisfy 1 <= min <= max, got {min_nodes}, {max_nodes}"))
            }
            _ => Ok(()),
        }
    }

    /// Refuses a noise more than ten times the inputs' RMS norm (`input_rms`, in `unit`): a
    /// standard deviation given in another unit (1 meaning 1 mm, on inputs in metres) would
    /// drown the inputs.
    pub fn check_scale(&self, input_rms: f64, unit: FieldUnit) -> Result<()> {
        if input_rms > 0.0 && self.noise_std > 10.0 * input_rms {
            let hint = match unit {
                FieldUnit::Metre => " (1 mm is 0.001)",
                FieldUnit::Newton => "",
            };
            return Err(LearnError::InvalidInput(format!(
                "a noise of {} {unit} on inputs whose RMS is {:.3e} {unit} would drown them: the noise is in the \
                 inputs' unit, {unit}{hint}",
                self.noise_std, input_rms
            )));
        }
        Ok(())
    }

    /// Refuses a patch sparsity that keeps every input node of `samples` (its smallest patch at
    /// least as large as their most nonzero nodes: the input would not be sparse), or whose
    /// largest patch exceeds that count (the draws above it would keep every node).
    pub fn check_sparsity(&self, samples: &Samples) -> Result<()> {
        let Some(Sparsity::Patch { min_nodes, max_nodes }) = &self.sparsity else { return Ok(()) };
        let most = (0..samples.len()).map(|p| nonzero_nodes(samples.input(p), samples.grid).len()).max().unwrap_or(0);
        if *min_nodes >= most {
            return Err(LearnError::InvalidInput(format!(
                "--sparse {min_nodes},{max_nodes} keeps every input node: the samples have at most {most}, so the \
                 input would not be sparse; give a range below {most}"
            )));
        }
        if *max_nodes > most {
            let kept_whole = 100.0 * (max_nodes - most) as f64 / (max_nodes - min_nodes + 1) as f64;
            return Err(LearnError::InvalidInput(format!(
                "--sparse {min_nodes},{max_nodes} reaches past the samples' input nodes (at most {most}): \
                 {kept_whole:.0} % of the draws would keep every node; give a range within {min_nodes},{}",
                most - 1
            )));
        }
        Ok(())
    }

    /// Corrupts one input field (`[3, nx, ny, nz]`) in place.
    pub fn apply(&self, input: &mut [f32], grid: GridShape, rng: &mut impl Rng) -> Result<()> {
        self.validate()?;
        if input.len() != grid.field_len() {
            return Err(LearnError::InvalidInput(format!(
                "corruption: input has {} values, grid {grid} needs {}",
                input.len(),
                grid.field_len()
            )));
        }
        let n = grid.nodes();
        let nonzero = nonzero_nodes(input, grid);
        if nonzero.is_empty() {
            return Ok(());
        }
        let kept = match &self.sparsity {
            None => nonzero,
            Some(Sparsity::Subset { min_fraction, max_fraction }) => {
                let fraction = if max_fraction > min_fraction {
                    rng.random_range(*min_fraction..=*max_fraction)
                } else {
                    *min_fraction
                };
                let count = ((fraction * nonzero.len() as f64).round() as usize).clamp(1, nonzero.len());
                let mut chosen = rand::seq::index::sample(rng, nonzero.len(), count).into_vec();
                chosen.sort_unstable();
                chosen.into_iter().map(|p| nonzero[p]).collect()
            }
            Some(Sparsity::Patch { min_nodes, max_nodes }) => {
                let size = rng.random_range(*min_nodes..=*max_nodes).min(nonzero.len());
                let center = grid.node_coords(nonzero[rng.random_range(0..nonzero.len())]);
                let mut by_distance: Vec<(usize, usize)> = nonzero
                    .iter()
                    .map(|&v| {
                        let p = grid.node_coords(v);
                        let d2 = (0..3).map(|a| p[a].abs_diff(center[a]).pow(2)).sum::<usize>();
                        (d2, v)
                    })
                    .collect();
                by_distance.sort_unstable();
                let mut kept: Vec<usize> = by_distance[..size].iter().map(|&(_, v)| v).collect();
                kept.sort_unstable();
                kept
            }
        };
        if self.sparsity.is_some() {
            let mut visible = vec![false; n];
            for &v in &kept {
                visible[v] = true;
            }
            for c in 0..CHANNELS {
                for v in 0..n {
                    if !visible[v] {
                        input[c * n + v] = 0.0;
                    }
                }
            }
        }
        if self.noise_std > 0.0 {
            let normal = Normal::new(0.0, self.noise_std)
                .map_err(|e| LearnError::InvalidInput(format!("corruption: noise distribution: {e}")))?;
            for &v in &kept {
                for c in 0..CHANNELS {
                    input[c * n + v] += normal.sample(rng) as f32;
                }
            }
        }
        Ok(())
    }
}

/// Random stream of the batch shuffling.
pub(crate) const STREAM_SHUFFLE: u64 = 1;
/// Random stream of the training-time corruption.
pub(crate) const STREAM_TRAIN_CORRUPTION: u64 = 2;
/// Random stream of the evaluation-time (validation and test) corruption.
pub(crate) const STREAM_EVAL_CORRUPTION: u64 = 3;

/// A random generator for one corrupted item, derived from a seed, a stream (training,
/// evaluation, ...) and the item number, independent of the order in which items are processed.
pub fn item_rng(seed: u64, stream: u64, item: u64) -> StdRng {
    let mut s = splitmix64(seed ^ splitmix64(stream.wrapping_add(0x9E37_79B9_7F4A_7C15)));
    s = splitmix64(s ^ item);
    StdRng::seed_from_u64(s)
}

/// The SplitMix64 mixing function.
pub(crate) fn splitmix64(x: u64) -> u64 {
    let mut z = x.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}
