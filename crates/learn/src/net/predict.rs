//! Single predictions and prediction timing.

use std::time::Instant;

#[cfg(feature = "cpu-burn")]
use burn::tensor::{Device, Tensor, TensorData};
use mesh::embedding::Grid;
use serde::{Deserialize, Serialize};

use crate::data::dataset::Normalization;
use crate::data::grid::{check_prediction_input, placed_model_grid, GridShape};
#[cfg(feature = "cpu-burn")]
use crate::net::burn_unet::{tensor_values, BurnUNet};
use crate::net::inference::InferenceNet;
use crate::net::unet::{TrainedModel, UNet};
use crate::Compute;
use crate::{LearnError, Result};

/// A trained model ready for repeated predictions, with its normalisation and grid: on the CPU
/// its network repacked once for fast inference ([`InferenceNet`]), otherwise burn's network on
/// the chosen device ([`Compute`], with the `cpu-burn` feature).
pub struct Predictor {
    engine: Engine,
    normalization: Normalization,
    grid: GridShape,
}

/// What runs the network.
// One per predictor, held for its lifetime: the variants' sizes do not matter.
#[allow(clippy::large_enum_variant)]
enum Engine {
    /// The repacked CPU engine.
    Repacked(InferenceNet),
    /// burn's network on `device` (a GPU, or burn's CPU backend).
    #[cfg(feature = "cpu-burn")]
    Burn { net: BurnUNet, device: Device },
}

impl Predictor {
    /// Prepares `model` for prediction on `compute`: repacks it for the CPU engine, or copies
    /// its weights to burn's device (an error when that device is not built in or available).
    pub fn new(model: &TrainedModel, compute: Compute) -> Result<Predictor> {
        Predictor::from_net(&model.net, compute, model.normalization, model.grid)
    }

    /// A predictor of `net` on `compute`.
    pub(crate) fn from_net(
        net: &UNet,
        compute: Compute,
        normalization: Normalization,
        grid: GridShape,
    ) -> Result<Predictor> {
        compute.ensure_available()?;
        #[cfg(feature = "cpu-burn")]
        if compute.uses_burn() {
            let device = compute.device()?;
            let engine = Engine::Burn { net: BurnUNet::new(net, &device)?, device };
            return Ok(Predictor { engine, normalization, grid });
        }
        Ok(Predictor { engine: Engine::Repacked(net.to_inference()?), normalization, grid })
    }

    /// Predicts the displacement field (m, `[3, nx, ny, nz]`) for one input field (`[3, nx, ny,
    /// nz]` on the model's grid, in the model's input unit). Values outside the organ are
    /// meaningless; apply the mask.
    pub fn predict(&self, input: &[f32]) -> Result<Vec<f32>> {
        check_prediction_input(input, self.grid)?;
        let si = 1.0 / self.normalization.input_scale;
        let x: Vec<f32> = input.iter().map(|v| (f64::from(*v) * si) as f32).collect();
        let out = self.forward_normalized(x)?;
        Ok(out.into_iter().map(|v| (f64::from(v) * self.normalization.target_scale) as f32).collect())
    }

    /// The network's output for a normalised input (`[3, nx, ny, nz]`), normalised.
    fn forward_normalized(&self, x: Vec<f32>) -> Result<Vec<f32>> {
        match &self.engine {
            Engine::Repacked(net) => net.forward(&x, self.grid),
            #[cfg(feature = "cpu-burn")]
            Engine::Burn { net, device } => {
                let [nx, ny, nz] = self.grid.dims();
                let c = x.len() / self.grid.nodes();
                let input = Tensor::<5>::from_data(TensorData::new(x, [1, c, nx, ny, nz]), device);
                tensor_values(net.forward(input))
            }
        }
    }
}

impl TrainedModel {
    /// Predicts one displacement field (see [`Predictor::predict`]); for repeated predictions
    /// build a [`Predictor`] once.
    pub fn predict(&self, input: &[f32]) -> Result<Vec<f32>> {
        Predictor::new(self, Compute::Cpu)?.predict(input)
    }

    /// The model's grid where it lies in space (needed to put points on it or to interpolate to a mesh); an
    /// error for a model trained before grid placement was recorded.
    pub fn placed_grid(&self) -> Result<Grid> {
        placed_model_grid(self.placement, self.grid)
    }

    /// Whether the network takes nodal forces (input unit N) rather than displacements (m).
    pub fn takes_forces(&self) -> bool {
        self.input_unit.is_force()
    }
}

/// Wall-clock statistics of repeated predictions (s).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Timing {
    /// Timed runs.
    pub runs: usize,
    /// Median ([`mesh::stats::median`]: the mean of the two middle runs for an even count).
    pub median: f64,
    /// Mean.
    pub mean: f64,
    /// Standard deviation.
    pub std: f64,
    /// Fastest run.
    pub min: f64,
    /// Slowest run.
    pub max: f64,
}

impl Timing {
    /// Statistics of a non-empty list of durations (s).
    pub fn from_durations(mut d: Vec<f64>) -> Result<Timing> {
        if d.is_empty() {
            return Err(LearnError::InvalidInput("no timed runs".into()));
        }
        let n = d.len();
        let (mean, max) = (mesh::stats::mean(&d), mesh::stats::max(&d));
        let min = d.iter().copied().fold(f64::INFINITY, f64::min);
        let std = (d.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>() / n as f64).sqrt();
        Ok(Timing { runs: n, median: mesh::stats::median(&mut d), mean, std, min, max })
    }
}

/// Times `predict` (e.g. [`Predictor::predict`], normalisation and the copy back included) on
/// `input`: `warmup` untimed runs, then `runs` timed ones.
pub fn time_prediction(
    predict: impl Fn(&[f32]) -> Result<Vec<f32>>,
    input: &[f32],
    warmup: usize,
    runs: usize,
) -> Result<Timing> {
    if runs == 0 {
        return Err(LearnError::InvalidInput("time_prediction needs at least one run".into()));
    }
    for _ in 0..warmup {
        predict(input)?;
    }
    let mut d = Vec::with_capacity(runs);
    for _ in 0..runs {
        let t0 = Instant::now();
        std::hint::black_box(predict(input)?);
        d.push(t0.elapsed().as_secs_f64());
    }
    Timing::from_durations(d)
}
