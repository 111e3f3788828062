//! A reduced-order model (ROM): the second learned model beside the U-Net, trained on the same
//! datasets with the same splits, in seconds on a CPU.
//!
//! * **Output basis** — proper orthogonal decomposition (POD) of the training targets: their mean
//!   and leading principal directions over the grid nodes inside the organ (the method of
//!   snapshots on faer's symmetric eigensolver). The number of modes is chosen on validation.
//! * **Input features** — the nonzero entries of the training inputs, centred and projected on
//!   their leading principal directions (enough to hold all but 1e-5 of their energy): a space in
//!   which the kernel compares inputs, and which drops most of the noise of a corrupted input.
//!   Each feature may be divided by its training spread to a power (0 or ¼, chosen on
//!   validation), giving the smaller ones more say.
//! * **Physics prior** (optional, force inputs) — the linear-elastic response at rest of the
//!   dataset's problem ([`crate::data::response`]), in modal coefficients: a linear map of the
//!   input (`prior.npy`) that the model adds to the regression, which learns the nonlinear
//!   remainder; its leading coefficients are then the features the kernel compares.
//! * **Regression** — a Gaussian process from the features to the modal coefficients, all modes
//!   sharing one kernel (squared exponential or Matérn 5/2), length scale and noise ratio, each its
//!   own amplitude (the marginal-likelihood estimate). Kernel, length scale, noise, the number of
//!   modes and the features' scaling are chosen on validation (the mean over its samples of their
//!   root-mean-square node error). Large datasets use a Nyström (subset of
//!   regressors) approximation: at most [`RomConfig::max_inducing`] training samples serve as the
//!   inducing points; below that the regression is the exact Gaussian process.
//! * **Uncertainty** — the predictive variance of the process, spread to every node through the
//!   modes' amplitudes, plus the basis's own truncation error per node (measured on validation),
//!   scaled by one factor chosen on validation so that 95 % of the validation nodes' errors fall
//!   within two standard deviations.
//!
//! # Files
//! A model directory holds `model.json` (format `augsim-rom`) and NumPy arrays, so that NumPy
//! alone predicts with it:
//! ```python
//! import json, numpy as np
//! d = "models/liver_ar_rom"; m = json.load(open(f"{d}/model.json")); a = lambda n: np.load(f"{d}/{n}.npy")
//! x = input_field                                            # [3, nx, ny, nz], the model's input unit
//! v = x[a("input_mask").astype(bool)] - a("input_mean")
//! r = a("prior") if m["rom"].get("prior") else a("input_components")
//! f = a("feature_scales") * (r[:m["rom"]["input_components"]] @ v)
//! z = a("inducing"); d2 = ((z - f) ** 2).sum(1) / m["rom"]["length_scale"] ** 2
//! k = np.exp(-0.5 * d2)                                      # "rbf"; "matern52": (1+r+r²/3)e^{-r}, r = √(5 d2)
//! c = k @ a("weights")                                       # with a prior: c += a("prior")[:m["rom"]["modes"]] @ v
//! field = np.zeros(x.shape); mask = a("output_mask").astype(bool)
//! field[:, mask] = (a("output_mean") + c @ a("basis")).reshape(3, -1)
//! sigma = np.zeros(x.shape[1:])                              # per node, m
//! sigma[mask] = m["rom"]["calibration"] * np.sqrt(max(1 - k @ a("covariance") @ k, 0) * a("variance_weights") + a("floor"))
//! ```

mod fit;
mod linalg;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use faer::{Mat, MatRef, Par};
use serde::{Deserialize, Serialize};

use crate::data::corrupt::Corruption;
use crate::data::grid::{check_prediction_input, GridPlacement, GridShape, CHANNELS, LAYOUT};
use crate::data::split::Split;
use crate::FieldUnit;
use crate::{LearnError, Result};
use mesh::io::npy::{read_npy_bytes, write_f32, write_f64, write_u8};

pub use fit::{fit, Candidate, Context, RomConfig, RomReport};
pub use linalg::Kernel;

/// The format name in a reduced-order model's `model.json`.
pub const ROM_FORMAT: &str = "augsim-rom";
/// The file of a reduced-order model's basis, in its folder.
pub const BASIS_FILE: &str = "basis.npy";
const ROM_VERSION: u32 = 1;

/// How a reduced-order model was trained and what it chose.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RomInfo {
    /// The kernel.
    pub kernel: Kernel,
    /// Its length scale, in the input unit.
    pub length_scale: f64,
    /// The noise variance relative to the kernel's (the regression's ridge).
    pub noise: f64,
    /// Number of POD modes of the output.
    pub modes: usize,
    /// Number of principal components of the input the kernel compares.
    pub input_components: usize,
    /// The features' scaling: each is divided by its training spread, relative to the first
    /// feature's, to this power (`feature_scales.npy`).
    pub feature_exponent: f64,
    /// Number of inducing points (the training samples when the regression is exact).
    pub inducing: usize,
    /// Whether the regression is the exact Gaussian process (else its Nyström approximation).
    pub exact: bool,
    /// The factor on the predicted standard deviation chosen on validation.
    pub calibration: f64,
    /// Training samples (without their corrupted copies) and validation samples.
    pub train_samples: usize,
    /// Validation samples.
    pub val_samples: usize,
    /// Corrupted copies of each training sample added to the training set.
    pub noise_copies: usize,
    /// The corruption of those copies and of the validation inputs.
    pub corruption: Corruption,
    /// Seed of the corruption draws and of the choice of inducing points.
    pub seed: u64,
    /// The physics prior whose modal coefficients the model adds to its regression (`prior.npy`),
    /// if any.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub prior: Option<String>,
    /// Mean Euclidean error on the validation samples (m).
    pub val_mean_error: f64,
    /// Wall-clock seconds of the fit.
    pub seconds: f64,
    /// Which samples trained, selected and test the model.
    pub split: Split,
    /// The fit's settings, with which it is fitted again on more draws (`augsim generate
    /// --chosen-by`); absent in models saved before they were recorded.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fit: Option<RomConfig>,
}

/// The contents of `model.json`.
#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct RomFile {
    format: String,
    version: u32,
    layout: String,
    grid: GridShape,
    placement: Option<GridPlacement>,
    input_unit: FieldUnit,
    target_unit: FieldUnit,
    rom: RomInfo,
    /// A digest of each array file as saved ([`crate::digest`]), so that arrays of another fit
    /// copied in are refused; absent in models saved before they were recorded.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    array_digests: Option<BTreeMap<String, String>>,
}

/// A trained reduced-order model (see the module documentation).
#[derive(Clone, Debug)]
pub struct ReducedModel {
    /// Grid of the training data (prediction inputs must be on it).
    pub grid: GridShape,
    /// Where that grid lies in space, when known.
    pub placement: Option<GridPlacement>,
    /// Input unit (forces or displacements).
    pub input_unit: FieldUnit,
    /// Target unit (displacements).
    pub target_unit: FieldUnit,
    /// How it was trained.
    pub info: RomInfo,
    /// Field entries (`[3, nx, ny, nz]` indices) the input features read.
    input_entries: Vec<usize>,
    input_mean: Vec<f64>,
    /// How the centred input is read.
    reader: Reader,
    /// The factor on each feature (`components`).
    feature_scales: Vec<f64>,
    /// `inducing × components`, and their squared norms.
    inducing: Mat<f64>,
    inducing_norms: Vec<f64>,
    /// `inducing × modes`: the coefficients are `k(x)ᵀ weights`, plus the prior's with a prior.
    weights: Mat<f64>,
    /// `inducing × inducing`: the predictive variance is `1 − k(x)ᵀ covariance k(x)`.
    covariance: Mat<f64>,
    /// Grid nodes inside the organ (where the output lives), in increasing order.
    nodes: Vec<usize>,
    /// The output mean and the basis (`modes × 3·nodes`, channel-major over `nodes`).
    output_mean: Vec<f64>,
    basis: Mat<f64>,
    /// Per node: Σ modes' amplitude² × basis² over the channels, and the truncation variance.
    variance_weights: Vec<f64>,
    floor: Vec<f64>,
}

/// How a model reads its centred input `x`: the features its kernel compares, and the prior's
/// modal coefficients that it adds to the regression's.
#[derive(Clone, Debug)]
enum Reader {
    /// The input's principal directions (`components × entries`): the features are `P x`.
    Components(Mat<f64>),
    /// A prior's modal coefficients `A x` (`rows × entries`, rows the larger of the modes and the
    /// features): the first [`RomInfo::input_components`] are the features, the first
    /// [`RomInfo::modes`] add to the coefficients.
    Prior(Mat<f64>),
}

/// A prediction with its uncertainty.
#[derive(Clone, Debug, PartialEq)]
pub struct UncertainPrediction {
    /// The displacement field, `[3, nx, ny, nz]` (m; zero outside the organ).
    pub field: Vec<f32>,
    /// The predicted standard deviation of the displacement's error at each grid node (m, the
    /// root mean square of its Euclidean norm; zero outside the organ), `[nx, ny, nz]`.
    pub std: Vec<f32>,
}

impl ReducedModel {
    /// The field entries (`[3, nx, ny, nz]` indices) its input features read: the rest of an
    /// input field is not read.
    pub fn input_entries(&self) -> &[usize] {
        &self.input_entries
    }

    /// How far one input field lies from the training inputs, as the kernel sees it: its
    /// features' norm over the root mean square of the inducing points' (training inputs').
    pub fn feature_ratio(&self, input: &[f32]) -> Result<f64> {
        let (features, _) = self.features(input)?;
        let norm: f64 = features.iter().map(|v| v * v).sum();
        let training = self.inducing_norms.iter().sum::<f64>() / self.inducing_norms.len().max(1) as f64;
        Ok((norm / training).sqrt())
    }

    /// The features of one input field and the prior's modal coefficients (empty without one).
    fn features(&self, input: &[f32]) -> Result<(Vec<f64>, Vec<f64>)> {
        check_prediction_input(input, self.grid)?;
        let x: Vec<f64> =
            self.input_entries.iter().zip(&self.input_mean).map(|(&e, m)| f64::from(input[e]) - m).collect();
        let (mut features, prior) = match &self.reader {
            Reader::Components(p) => (gemv(p.as_ref(), &x), Vec::new()),
            Reader::Prior(a) => {
                let coefficients = gemv(a.as_ref(), &x);
                let (features, modes) = (self.info.input_components, self.info.modes);
                (coefficients[..features].to_vec(), coefficients[..modes].to_vec())
            }
        };
        features.iter_mut().zip(&self.feature_scales).for_each(|(f, s)| *f *= s);
        Ok((features, prior))
    }

    /// The kernel row of one input field and the prior's modal coefficients (empty without one).
    fn kernel_row(&self, input: &[f32]) -> Result<(Vec<f64>, Vec<f64>)> {
        let (features, prior) = self.features(input)?;
        let norm: f64 = features.iter().map(|v| v * v).sum();
        let cross = gemv(self.inducing.as_ref(), &features);
        let k = cross
            .iter()
            .zip(&self.inducing_norms)
            .map(|(c, z2)| self.info.kernel.eval(z2 + norm - 2.0 * c, self.info.length_scale))
            .collect();
        Ok((k, prior))
    }

    /// The displacement on the organ's nodes (channel-major over [`Self::nodes`]) for a kernel row
    /// and the prior's coefficients.
    fn reconstruct(&self, k: &[f64], prior: &[f64]) -> Vec<f64> {
        let mut coeffs = gemv(self.weights.transpose(), k);
        coeffs.iter_mut().zip(prior).for_each(|(c, p)| *c += p);
        let mut out = gemv(self.basis.transpose(), &coeffs);
        out.iter_mut().zip(&self.output_mean).for_each(|(o, m)| *o += m);
        out
    }

    /// Scatters values on the organ's nodes (channel-major) into a `[channels, nx, ny, nz]` field.
    fn scatter(&self, values: &[f64], channels: usize) -> Vec<f32> {
        let n = self.grid.nodes();
        let mut field = vec![0f32; channels * n];
        for c in 0..channels {
            for (p, &node) in self.nodes.iter().enumerate() {
                field[c * n + node] = values[c * self.nodes.len() + p] as f32;
            }
        }
        field
    }

    /// Predicts the displacement field (m, `[3, nx, ny, nz]`, zero outside the organ) for one
    /// input field (`[3, nx, ny, nz]` on the model's grid, in the model's input unit).
    pub fn predict(&self, input: &[f32]) -> Result<Vec<f32>> {
        let (k, prior) = self.kernel_row(input)?;
        Ok(self.scatter(&self.reconstruct(&k, &prior), CHANNELS))
    }

    /// [`predict`](Self::predict) with the predicted standard deviation at every node.
    pub fn predict_with_std(&self, input: &[f32]) -> Result<UncertainPrediction> {
        let (k, prior) = self.kernel_row(input)?;
        let field = self.scatter(&self.reconstruct(&k, &prior), CHANNELS);
        let std = self.scatter(&self.node_std(&k), 1);
        Ok(UncertainPrediction { field, std })
    }

    /// The predicted standard deviation alone (`[nx, ny, nz]`, m, zero outside the organ) for one
    /// input field: [`predict_with_std`](Self::predict_with_std)'s without the displacement.
    pub fn predict_std(&self, input: &[f32]) -> Result<Vec<f32>> {
        let (k, _) = self.kernel_row(input)?;
        Ok(self.scatter(&self.node_std(&k), 1))
    }

    /// The calibrated standard deviation on the organ's nodes for a kernel row.
    fn node_std(&self, k: &[f64]) -> Vec<f64> {
        let v = (1.0 - quadratic_form(self.covariance.as_ref(), k)).max(0.0);
        self.variance_weights.iter().zip(&self.floor).map(|(w, f)| self.info.calibration * (v * w + f).sqrt()).collect()
    }

    /// The displacement field `field` (`[3, nx, ny, nz]`, m) projected on the model's basis: the
    /// mean plus the field's components along the modes, on the organ's nodes (zero elsewhere).
    pub fn project(&self, field: &[f32]) -> Result<Vec<f32>> {
        let n = self.grid.nodes();
        if field.len() != CHANNELS * n {
            return Err(LearnError::InvalidInput(format!(
                "a field of {} values, expected {CHANNELS} × {n}",
                field.len()
            )));
        }
        let centred: Vec<f64> = (0..CHANNELS)
            .flat_map(|c| self.nodes.iter().map(move |&node| c * n + node))
            .zip(&self.output_mean)
            .map(|(e, mean)| f64::from(field[e]) - mean)
            .collect();
        let coefficients = gemv(self.basis.as_ref(), &centred);
        let mut out = gemv(self.basis.transpose(), &coefficients);
        out.iter_mut().zip(&self.output_mean).for_each(|(o, m)| *o += m);
        Ok(self.scatter(&out, CHANNELS))
    }

    /// The model's shape space on its grid, its leading `modes` modes at most: the output mean and
    /// each mode as `[3, nx, ny, nz]` fields (m, zero outside the organ), and the prior of the modal
    /// coefficients — the mean and covariance (`modes × modes`, row-major) of the regression's
    /// coefficients at its inducing points (the training samples, or a subset of them):
    /// `k(Z, Z) · weights`, plus the physics prior's coefficients where the features hold them.
    pub fn shape_space(&self, modes: usize) -> Result<GridShapeSpace> {
        let modes = modes.min(self.info.modes);
        let mut coefficients = linalg::kernel_matrix(
            self.info.kernel,
            self.info.length_scale,
            self.inducing.as_ref(),
            &self.inducing_norms,
            self.inducing.as_ref(),
            &self.inducing_norms,
            Par::rayon(0),
        );
        coefficients = linalg::mul(coefficients.as_ref(), self.weights.subcols(0, modes), Par::rayon(0));
        if matches!(self.reader, Reader::Prior(_)) {
            // The prior's coefficients are the leading features, unscaled; only as many as there are
            // features can be recovered.
            if self.info.input_components < modes {
                return Err(LearnError::InvalidInput(format!(
                    "the shape space of {modes} modes of a model with a physics prior needs as many features, it has \
                     {}: ask for fewer modes",
                    self.info.input_components
                )));
            }
            for i in 0..coefficients.nrows() {
                for j in 0..modes {
                    coefficients[(i, j)] += self.inducing[(i, j)] / self.feature_scales[j];
                }
            }
        }
        let m = coefficients.nrows();
        if m < 2 {
            return Err(LearnError::InvalidInput("a shape prior needs at least two inducing points".into()));
        }
        let mean: Vec<f64> = (0..modes).map(|j| coefficients.col(j).iter().sum::<f64>() / m as f64).collect();
        let centred = Mat::from_fn(m, modes, |i, j| coefficients[(i, j)] - mean[j]);
        let covariance = linalg::mul(centred.transpose(), centred.as_ref(), Par::rayon(0));
        let field = |values: &[f64]| self.scatter(values, CHANNELS);
        Ok(GridShapeSpace {
            mean_field: field(&self.output_mean),
            mode_fields: (0..modes).map(|j| field(&self.basis.row(j).iter().copied().collect::<Vec<_>>())).collect(),
            prior_mean: mean,
            prior_covariance: (0..modes * modes).map(|e| covariance[(e / modes, e % modes)] / (m - 1) as f64).collect(),
            floor: self.scatter(&self.floor, 1),
        })
    }

    /// Saves the model as a directory: `dir/model.json` and its arrays beside it, each file
    /// written atomically.
    pub fn save(&self, dir: &Path) -> Result<()> {
        mesh::io::create_folder(dir)?;
        mesh::io::remove_stale_temporaries(dir);
        let (modes, entries) = (self.basis.nrows(), self.input_entries.len());
        let mut input_mask = vec![0u8; self.grid.field_len()];
        self.input_entries.iter().for_each(|&e| input_mask[e] = 1);
        let mut output_mask = vec![0u8; self.grid.nodes()];
        self.nodes.iter().for_each(|&n| output_mask[n] = 1);
        let [nx, ny, nz] = self.grid.dims();
        let mut saved = SavedArrays { dir, names: Vec::new() };
        write_u8(&saved.file("input_mask.npy"), &[CHANNELS, nx, ny, nz], &input_mask)?;
        write_u8(&saved.file("output_mask.npy"), &[nx, ny, nz], &output_mask)?;
        write_f64(&saved.file("input_mean.npy"), &[entries], &self.input_mean)?;
        // The other reader's array, left by an earlier model in the directory, would mislead.
        let stale =
            dir.join(if matches!(self.reader, Reader::Prior(_)) { "input_components.npy" } else { "prior.npy" });
        match std::fs::remove_file(&stale) {
            Err(e) if e.kind() != std::io::ErrorKind::NotFound => return Err(LearnError::io(&stale, e)),
            _ => {}
        }
        match &self.reader {
            Reader::Components(p) => write_matrix(&saved.file("input_components.npy"), p.as_ref())?,
            Reader::Prior(a) => {
                let values: Vec<f32> =
                    (0..a.nrows()).flat_map(|i| a.row(i).iter().map(|&v| v as f32).collect::<Vec<_>>()).collect();
                write_f32(&saved.file("prior.npy"), &[a.nrows(), a.ncols()], &values)?;
            }
        }
        write_f64(&saved.file("feature_scales.npy"), &[self.feature_scales.len()], &self.feature_scales)?;
        write_matrix(&saved.file("inducing.npy"), self.inducing.as_ref())?;
        write_matrix(&saved.file("weights.npy"), self.weights.as_ref())?;
        write_matrix(&saved.file("covariance.npy"), self.covariance.as_ref())?;
        let mean32: Vec<f32> = self.output_mean.iter().map(|&v| v as f32).collect();
        write_f32(&saved.file("output_mean.npy"), &[mean32.len()], &mean32)?;
        let basis32: Vec<f32> =
            (0..modes).flat_map(|j| self.basis.row(j).iter().map(|&v| v as f32).collect::<Vec<_>>()).collect();
        write_f32(&saved.file(BASIS_FILE), &[modes, self.basis.ncols()], &basis32)?;
        write_f64(&saved.file("variance_weights.npy"), &[self.nodes.len()], &self.variance_weights)?;
        write_f64(&saved.file("floor.npy"), &[self.nodes.len()], &self.floor)?;
        let array_digests = saved.digests()?;
        let file = RomFile {
            format: ROM_FORMAT.into(),
            version: ROM_VERSION,
            layout: LAYOUT.into(),
            grid: self.grid,
            placement: self.placement,
            input_unit: self.input_unit,
            target_unit: self.target_unit,
            rom: self.info.clone(),
            array_digests: Some(array_digests),
        };
        let path = dir.join(crate::MODEL_FILE);
        let text = serde_json::to_string_pretty(&file)
            .map_err(|e| LearnError::model(&path, format!("cannot serialize model file: {e}")))?;
        Ok(mesh::io::write_atomic_bytes(&path, text.as_bytes())?)
    }

    /// Loads a model saved by [`save`](Self::save) from its `model.json`.
    pub fn load(json_path: &Path) -> Result<ReducedModel> {
        let text = std::fs::read_to_string(json_path).map_err(|e| LearnError::io(json_path, e))?;
        let file: RomFile = serde_json::from_str(&text)
            .map_err(|e| LearnError::model(json_path, format!("invalid model JSON: {e}")))?;
        if file.format != ROM_FORMAT || file.version != ROM_VERSION {
            return Err(LearnError::model(
                json_path,
                format!("format {:?} v{} is not {ROM_FORMAT:?} v{ROM_VERSION}", file.format, file.version),
            ));
        }
        GridPlacement::check_in(file.placement.as_ref(), file.grid, json_path)?;
        let dir = json_path.parent().unwrap_or(Path::new("."));
        let arrays = Arrays { dir: dir.to_path_buf(), json: json_path.to_path_buf(), digests: file.array_digests };
        let grid = file.grid;
        let input_mask = arrays.mask("input_mask")?;
        let output_mask = arrays.mask("output_mask")?;
        if input_mask.len() != grid.field_len() || output_mask.len() != grid.nodes() {
            return Err(arrays.bad("the masks do not match the grid"));
        }
        let input_entries: Vec<usize> = (0..input_mask.len()).filter(|&e| input_mask[e] == 1).collect();
        let nodes: Vec<usize> = (0..output_mask.len()).filter(|&n| output_mask[n] == 1).collect();
        let info = file.rom;
        let (k, m, r) = (info.input_components, info.inducing, info.modes);
        let model = ReducedModel {
            input_mean: arrays.vector("input_mean", input_entries.len())?,
            reader: match info.prior {
                None => Reader::Components(arrays.matrix("input_components", k, input_entries.len())?),
                Some(_) => Reader::Prior(arrays.matrix("prior", k.max(r), input_entries.len())?),
            },
            feature_scales: arrays.vector("feature_scales", k)?,
            inducing: arrays.matrix("inducing", m, k)?,
            weights: arrays.matrix("weights", m, r)?,
            covariance: arrays.matrix("covariance", m, m)?,
            output_mean: arrays.vector("output_mean", CHANNELS * nodes.len())?,
            basis: arrays.matrix("basis", r, CHANNELS * nodes.len())?,
            variance_weights: arrays.vector("variance_weights", nodes.len())?,
            floor: arrays.vector("floor", nodes.len())?,
            inducing_norms: Vec::new(),
            input_entries,
            nodes,
            grid,
            placement: file.placement,
            input_unit: file.input_unit,
            target_unit: file.target_unit,
            info,
        };
        if !(model.info.length_scale > 0.0 && model.info.calibration > 0.0) {
            return Err(arrays.bad("length scale and calibration must be positive"));
        }
        Ok(model.with_norms())
    }

    /// The model with the inducing points' squared norms computed.
    fn with_norms(mut self) -> ReducedModel {
        self.inducing_norms = linalg::row_norms2(self.inducing.as_ref());
        self
    }

    /// The grid nodes inside the organ, where the model predicts.
    pub fn nodes(&self) -> &[usize] {
        &self.nodes
    }
}

/// A reduced-order model's shape space on its grid ([`ReducedModel::shape_space`]): the
/// displacement `mean + Σ_j c_j mode_j`, and a Gaussian prior of the coefficients `c`.
#[derive(Clone, Debug)]
pub struct GridShapeSpace {
    /// The output mean, `[3, nx, ny, nz]` (m).
    pub mean_field: Vec<f32>,
    /// Each mode, `[3, nx, ny, nz]` (m per unit coefficient).
    pub mode_fields: Vec<Vec<f32>>,
    /// The coefficients' prior mean.
    pub prior_mean: Vec<f64>,
    /// Their prior covariance, `modes × modes`, row-major.
    pub prior_covariance: Vec<f64>,
    /// The basis's truncation variance at each grid node (m², `[nx, ny, nz]`): what no
    /// combination of the modes holds, measured on validation.
    pub floor: Vec<f32>,
}

/// `m · x`, on one thread (a single prediction is too small to share).
fn gemv(m: MatRef<'_, f64>, x: &[f64]) -> Vec<f64> {
    let mut out = Mat::<f64>::zeros(m.nrows(), 1);
    let xv = MatRef::from_column_major_slice(x, x.len(), 1);
    faer::linalg::matmul::matmul(out.as_mut(), faer::Accum::Replace, m, xv, 1.0, Par::Seq);
    out.col(0).iter().copied().collect()
}

/// `kᵀ M k` for a symmetric `M`.
fn quadratic_form(m: MatRef<'_, f64>, k: &[f64]) -> f64 {
    gemv(m, k).iter().zip(k).map(|(a, b)| a * b).sum()
}

/// Writes a matrix as a C-order `<f8` array.
fn write_matrix(path: &Path, m: MatRef<'_, f64>) -> Result<()> {
    let values: Vec<f64> = (0..m.nrows()).flat_map(|i| m.row(i).iter().copied().collect::<Vec<_>>()).collect();
    Ok(write_f64(path, &[m.nrows(), m.ncols()], &values)?)
}

/// The arrays a model saves, named as each is written, then each file's digest recorded (keyed by
/// its name without `.npy`, as [`Arrays`] looks it up).
struct SavedArrays<'d> {
    dir: &'d Path,
    names: Vec<&'static str>,
}

impl SavedArrays<'_> {
    /// The path of the array file `name` (`NAME.npy`), to be written and digested.
    fn file(&mut self, name: &'static str) -> PathBuf {
        self.names.push(name);
        self.dir.join(name)
    }

    /// The digest of each array file named, as written.
    fn digests(&self) -> Result<BTreeMap<String, String>> {
        self.names
            .iter()
            .map(|name| {
                let path = self.dir.join(name);
                let bytes = std::fs::read(&path).map_err(|e| LearnError::io(&path, e))?;
                Ok((name.trim_end_matches(".npy").to_string(), crate::digest(&bytes)))
            })
            .collect()
    }
}

/// Reads the arrays of a model directory, checking their shapes and, where the model records
/// them, their digests.
struct Arrays {
    dir: PathBuf,
    json: PathBuf,
    digests: Option<BTreeMap<String, String>>,
}

impl Arrays {
    fn bad(&self, message: impl Into<String>) -> LearnError {
        LearnError::model(&self.json, message.into())
    }

    /// The array `NAME.npy`, its digest checked against the one recorded.
    fn array(&self, name: &str) -> Result<mesh::io::npy::NpyArray> {
        let path = self.dir.join(format!("{name}.npy"));
        let (array, bytes) = read_npy_bytes(&path)?;
        let recorded = self.digests.as_ref().and_then(|d| d.get(name));
        if recorded.is_some_and(|d| *d != crate::digest(&bytes)) {
            return Err(self.bad(format!(
                "{name}.npy is not the one saved with this model (changed since, or another fit's): save the model \
                 again, or restore its folder whole"
            )));
        }
        Ok(array)
    }

    fn mask(&self, name: &str) -> Result<Vec<u8>> {
        Ok(self.array(name)?.into_mask(&self.dir.join(format!("{name}.npy")))?)
    }

    fn read(&self, name: &str, shape: &[usize]) -> Result<Vec<f64>> {
        let array = self.array(name)?;
        if array.shape != shape {
            return Err(self.bad(format!("{name}.npy has shape {:?}, expected {shape:?}", array.shape)));
        }
        let values = array.into_f64();
        if values.iter().any(|v| !v.is_finite()) {
            return Err(self.bad(format!("{name}.npy has a non-finite value")));
        }
        Ok(values)
    }

    fn vector(&self, name: &str, n: usize) -> Result<Vec<f64>> {
        self.read(name, &[n])
    }

    fn matrix(&self, name: &str, rows: usize, cols: usize) -> Result<Mat<f64>> {
        let v = self.read(name, &[rows, cols])?;
        Ok(Mat::from_fn(rows, cols, |i, j| v[i * cols + j]))
    }
}
