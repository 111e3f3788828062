//! Fitting a reduced-order model: the output basis, the input features, the choice of kernel,
//! length scale, noise and number of modes on validation, and the calibration of the predicted
//! uncertainty.

use std::time::Instant;

use faer::Mat;
use serde::{Deserialize, Serialize};

use super::linalg::{
    kernel_matrix, leading_eigen, median_distance, mul, mul_t, principal_directions, row_norms2, training_par, Kernel,
};
use super::{Reader, ReducedModel, RomInfo};
use crate::data::corrupt::{item_rng, Corruption, STREAM_EVAL_CORRUPTION, STREAM_TRAIN_CORRUPTION};
use crate::data::dataset::Samples;
use crate::data::grid::{GridPlacement, GridShape, CHANNELS};
use crate::data::response::RestResponse;
use crate::data::split::Split;
use crate::FieldUnit;
use crate::{LearnError, Result};

/// Settings of a reduced-order model's fit.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RomConfig {
    /// Most POD modes of the output (the number used is chosen on validation).
    pub max_modes: usize,
    /// Most principal components of the input.
    pub max_input_components: usize,
    /// Share of the training inputs' energy the input components keep.
    pub input_energy: f64,
    /// Most inducing points: above this many training samples the regression is a Nyström
    /// approximation on a seeded random subset of them.
    pub max_inducing: usize,
    /// Most training samples the POD basis is computed from (a seeded random subset above it).
    pub pod_samples: usize,
    /// Corrupted copies of each training sample added to the regression's training set (inputs
    /// corrupted by `corruption`), so that it learns to read corrupted inputs.
    pub noise_copies: usize,
    /// The corruption of those copies and of the validation inputs.
    pub corruption: Corruption,
    /// Seed of the corruption draws and of the subsets.
    pub seed: u64,
}

impl Default for RomConfig {
    fn default() -> Self {
        RomConfig {
            max_modes: 256,
            max_input_components: 256,
            input_energy: 1.0 - 1e-5,
            max_inducing: 3000,
            pod_samples: 3000,
            noise_copies: 0,
            corruption: Corruption::none(),
            seed: 0,
        }
    }
}

impl RomConfig {
    /// Checks the values: at least one mode, input component, inducing point and POD sample, an
    /// energy share in (0, 1], and the corruption's.
    pub fn validate(&self) -> Result<()> {
        let counts = [
            ("modes", self.max_modes),
            ("input components", self.max_input_components),
            ("inducing points", self.max_inducing),
            ("POD samples", self.pod_samples),
        ];
        if let Some((what, _)) = counts.iter().find(|(_, n)| *n == 0) {
            return Err(LearnError::InvalidInput(format!(
                "reduced-order model: at least one of its {what} is needed, got 0"
            )));
        }
        if !(self.input_energy > 0.0 && self.input_energy <= 1.0) {
            return Err(LearnError::InvalidInput(format!(
                "reduced-order model: the input energy kept must lie in (0, 1], got {}",
                self.input_energy
            )));
        }
        if self.noise_copies > 0 && self.corruption.is_identity() {
            return Err(LearnError::InvalidInput(format!(
                "reduced-order model: {} corrupted copies of each training sample asked for, but no corruption \
                 (`augsim train --noise` or `--sparse`): they would be copies of the clean samples",
                self.noise_copies
            )));
        }
        self.corruption.validate()
    }
}

/// What a fit measured.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RomReport {
    /// Share of the training targets' variance the chosen modes hold.
    pub energy: f64,
    /// Mean Euclidean error of the validation targets projected on the chosen basis (m): the
    /// floor of the model.
    pub val_projection_error: f64,
    /// Mean Euclidean error of the validation predictions (m).
    pub val_mean_error: f64,
    /// Largest validation sample's mean Euclidean error (m).
    pub val_max_error: f64,
    /// Share of the validation nodes whose error lies within twice the calibrated standard
    /// deviation (0.95 by construction, up to ties).
    pub val_coverage: f64,
    /// Every candidate tried, with its validation error.
    pub candidates: Vec<Candidate>,
}

/// One set of hyper-parameters tried on validation.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Candidate {
    /// The features' scaling exponent ([`RomInfo::feature_exponent`]).
    pub feature_exponent: f64,
    /// The kernel.
    pub kernel: Kernel,
    /// Its length scale.
    pub length_scale: f64,
    /// The noise ratio.
    pub noise: f64,
    /// The number of modes.
    pub modes: usize,
    /// Mean over the validation samples of their root-mean-square node error (m).
    pub val_error: f64,
}

/// The most memory the regression's training inputs (the training samples' and their corrupted
/// copies') may take: 8 GB (the shipped models' fits take under 1 GB).
const MAX_INPUT_BYTES: usize = 8_000_000_000;

/// Candidate exponents of the features' scaling: each feature is divided by its training spread
/// (relative to the first feature's) to this power. 0 compares the features as they are, in
/// which the leading ones dominate; ¼ gives the smaller ones more say.
const FEATURE_EXPONENTS: [f64; 2] = [0.0, 0.25];
/// Candidate length scales, as multiples of the median distance between training features.
const SCALES: [f64; 6] = [0.125, 0.25, 0.5, 1.0, 2.0, 4.0];
/// Candidate noise ratios (noise variance over the kernel's).
const NOISES: [f64; 6] = [1e-6, 1e-5, 1e-4, 1e-3, 1e-2, 1e-1];
/// Candidate numbers of modes (those up to the basis's size, and the whole basis).
const MODES: [usize; 7] = [8, 16, 32, 64, 128, 256, 512];
/// Eigenvalues of the inducing kernel matrix below this share of the largest are dropped.
const KERNEL_RANK_TOLERANCE: f64 = 1e-10;
/// Share of validation node errors within two calibrated standard deviations.
const COVERAGE: f64 = 0.95;

/// Where the samples lie and what they mean, for the model file.
pub struct Context {
    /// The grid's placement.
    pub placement: Option<GridPlacement>,
    /// Input unit.
    pub input_unit: FieldUnit,
    /// Target unit.
    pub target_unit: FieldUnit,
    /// The split the samples come from.
    pub split: Split,
}

impl Context {
    /// The context of samples of the dataset described by `manifest`, split by `split`.
    pub fn of_dataset(manifest: &crate::Manifest, split: Split) -> Context {
        Context {
            placement: manifest.placement(),
            input_unit: manifest.units.input,
            target_unit: manifest.units.target,
            split,
        }
    }
}

/// Fits a reduced-order model on `train`, choosing its hyper-parameters on `validation`. With a
/// `prior` (force inputs), the model adds the prior's modal coefficients to the regression, which
/// learns the remainder, and the kernel compares inputs by their prior coefficients.
pub fn fit(
    train: &Samples,
    validation: &Samples,
    config: &RomConfig,
    context: Context,
    prior: Option<&mut RestResponse>,
) -> Result<(ReducedModel, RomReport)> {
    let start = Instant::now();
    config.validate()?;
    let prior_description = prior.as_ref().map(|r| r.description().to_string());
    if train.len() < 2 || validation.is_empty() {
        return Err(LearnError::InvalidInput(format!(
            "a reduced-order model needs at least 2 training and 1 validation sample, got {} and {}",
            train.len(),
            validation.len()
        )));
    }
    if validation.grid != train.grid {
        return Err(LearnError::InvalidInput("training and validation samples lie on different grids".into()));
    }
    let n = train.len();
    let field_count = n.saturating_mul(config.noise_copies.saturating_add(1));
    let bytes = field_count.saturating_mul(train.grid.field_len()).saturating_mul(size_of::<f32>());
    if bytes > MAX_INPUT_BYTES {
        return Err(LearnError::InvalidInput(format!(
            "{n} training inputs and {} corrupted copies of each would take {:.1} GB, more than {} GB: fewer copies",
            config.noise_copies,
            bytes as f64 / 1e9,
            MAX_INPUT_BYTES / 1_000_000_000
        )));
    }
    let outputs = Outputs::new(train, validation, config)?;
    let clean: Vec<Vec<f32>> = (0..n).map(|i| train.input(i).to_vec()).collect();
    let inputs = Inputs::new(train.grid, &clean, config, &outputs, prior)?;
    let fields = with_corrupted_copies(clean, train, config)?;
    let (f_train, y_coeffs) = inputs.read(&fields, &outputs.coeffs_train, &|i| i % n);
    let val_fields = validation_inputs(validation, config)?;
    let (f_val, target_val) = inputs.read(&val_fields, &outputs.coeffs_val, &|i| i);

    // Inducing points: the clean training samples (a seeded subset above `max_inducing`).
    let inducing_rows = subset(n, config.max_inducing, config.seed ^ 0x5eed);
    let spread: Vec<f64> = (0..inputs.components)
        .map(|j| {
            let mean = (0..n).map(|i| f_train[(i, j)]).sum::<f64>() / n as f64;
            ((0..n).map(|i| (f_train[(i, j)] - mean).powi(2)).sum::<f64>() / n as f64).sqrt()
        })
        .collect();
    let mut scalings: Vec<Features> = FEATURE_EXPONENTS
        .iter()
        .map(|&exponent| Features::new(&f_train, &f_val, &spread, exponent, &inducing_rows))
        .collect();
    let candidates = validation_candidates(&scalings, &outputs, &y_coeffs, &target_val)?;
    let chosen = candidates
        .iter()
        .min_by(|a, b| a.val_error.total_cmp(&b.val_error))
        .cloned()
        .ok_or_else(|| LearnError::InvalidInput("no candidate".into()))?;
    let at = scalings
        .iter()
        .position(|f| f.exponent == chosen.feature_exponent)
        .ok_or_else(|| LearnError::InvalidInput("no candidate".into()))?;
    let features = scalings.swap_remove(at);
    let info = RomInfo {
        kernel: chosen.kernel,
        length_scale: chosen.length_scale,
        noise: chosen.noise,
        modes: chosen.modes,
        input_components: inputs.components,
        feature_exponent: chosen.feature_exponent,
        inducing: features.inducing.nrows(),
        exact: features.exact,
        calibration: 1.0,
        train_samples: n,
        val_samples: validation.len(),
        noise_copies: config.noise_copies,
        corruption: config.corruption.clone(),
        seed: config.seed,
        prior: prior_description,
        val_mean_error: 0.0,
        seconds: 0.0,
        split: context.split.clone(),
        fit: Some(config.clone()),
    };
    let energy = outputs.pod_values[..chosen.modes].iter().sum::<f64>() / outputs.pod_energy;
    let (mut model, project) = chosen_model(train.grid, &context, info, inputs, features, &outputs, &y_coeffs)?;
    let report = calibrate(&mut model, &val_fields, &outputs.y_val, &project, energy, candidates)?;
    model.info.seconds = start.elapsed().as_secs_f64();
    Ok((model, report))
}

/// The training targets' output basis: the organ's grid nodes (those of any training mask), the
/// target entries on them, their mean, the POD basis and the targets' modal coefficients.
struct Outputs {
    /// The organ's grid nodes.
    nodes: Vec<usize>,
    /// The target entries read, channel by channel over `nodes`.
    entries: Vec<usize>,
    /// The validation targets.
    y_val: Mat<f64>,
    /// The validation targets less the training mean.
    yc_val: Mat<f64>,
    /// The training targets' mean.
    mean: Vec<f64>,
    /// The POD's eigenvalues, and the squared norm of the samples it was computed from.
    pod_values: Vec<f64>,
    pod_energy: f64,
    /// The POD basis (a mode per row).
    basis: Mat<f64>,
    /// The modal coefficients of the training and the validation targets.
    coeffs_train: Mat<f64>,
    coeffs_val: Mat<f64>,
    /// The validation targets' energy outside the basis, per sample.
    outside_val: Vec<f64>,
}

impl Outputs {
    fn new(train: &Samples, validation: &Samples, config: &RomConfig) -> Result<Outputs> {
        let grid_nodes = train.grid.nodes();
        let n = train.len();
        let nodes: Vec<usize> = (0..grid_nodes).filter(|&v| (0..n).any(|i| train.mask(i)[v] == 1)).collect();
        let entries: Vec<usize> = (0..CHANNELS).flat_map(|c| nodes.iter().map(move |&v| c * grid_nodes + v)).collect();
        let targets = |s: &Samples| Mat::from_fn(s.len(), entries.len(), |i, e| f64::from(s.target(i)[entries[e]]));
        let (y_train, y_val) = (targets(train), targets(validation));
        let mean: Vec<f64> = (0..y_train.ncols()).map(|e| y_train.col(e).iter().sum::<f64>() / n as f64).collect();
        let centre = |y: &Mat<f64>| Mat::from_fn(y.nrows(), y.ncols(), |i, e| y[(i, e)] - mean[e]);
        let (yc_train, yc_val) = (centre(&y_train), centre(&y_val));
        let pod_rows = subset(n, config.pod_samples, config.seed);
        let pod_x = Mat::from_fn(pod_rows.len(), yc_train.ncols(), |i, e| yc_train[(pod_rows[i], e)]);
        let (pod_values, basis) = principal_directions(pod_x.as_ref(), config.max_modes, 1e-7)?;
        if basis.nrows() == 0 {
            return Err(LearnError::InvalidInput("the training targets do not vary: nothing to learn".into()));
        }
        let coeffs_train = mul_t(yc_train.as_ref(), basis.as_ref(), training_par());
        let coeffs_val = mul_t(yc_val.as_ref(), basis.as_ref(), training_par());
        let outside_val: Vec<f64> = (0..validation.len())
            .map(|i| {
                let total: f64 = yc_val.row(i).iter().map(|v| v * v).sum();
                (total - coeffs_val.row(i).iter().map(|v| v * v).sum::<f64>()).max(0.0)
            })
            .collect();
        Ok(Outputs {
            nodes,
            entries,
            y_val,
            yc_val,
            mean,
            pod_values,
            pod_energy: pod_x.norm_l2().powi(2).max(f64::MIN_POSITIVE),
            basis,
            coeffs_train,
            coeffs_val,
            outside_val,
        })
    }
}

/// The input features: the input entries that vary, their training mean, and the directions
/// that make features of them (the inputs' leading principal directions or, with a prior, its
/// leading modal coefficients: the prior's transpose applied to each mode, one solve per mode),
/// as many as keep `input_energy` of the training inputs' energy in their space.
struct Inputs {
    entries: Vec<usize>,
    mean: Vec<f64>,
    components: usize,
    directions: Mat<f64>,
    prior: Option<Mat<f64>>,
}

impl Inputs {
    fn new(
        grid: GridShape,
        clean: &[Vec<f32>],
        config: &RomConfig,
        outputs: &Outputs,
        prior: Option<&mut RestResponse>,
    ) -> Result<Inputs> {
        let entries: Vec<usize> = (0..grid.field_len()).filter(|&e| clean.iter().any(|x| x[e] != 0.0)).collect();
        if entries.is_empty() {
            return Err(LearnError::InvalidInput("every training input is zero: nothing to learn from".into()));
        }
        let x_clean = input_matrix(&entries, clean);
        let n = clean.len();
        let mean: Vec<f64> = (0..x_clean.ncols()).map(|e| x_clean.col(e).iter().sum::<f64>() / n as f64).collect();
        let x_centred = centred(&x_clean, &mean);
        let (values, directions, prior) = match prior {
            None => {
                let (values, directions) = principal_directions(x_centred.as_ref(), config.max_input_components, 1e-7)?;
                (values, directions, None)
            }
            Some(response) => {
                let a =
                    prior_coefficients_matrix(response, &outputs.basis, &outputs.entries, &entries, grid.field_len())?;
                let p = mul_t(x_centred.as_ref(), a.as_ref(), training_par());
                let values = (0..p.ncols()).map(|j| p.col(j).iter().map(|v| v * v).sum()).collect();
                let directions = a.subrows(0, a.nrows().min(config.max_input_components)).to_owned();
                (values, directions, Some(a))
            }
        };
        let total: f64 = values.iter().sum();
        let mut kept = 0.0;
        let components = values
            .iter()
            .position(|v| {
                kept += v;
                kept >= config.input_energy * total
            })
            .map_or(directions.nrows(), |p| p + 1)
            .min(directions.nrows());
        let directions = directions.subrows(0, components).to_owned();
        Ok(Inputs { entries, mean, components, directions, prior })
    }

    /// A set of inputs read and centred once: its features, and what the regression learns for
    /// it (the modal coefficients of sample `sample(i)`, less the prior's; with a prior the
    /// features are the leading prior coefficients).
    fn read(&self, fields: &[Vec<f32>], coeffs: &Mat<f64>, sample: &dyn Fn(usize) -> usize) -> (Mat<f64>, Mat<f64>) {
        let x = centred(&input_matrix(&self.entries, fields), &self.mean);
        let p = self.prior.as_ref().map(|a| mul_t(x.as_ref(), a.as_ref(), training_par()));
        let features = match &p {
            Some(p) => p.subcols(0, self.components).to_owned(),
            None => mul_t(x.as_ref(), self.directions.as_ref(), training_par()),
        };
        let targets = Mat::from_fn(fields.len(), coeffs.ncols(), |i, j| {
            coeffs[(sample(i), j)] - p.as_ref().map_or(0.0, |p| p[(i, j)])
        });
        (features, targets)
    }
}

/// The `entries` of `fields`, a row per field.
fn input_matrix(entries: &[usize], fields: &[Vec<f32>]) -> Mat<f64> {
    Mat::from_fn(fields.len(), entries.len(), |i, e| f64::from(fields[i][entries[e]]))
}

/// `x` less `mean` (one per column).
fn centred(x: &Mat<f64>, mean: &[f64]) -> Mat<f64> {
    Mat::from_fn(x.nrows(), x.ncols(), |i, e| x[(i, e)] - mean[e])
}

/// The regression's training inputs: the clean samples, then `noise_copies` corrupted copies of them.
fn with_corrupted_copies(mut fields: Vec<Vec<f32>>, train: &Samples, config: &RomConfig) -> Result<Vec<Vec<f32>>> {
    let n = train.len();
    for copy in 0..config.noise_copies {
        for i in 0..n {
            let mut input = train.input(i).to_vec();
            let item = (copy * n + i) as u64;
            config.corruption.apply(
                &mut input,
                train.grid,
                &mut item_rng(config.seed, STREAM_TRAIN_CORRUPTION, item),
            )?;
            fields.push(input);
        }
    }
    Ok(fields)
}

/// The validation inputs, corrupted as the model's inputs will be.
fn validation_inputs(validation: &Samples, config: &RomConfig) -> Result<Vec<Vec<f32>>> {
    (0..validation.len())
        .map(|i| {
            let mut input = validation.input(i).to_vec();
            if !config.corruption.is_identity() {
                let mut rng = item_rng(config.seed, STREAM_EVAL_CORRUPTION, i as u64);
                config.corruption.apply(&mut input, validation.grid, &mut rng)?;
            }
            Ok(input)
        })
        .collect()
}

/// Every candidate's validation error: each sample's root-mean-square node error (inside the
/// candidate's modes, beyond them and outside the basis), averaged over the samples.
fn validation_candidates(
    scalings: &[Features],
    outputs: &Outputs,
    y_coeffs: &Mat<f64>,
    target_val: &Mat<f64>,
) -> Result<Vec<Candidate>> {
    let basis_size = outputs.basis.nrows();
    let mode_counts: Vec<usize> =
        MODES.iter().copied().filter(|&r| r < basis_size).chain(std::iter::once(basis_size)).collect();
    let node_entries = outputs.entries.len() as f64 / CHANNELS as f64;
    let samples = target_val.nrows();
    let mut candidates: Vec<Candidate> = Vec::new();
    for features in scalings {
        let feature_exponent = features.exponent;
        for kernel in [Kernel::Rbf, Kernel::Matern52] {
            for &s in &SCALES {
                let length_scale = s * features.base_scale;
                let fitted = features.regression(kernel, length_scale, y_coeffs)?;
                let k_val = features.validation_kernel(kernel, length_scale);
                for &noise in &NOISES {
                    let predicted = mul(k_val.as_ref(), fitted.weights(noise).as_ref(), training_par());
                    for &modes in &mode_counts {
                        let val_error = (0..samples)
                            .map(|i| {
                                let inside: f64 =
                                    (0..modes).map(|j| (target_val[(i, j)] - predicted[(i, j)]).powi(2)).sum();
                                let beyond: f64 = (modes..basis_size).map(|j| outputs.coeffs_val[(i, j)].powi(2)).sum();
                                ((inside + beyond + outputs.outside_val[i]) / node_entries).sqrt()
                            })
                            .sum::<f64>()
                            / samples as f64;
                        candidates.push(Candidate { feature_exponent, kernel, length_scale, noise, modes, val_error });
                    }
                }
            }
        }
    }
    Ok(candidates)
}

/// The model of the chosen hyper-parameters (`info`), and the validation targets (centred)
/// projected on its basis.
fn chosen_model(
    grid: GridShape,
    context: &Context,
    info: RomInfo,
    inputs: Inputs,
    features: Features,
    outputs: &Outputs,
    y_coeffs: &Mat<f64>,
) -> Result<(ReducedModel, Mat<f64>)> {
    let (modes, noise) = (info.modes, info.noise);
    let fitted = features.regression(info.kernel, info.length_scale, y_coeffs)?;
    let weights = fitted.weights(noise).subcols(0, modes).to_owned();
    let covariance = fitted.covariance(noise);
    let amplitudes = fitted.amplitudes(noise, y_coeffs);
    let basis = outputs.basis.subrows(0, modes).to_owned();
    let m = outputs.nodes.len();
    let variance_weights: Vec<f64> = (0..m)
        .map(|p| {
            (0..CHANNELS).map(|c| (0..modes).map(|j| amplitudes[j] * basis[(j, c * m + p)].powi(2)).sum::<f64>()).sum()
        })
        .collect();
    let yc_val = &outputs.yc_val;
    let project = mul(mul_t(yc_val.as_ref(), basis.as_ref(), training_par()).as_ref(), basis.as_ref(), training_par());
    let floor: Vec<f64> = (0..m)
        .map(|p| {
            (0..yc_val.nrows())
                .map(|i| (0..CHANNELS).map(|c| (yc_val[(i, c * m + p)] - project[(i, c * m + p)]).powi(2)).sum::<f64>())
                .sum::<f64>()
                / yc_val.nrows() as f64
        })
        .collect();
    let reader = match inputs.prior {
        None => Reader::Components(inputs.directions),
        Some(a) => Reader::Prior(a.subrows(0, modes.max(info.input_components)).to_owned()),
    };
    let model = ReducedModel {
        grid,
        placement: context.placement,
        input_unit: context.input_unit,
        target_unit: context.target_unit,
        info,
        input_entries: inputs.entries,
        input_mean: inputs.mean,
        reader,
        feature_scales: features.scales,
        inducing_norms: features.inducing_norms,
        inducing: features.inducing,
        weights,
        covariance,
        nodes: outputs.nodes.clone(),
        output_mean: outputs.mean.clone(),
        basis,
        variance_weights,
        floor,
    };
    Ok((model, project))
}

/// The validation errors of `model`, the projection floor (`project`: the centred validation
/// targets projected on the model's basis) and the calibration of its standard deviation, set
/// in the model; the report of the fit, with the basis's `energy` and the `candidates` tried.
fn calibrate(
    model: &mut ReducedModel,
    val_fields: &[Vec<f32>],
    y_val: &Mat<f64>,
    project: &Mat<f64>,
    energy: f64,
    candidates: Vec<Candidate>,
) -> Result<RomReport> {
    let m = model.nodes.len();
    let (mut errors, mut ratios, mut floor_errors) = (Vec::new(), Vec::new(), Vec::new());
    for (i, input) in val_fields.iter().enumerate() {
        let (k, prior) = model.kernel_row(input)?;
        let (pred, std) = (model.reconstruct(&k, &prior), model.node_std(&k));
        let node_error = |p: usize, v: &dyn Fn(usize) -> f64| {
            (0..CHANNELS).map(|c| (v(c * m + p) - y_val[(i, c * m + p)]).powi(2)).sum::<f64>().sqrt()
        };
        let mut sum = 0.0;
        let mut floor_sum = 0.0;
        for (p, s) in std.iter().enumerate() {
            let e = node_error(p, &|e| pred[e]);
            sum += e;
            floor_sum += node_error(p, &|e| project[(i, e)] + model.output_mean[e]);
            ratios.push(e / (2.0 * s).max(f64::MIN_POSITIVE));
        }
        errors.push(sum / m as f64);
        floor_errors.push(floor_sum / m as f64);
    }
    let q = ((COVERAGE * ratios.len() as f64).ceil() as usize).clamp(1, ratios.len()) - 1;
    let calibration = *ratios.select_nth_unstable_by(q, f64::total_cmp).1;
    model.info.calibration = calibration.max(f64::MIN_POSITIVE);
    let val_coverage = ratios.iter().filter(|&&r| r <= calibration).count() as f64 / ratios.len() as f64;
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    model.info.val_mean_error = mean(&errors);
    Ok(RomReport {
        energy,
        val_projection_error: mean(&floor_errors),
        val_mean_error: mean(&errors),
        val_max_error: errors.iter().copied().fold(0.0, f64::max),
        val_coverage,
        candidates,
    })
}

/// The scale of each feature for a scaling exponent: its spread relative to the first feature's,
/// to the power `-exponent` (all ones for 0, and for features that do not vary).
fn feature_scales(spread: &[f64], exponent: f64) -> Vec<f64> {
    let first = spread.first().copied().unwrap_or(1.0);
    spread.iter().map(|&s| if s > 0.0 && first > 0.0 { (s / first).powf(-exponent) } else { 1.0 }).collect()
}

/// The training and validation features scaled for one exponent (each by its spread, see
/// [`feature_scales`]), the inducing points among them, the squared norms of each and the median
/// distance between inducing points.
struct Features {
    /// The scaling exponent and the factor on each feature.
    exponent: f64,
    scales: Vec<f64>,
    /// Whether the inducing points are the training samples, in order.
    exact: bool,
    train: Mat<f64>,
    validation: Mat<f64>,
    inducing: Mat<f64>,
    train_norms: Vec<f64>,
    validation_norms: Vec<f64>,
    inducing_norms: Vec<f64>,
    base_scale: f64,
}

impl Features {
    fn new(
        train: &Mat<f64>,
        validation: &Mat<f64>,
        spread: &[f64],
        exponent: f64,
        inducing_rows: &[usize],
    ) -> Features {
        let scales = feature_scales(spread, exponent);
        let exact = inducing_rows.len() == train.nrows();
        let scaled = |f: &Mat<f64>| Mat::from_fn(f.nrows(), f.ncols(), |i, j| f[(i, j)] * scales[j]);
        let (train, validation) = (scaled(train), scaled(validation));
        let inducing = Mat::from_fn(inducing_rows.len(), train.ncols(), |i, j| train[(inducing_rows[i], j)]);
        Features {
            exponent,
            exact,
            train_norms: row_norms2(train.as_ref()),
            validation_norms: row_norms2(validation.as_ref()),
            inducing_norms: row_norms2(inducing.as_ref()),
            base_scale: median_distance(inducing.as_ref()).max(f64::MIN_POSITIVE),
            train,
            validation,
            inducing,
            scales,
        }
    }

    /// The regression of `y` on the training features.
    fn regression(&self, kernel: Kernel, scale: f64, y: &Mat<f64>) -> Result<Regression> {
        if self.exact {
            Regression::exact(kernel, scale, &self.train, &self.train_norms, y)
        } else {
            Regression::new(kernel, scale, &self.inducing, &self.inducing_norms, &self.train, &self.train_norms, y)
        }
    }

    /// The kernel between the validation features and the inducing points.
    fn validation_kernel(&self, kernel: Kernel, scale: f64) -> Mat<f64> {
        let (v, z) = (self.validation.as_ref(), self.inducing.as_ref());
        kernel_matrix(kernel, scale, v, &self.validation_norms, z, &self.inducing_norms, training_par())
    }
}

/// The prior's modal coefficients as a matrix on the input entries (`modes × entries`): row `j`
/// is the prior's transpose applied to mode `j` (its values at `out_entries` of a grid field of
/// `field_len` values), read at `input_entries`.
fn prior_coefficients_matrix(
    response: &mut RestResponse,
    basis: &Mat<f64>,
    out_entries: &[usize],
    input_entries: &[usize],
    field_len: usize,
) -> Result<Mat<f64>> {
    let mut a = Mat::zeros(basis.nrows(), input_entries.len());
    let mut mode = vec![0.0; field_len];
    for j in 0..basis.nrows() {
        out_entries.iter().enumerate().for_each(|(e, &entry)| mode[entry] = basis[(j, e)]);
        let weights = response.adjoint(&mode)?;
        input_entries.iter().enumerate().for_each(|(e, &entry)| a[(j, e)] = weights[entry]);
    }
    Ok(a)
}

/// `count` of `0..n` (all when `count ≥ n`), a seeded random subset in increasing order.
fn subset(n: usize, count: usize, seed: u64) -> Vec<usize> {
    if count >= n {
        return (0..n).collect();
    }
    let mut chosen = rand::seq::index::sample(&mut item_rng(seed, 0, 0), n, count).into_vec();
    chosen.sort_unstable();
    chosen
}

/// A kernel regression in Nyström form for one kernel and length scale, solved for every noise
/// ratio at once: with `K_zz = V Λ Vᵀ` (inducing points) the features are `φ(x) = Λ^{-1/2} Vᵀ k_z(x)`,
/// and with `Φᵀ Φ = U S Uᵀ` (training samples) the weights for a noise ratio λ are
/// `T U (S + λ)⁻¹ Uᵀ Φᵀ Y`, `T = V Λ^{-1/2}`. With every training sample an inducing point this is
/// the exact Gaussian-process mean `k(x)ᵀ (K + λ I)⁻¹ Y`.
struct Regression {
    /// `T U` (inducing × rank).
    tu: Mat<f64>,
    /// `S`.
    s: Vec<f64>,
    /// `Uᵀ Φᵀ Y` (rank × modes).
    b: Mat<f64>,
    /// Number of training samples.
    n: usize,
}

impl Regression {
    fn new(
        kernel: Kernel,
        scale: f64,
        inducing: &Mat<f64>,
        z2: &[f64],
        train: &Mat<f64>,
        t2: &[f64],
        y: &Mat<f64>,
    ) -> Result<Regression> {
        let par = training_par();
        let kzz = kernel_matrix(kernel, scale, inducing.as_ref(), z2, inducing.as_ref(), z2, par);
        let (lambda, v) = leading_eigen(kzz.as_ref(), kzz.nrows(), KERNEL_RANK_TOLERANCE)?;
        let t = Mat::from_fn(v.nrows(), v.ncols(), |i, j| v[(i, j)] / lambda[j].sqrt());
        let knz = kernel_matrix(kernel, scale, train.as_ref(), t2, inducing.as_ref(), z2, par);
        let phi = mul(knz.as_ref(), t.as_ref(), par);
        let c = mul(phi.transpose(), phi.as_ref(), par);
        let (s, u) = leading_eigen(c.as_ref(), c.nrows(), 0.0)?;
        let b = mul(mul(u.transpose(), phi.transpose(), par).as_ref(), y.as_ref(), par);
        let tu = mul(t.as_ref(), u.as_ref(), par);
        Ok(Regression { tu, s, b, n: train.nrows() })
    }

    /// [`new`](Self::new) when the inducing points are the training samples: then `Φ = V Λ^{1/2}`,
    /// so `S = Λ`, `U = I` and `Φᵀ Y = Λ^{1/2} Vᵀ Y`, and one eigendecomposition does.
    fn exact(kernel: Kernel, scale: f64, train: &Mat<f64>, t2: &[f64], y: &Mat<f64>) -> Result<Regression> {
        let par = training_par();
        let k = kernel_matrix(kernel, scale, train.as_ref(), t2, train.as_ref(), t2, par);
        let (lambda, v) = leading_eigen(k.as_ref(), k.nrows(), KERNEL_RANK_TOLERANCE)?;
        let vty = mul(v.transpose(), y.as_ref(), par);
        let b = Mat::from_fn(vty.nrows(), vty.ncols(), |i, j| vty[(i, j)] * lambda[i].sqrt());
        let tu = Mat::from_fn(v.nrows(), v.ncols(), |i, j| v[(i, j)] / lambda[j].sqrt());
        Ok(Regression { tu, s: lambda, b, n: train.nrows() })
    }

    /// The weights `A` of the mean `k_z(x)ᵀ A` (inducing × modes) for noise ratio `noise`.
    fn weights(&self, noise: f64) -> Mat<f64> {
        let scaled = Mat::from_fn(self.b.nrows(), self.b.ncols(), |k, j| self.b[(k, j)] / (self.s[k] + noise));
        mul(self.tu.as_ref(), scaled.as_ref(), training_par())
    }

    /// The matrix `G` of the unit-amplitude predictive variance `1 − k_z(x)ᵀ G k_z(x)`:
    /// `T U diag(S / (S + λ)) Uᵀ Tᵀ`.
    fn covariance(&self, noise: f64) -> Mat<f64> {
        let scaled =
            Mat::from_fn(self.tu.nrows(), self.tu.ncols(), |i, k| self.tu[(i, k)] * self.s[k] / (self.s[k] + noise));
        mul_t(scaled.as_ref(), self.tu.as_ref(), training_par())
    }

    /// Each mode's amplitude (signal variance) by maximum marginal likelihood at noise ratio λ:
    /// `yᵀ (Φ Φᵀ + λ I)⁻¹ y / n`, with `(Φ Φᵀ + λ I)⁻¹ = (I − Φ (C + λ)⁻¹ Φᵀ) / λ`.
    fn amplitudes(&self, noise: f64, y: &Mat<f64>) -> Vec<f64> {
        (0..y.ncols())
            .map(|j| {
                let yy: f64 = y.col(j).iter().map(|v| v * v).sum();
                let explained: f64 = (0..self.s.len()).map(|k| self.b[(k, j)].powi(2) / (self.s[k] + noise)).sum();
                ((yy - explained) / (noise * self.n as f64)).max(0.0)
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// With every training sample an inducing point, the Nyström solution and its shortcut are the
    /// exact Gaussian-process mean `k(x)ᵀ (K + λ I)⁻¹ y`, computed here by a dense solve.
    #[test]
    fn the_regression_is_the_exact_gaussian_process_mean() {
        let x = Mat::from_fn(12, 2, |i, d| ((i * 7 + d * 3) as f64 * 0.37).sin());
        let y = Mat::from_fn(12, 2, |i, j| ((i + 2 * j) as f64 * 0.5).cos());
        let x2 = row_norms2(x.as_ref());
        let (kernel, scale, noise) = (Kernel::Matern52, 0.8, 1e-2);
        let fitted = Regression::new(kernel, scale, &x, &x2, &x, &x2, &y).unwrap();
        let a = fitted.weights(noise);
        let k = kernel_matrix(kernel, scale, x.as_ref(), &x2, x.as_ref(), &x2, faer::Par::Seq);
        let mut regularised = k.clone();
        (0..12).for_each(|i| regularised[(i, i)] += noise);
        use faer::linalg::solvers::Solve;
        let alpha = regularised.llt(faer::Side::Lower).unwrap().solve(&y);
        let diff = (&a - &alpha).norm_l2() / alpha.norm_l2();
        assert!(diff < 1e-8, "relative difference {diff}");
        let shortcut = Regression::exact(kernel, scale, &x, &x2, &y).unwrap();
        let diff = (&shortcut.weights(noise) - &alpha).norm_l2() / alpha.norm_l2();
        assert!(diff < 1e-8, "the exact shortcut: relative difference {diff}");
        assert!((&shortcut.covariance(noise) - &fitted.covariance(noise)).norm_l2() < 1e-8);
        let (ours, theirs) = (shortcut.amplitudes(noise, &y), fitted.amplitudes(noise, &y));
        assert!(ours.iter().zip(&theirs).all(|(a, b)| (a - b).abs() < 1e-8 * b.abs().max(1.0)), "{ours:?} {theirs:?}");
        // The predictive variance at a training point: 1 − kᵀ (K + λI)⁻¹ k.
        let g = fitted.covariance(noise);
        let k0: Vec<f64> = k.row(0).iter().copied().collect();
        let exact = 1.0 - {
            let kv = Mat::from_fn(12, 1, |i, _| k0[i]);
            let sol = regularised.llt(faer::Side::Lower).unwrap().solve(&kv);
            (0..12).map(|i| k0[i] * sol[(i, 0)]).sum::<f64>()
        };
        let ours = 1.0 - super::super::quadratic_form(g.as_ref(), &k0);
        assert!((ours - exact).abs() < 1e-8, "variance {ours} against {exact}");
    }
}
