//! The 3D U-Net: its architecture, its parameters and the saved-model bundle.
//!
//! The architecture is described once, in `docs/method.md` (section 5.2), and in code by
//! `UNetConfig::layers`: every engine ([`crate::InferenceNet`], the backward pass of
//! [`crate::net::backprop`], burn's network of `burn_unet` with the `cpu-burn` feature) builds
//! its layers from that list, and `augsim.torch` (`python/augsim/torch.py`) follows it.
//!
//! [`UNet`] holds the parameters: one named `f32` tensor per weight and bias, in the order of the
//! layers (`encoder.0.conv1.weight`, `encoder.0.conv1.bias`, ...). A saved model is a JSON file
//! (configuration, normalisation, grid, units, training summary) and a safetensors file of those
//! tensors beside it.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use mesh::io::write_atomic_bytes;
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use safetensors::tensor::{Dtype, SafeTensors, TensorView};
use serde::{Deserialize, Serialize};

use crate::data::corrupt::{splitmix64, Corruption};
use crate::data::dataset::Normalization;
use crate::data::grid::{GridPlacement, GridShape, CHANNELS, LAYOUT};
use crate::data::split::{Provenance, Split};
use crate::fsutil::read;
use crate::net::inference::{InferenceNet, Packed};
use crate::FieldUnit;
use crate::{LearnError, Result};

/// U-Net hyper-parameters.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct UNetConfig {
    /// Input channels (3).
    pub in_channels: usize,
    /// Output channels (3).
    pub out_channels: usize,
    /// Channels of the first level (doubled at each down step).
    pub base_channels: usize,
    /// Number of down steps.
    pub depth: usize,
    /// Size of the level convolutions (odd).
    pub kernel_size: usize,
}

impl Default for UNetConfig {
    fn default() -> Self {
        UNetConfig { in_channels: CHANNELS, out_channels: CHANNELS, base_channels: 16, depth: 3, kernel_size: 3 }
    }
}

/// The most channels of any level's input, output or first level that [`UNetConfig::validate`]
/// accepts.
pub const MAX_CHANNELS: usize = 4096;
/// The largest kernel [`UNetConfig::validate`] accepts.
pub const MAX_KERNEL: usize = 15;
/// The most parameters [`UNetConfig::validate`] accepts: 400 MB of weights (the published
/// network has 16 first-level channels and depth 3: about 1.4 million).
pub const MAX_PARAMETERS: usize = 100_000_000;

impl UNetConfig {
    /// Checks the values: channels, depth and kernel, and a parameter count that fits in memory.
    pub fn validate(&self) -> Result<()> {
        let bad = |m: String| Err(LearnError::InvalidInput(format!("U-Net config: {m}")));
        if self.in_channels == 0 || self.out_channels == 0 || self.base_channels == 0 {
            return bad("channel counts must be at least 1".into());
        }
        if self.depth > 6 {
            return bad(format!("depth {} is more than 6", self.depth));
        }
        if self.kernel_size.is_multiple_of(2) {
            return bad(format!("kernel_size {} must be odd", self.kernel_size));
        }
        let largest = self.in_channels.max(self.out_channels).max(self.base_channels);
        if largest > MAX_CHANNELS || self.kernel_size > MAX_KERNEL {
            return bad(format!(
                "{largest} channels or kernel_size {}: beyond {MAX_CHANNELS} channels or kernel {MAX_KERNEL}",
                self.kernel_size
            ));
        }
        let parameters: usize = self.layers().iter().map(|l| l.weight_len() + l.c_out).sum();
        if parameters > MAX_PARAMETERS {
            return bad(format!(
                "{parameters} parameters, more than {MAX_PARAMETERS} (about 4 bytes each for the weights, and \
                 several times that in training): fewer channels, a smaller depth or kernel"
            ));
        }
        Ok(())
    }

    /// The multiple every grid dimension is padded to (`2^depth`).
    pub fn pad_multiple(&self) -> usize {
        1 << self.depth
    }

    /// The padded size of a grid dimension.
    pub fn padded(&self, n: usize) -> usize {
        n.div_ceil(self.pad_multiple()) * self.pad_multiple()
    }

    /// The layers, in parameter order: the two convolutions of each encoder level, the
    /// down-sampling convolutions, the bottleneck's two convolutions, the up-sampling
    /// convolutions, the two convolutions of each decoder level (level 0 first) and the head.
    pub(crate) fn layers(&self) -> Vec<Layer> {
        let (k, depth) = (self.kernel_size, self.depth);
        let ch = |l: usize| self.base_channels << l;
        let level_in = |l: usize| if l == 0 { self.in_channels } else { ch(l - 1) };
        let layer = |name: String, kind: LayerKind, c_in: usize, c_out: usize| Layer { name, kind, c_in, c_out };
        let conv = |parts: usize| LayerKind::Conv { kernel: k, parts };
        let mut layers = Vec::with_capacity(6 * depth + 3);
        for l in 0..depth {
            layers.push(layer(format!("encoder.{l}.conv1"), conv(1), level_in(l), ch(l)));
            layers.push(layer(format!("encoder.{l}.conv2"), conv(1), ch(l), ch(l)));
        }
        layers.extend((0..depth).map(|l| layer(format!("down.{l}"), LayerKind::Down, ch(l), ch(l))));
        layers.push(layer("bottleneck.conv1".into(), conv(1), level_in(depth), ch(depth)));
        layers.push(layer("bottleneck.conv2".into(), conv(1), ch(depth), ch(depth)));
        layers.extend((0..depth).map(|l| layer(format!("up.{l}"), LayerKind::Up, ch(l + 1), ch(l))));
        for l in 0..depth {
            layers.push(layer(format!("decoder.{l}.conv1"), conv(2), 2 * ch(l), ch(l)));
            layers.push(layer(format!("decoder.{l}.conv2"), conv(1), ch(l), ch(l)));
        }
        layers.push(layer("head".into(), LayerKind::Conv { kernel: 1, parts: 1 }, ch(0), self.out_channels));
        layers
    }
}

/// What a layer computes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum LayerKind {
    /// A stride-1 convolution of size `kernel³` with zero padding `kernel / 2`, whose input is the
    /// concatenation of `parts` equal channel groups (the decoder's up-sampled and skip features);
    /// a ReLU follows, except after the head.
    Conv {
        /// Kernel size.
        kernel: usize,
        /// Input channel groups.
        parts: usize,
    },
    /// A 2×2×2 stride-2 convolution (down-sampling).
    Down,
    /// A 2×2×2 stride-2 transposed convolution (up-sampling).
    Up,
}

/// One layer of the U-Net: its parameters are `{name}.weight` and `{name}.bias`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) struct Layer {
    /// The parameter path prefix (`encoder.0.conv1`, `down.1`, `head`, ...).
    pub(crate) name: String,
    /// What it computes.
    pub(crate) kind: LayerKind,
    /// Input channels.
    pub(crate) c_in: usize,
    /// Output channels.
    pub(crate) c_out: usize,
}

impl Layer {
    /// The weight's shape: `[c_out, c_in, k, k, k]` for a convolution, `[c_in, c_out, 2, 2, 2]`
    /// for the transposed one (burn's and PyTorch's layouts).
    pub(crate) fn weight_shape(&self) -> [usize; 5] {
        match self.kind {
            LayerKind::Conv { kernel: k, .. } => [self.c_out, self.c_in, k, k, k],
            LayerKind::Down => [self.c_out, self.c_in, 2, 2, 2],
            LayerKind::Up => [self.c_in, self.c_out, 2, 2, 2],
        }
    }

    /// The number of its weights (its biases are `c_out`).
    pub(crate) fn weight_len(&self) -> usize {
        self.weight_shape().iter().product()
    }

    /// Whether it belongs to the contracting path (frozen by [`UNet::freeze_encoder`]).
    fn in_encoder(&self) -> bool {
        UNet::is_encoder_parameter(&self.name)
    }
}

/// One item per layer, grouped as the U-Net's structure.
pub(crate) struct Levels<T> {
    /// The two convolutions of each encoder level.
    pub(crate) encoder: Vec<[T; 2]>,
    /// The down-sampling convolutions.
    pub(crate) down: Vec<T>,
    /// The bottleneck's two convolutions.
    pub(crate) bottleneck: [T; 2],
    /// The up-sampling convolutions, by level.
    pub(crate) up: Vec<T>,
    /// The two convolutions of each decoder level, by level.
    pub(crate) decoder: Vec<[T; 2]>,
    /// The 1×1×1 output convolution.
    pub(crate) head: T,
}

impl<T> Levels<T> {
    /// Groups the items of a network of `depth` levels, given in the order of
    /// [`UNetConfig::layers`].
    pub(crate) fn new(depth: usize, items: impl IntoIterator<Item = T>) -> Result<Levels<T>> {
        let mut items = items.into_iter();
        let mut take = || items.next().ok_or_else(|| LearnError::InvalidInput("U-Net layers missing".into()));
        let encoder = (0..depth).map(|_| Ok([take()?, take()?])).collect::<Result<Vec<_>>>()?;
        let down = (0..depth).map(|_| take()).collect::<Result<Vec<_>>>()?;
        let bottleneck = [take()?, take()?];
        let up = (0..depth).map(|_| take()).collect::<Result<Vec<_>>>()?;
        let decoder = (0..depth).map(|_| Ok([take()?, take()?])).collect::<Result<Vec<_>>>()?;
        let head = take()?;
        if items.next().is_some() {
            return Err(LearnError::InvalidInput("more layers than a U-Net of this depth has".into()));
        }
        Ok(Levels { encoder, down, bottleneck, up, decoder, head })
    }
}

/// A layer with its parameters, as [`UNet::levels`] gives them.
pub(crate) struct LayerParams<'a> {
    /// The layer.
    pub(crate) layer: &'a Layer,
    /// Its weight, in the layout of [`Layer::weight_shape`].
    pub(crate) weight: &'a [f32],
    /// Its bias (`c_out` values).
    pub(crate) bias: &'a [f32],
    /// Whether its parameters are trained (not those of a frozen encoder).
    pub(crate) trainable: bool,
    /// Its position in [`UNetConfig::layers`]: its weight is parameter `2 · index`, its bias
    /// `2 · index + 1`.
    pub(crate) index: usize,
}

/// The parameters of a 3D U-Net (see the module documentation).
#[derive(Clone, Debug, PartialEq)]
pub struct UNet {
    config: UNetConfig,
    layers: Vec<Layer>,
    /// Parameter `2 i` is the weight of layer `i`, `2 i + 1` its bias.
    values: Vec<Vec<f32>>,
    frozen_encoder: bool,
}

/// Parameter-path prefixes of the contracting path (frozen by [`UNet::freeze_encoder`]).
const ENCODER_PREFIXES: [&str; 3] = ["encoder.", "down.", "bottleneck."];

impl UNet {
    /// A new network with weights drawn from a generator seeded by `seed`: He-uniform weights
    /// (bound `√(6 / fan_in)`, fan-in from the weight's second dimension times the kernel
    /// volume, as PyTorch does), drawn layer after layer in parameter order, and zero biases.
    pub fn new(config: &UNetConfig, seed: u64) -> Result<UNet> {
        let mut net = UNet::zeros(config)?;
        let mut rng = StdRng::seed_from_u64(seed);
        for (layer, weight) in net.layers.iter().zip(net.values.iter_mut().step_by(2)) {
            let dims = layer.weight_shape();
            let bound = (6.0 / (dims[1] * dims[2..].iter().product::<usize>()) as f64).sqrt();
            weight.iter_mut().for_each(|w| *w = rng.random_range(-bound..bound) as f32);
        }
        Ok(net)
    }

    /// A network of `config` with every parameter zero.
    fn zeros(config: &UNetConfig) -> Result<UNet> {
        config.validate()?;
        let layers = config.layers();
        let values = layers.iter().flat_map(|l| [vec![0.0; l.weight_len()], vec![0.0; l.c_out]]).collect();
        Ok(UNet { config: config.clone(), layers, values, frozen_encoder: false })
    }

    /// The configuration.
    pub fn config(&self) -> &UNetConfig {
        &self.config
    }

    /// Number of down steps.
    pub fn depth(&self) -> usize {
        self.config.depth
    }

    /// Number of parameter values (weights and biases).
    pub fn num_params(&self) -> usize {
        self.values.iter().map(Vec::len).sum()
    }

    /// The layers with their parameters, grouped as the U-Net's structure.
    pub(crate) fn levels(&self) -> Result<Levels<LayerParams<'_>>> {
        let params = self.layers.iter().enumerate().map(|(index, layer)| LayerParams {
            layer,
            weight: &self.values[2 * index],
            bias: &self.values[2 * index + 1],
            trainable: !(self.frozen_encoder && layer.in_encoder()),
            index,
        });
        Levels::new(self.depth(), params)
    }

    /// The network repacked for fast CPU inference (same results up to rounding).
    pub fn to_inference(&self) -> Result<InferenceNet> {
        let levels = self.levels()?;
        let conv = |p: &LayerParams| -> Result<Packed> {
            let [c_out, c_in, kx, ky, kz] = p.layer.weight_shape();
            let parts = match p.layer.kind {
                LayerKind::Conv { parts, .. } => parts,
                LayerKind::Down | LayerKind::Up => 1,
            };
            Packed::conv(p.weight, p.bias, c_out, &vec![c_in / parts; parts], kx * ky * kz)
        };
        let block = |b: &[LayerParams; 2]| -> Result<[Packed; 2]> { Ok([conv(&b[0])?, conv(&b[1])?]) };
        let up = |p: &LayerParams| Packed::transposed(p.weight, p.bias, p.layer.c_in, p.layer.c_out);
        InferenceNet::new(
            self.config.kernel_size,
            levels.encoder.iter().map(block).collect::<Result<_>>()?,
            levels.down.iter().map(conv).collect::<Result<_>>()?,
            block(&levels.bottleneck)?,
            levels.up.iter().map(up).collect::<Result<_>>()?,
            levels.decoder.iter().map(block).collect::<Result<_>>()?,
            conv(&levels.head)?,
        )
    }

    /// Stops gradient updates of the contracting path (encoder levels, down-sampling, bottleneck).
    pub fn freeze_encoder(mut self) -> Self {
        self.frozen_encoder = true;
        self
    }

    /// Whether the contracting path is frozen ([`freeze_encoder`](Self::freeze_encoder)).
    pub fn frozen_encoder(&self) -> bool {
        self.frozen_encoder
    }

    /// Whether a parameter path (as in [`named_parameters`](Self::named_parameters)) belongs to
    /// the contracting path.
    pub fn is_encoder_parameter(path: &str) -> bool {
        ENCODER_PREFIXES.iter().any(|p| path.starts_with(p))
    }

    /// Every parameter with its path (`encoder.0.conv1.weight`, ...) and values, in parameter
    /// order.
    pub fn named_parameters(&self) -> Vec<(String, Vec<f32>)> {
        self.parameter_names().zip(&self.values).map(|(name, v)| (name, v.clone())).collect()
    }

    /// The parameter paths, in parameter order.
    pub(crate) fn parameter_names(&self) -> impl Iterator<Item = String> + '_ {
        self.layers.iter().flat_map(|l| [format!("{}.weight", l.name), format!("{}.bias", l.name)])
    }

    /// The shape of parameter `p`.
    pub(crate) fn parameter_shape(&self, p: usize) -> Vec<usize> {
        let layer = &self.layers[p / 2];
        if p.is_multiple_of(2) {
            layer.weight_shape().to_vec()
        } else {
            vec![layer.c_out]
        }
    }

    /// The values of every parameter, in parameter order.
    pub(crate) fn values(&self) -> &[Vec<f32>] {
        &self.values
    }

    /// The values of every parameter, to update them in place.
    pub(crate) fn values_mut(&mut self) -> &mut [Vec<f32>] {
        &mut self.values
    }

    /// Serializes the weights to safetensors bytes, one `F32` tensor per parameter under its
    /// path, with the metadata `{"format": "safetensors"}` (deterministic: the same weights give
    /// the same bytes).
    pub fn to_safetensors(&self) -> Result<Vec<u8>> {
        write_safetensors(self.tensors(""), Some(HashMap::from([("format".into(), "safetensors".into())])))
    }

    /// The parameters as named tensors (`prefix` + path), for [`write_safetensors`].
    pub(crate) fn tensors<'a>(&'a self, prefix: &'a str) -> impl Iterator<Item = NamedTensor<'a>> + 'a {
        self.parameter_names()
            .zip(&self.values)
            .enumerate()
            .map(move |(p, (name, v))| (format!("{prefix}{name}"), self.parameter_shape(p), &v[..]))
    }

    /// A network of `config` with the weights of safetensors `bytes` (every parameter present
    /// under its path with its shape, nothing else); `path` only names the source in errors.
    pub fn from_safetensors(config: &UNetConfig, bytes: &[u8], path: &Path) -> Result<UNet> {
        let tensors = SafeTensors::deserialize(bytes)
            .map_err(|e| LearnError::model(path, format!("cannot read safetensors weights: {e}")))?;
        let mut net = UNet::zeros(config)?;
        net.load_tensors(&tensors, "", path)?;
        let expected = net.values.len();
        if tensors.len() != expected {
            return Err(LearnError::model(
                path,
                format!(
                    "weights do not fit the configuration {config:?}: {} tensors, expected {expected}",
                    tensors.len()
                ),
            ));
        }
        Ok(net)
    }

    /// Replaces every parameter by the tensor `prefix` + its path of `tensors`; a tensor with a
    /// NaN or an infinite value is refused, named.
    pub(crate) fn load_tensors(&mut self, tensors: &SafeTensors, prefix: &str, path: &Path) -> Result<()> {
        let names: Vec<String> = self.parameter_names().collect();
        for (p, name) in names.iter().enumerate() {
            let values = read_tensor(tensors, &format!("{prefix}{name}"), &self.parameter_shape(p)).map_err(|m| {
                LearnError::model(path, format!("weights do not fit the configuration {:?}: {m}", self.config))
            })?;
            if let Some(at) = values.iter().position(|v| !v.is_finite()) {
                return Err(LearnError::model(
                    path,
                    format!(
                        "tensor {prefix}{name} holds a non-finite value ({} at position {at}): the weights are \
                         damaged; train again, or use an intact copy",
                        values[at]
                    ),
                ));
            }
            self.values[p] = values;
        }
        Ok(())
    }
}

/// A tensor to write: name, shape and values.
pub(crate) type NamedTensor<'a> = (String, Vec<usize>, &'a [f32]);

/// Serializes `F32` tensors to safetensors bytes.
pub(crate) fn write_safetensors<'a>(
    tensors: impl IntoIterator<Item = NamedTensor<'a>>,
    metadata: Option<HashMap<String, String>>,
) -> Result<Vec<u8>> {
    let bad = |e: safetensors::SafeTensorError| LearnError::InvalidInput(format!("cannot serialize safetensors: {e}"));
    let tensors: Vec<(String, Vec<usize>, Vec<u8>)> = tensors
        .into_iter()
        .map(|(name, shape, values)| (name, shape, values.iter().flat_map(|v| v.to_le_bytes()).collect()))
        .collect();
    let views = tensors
        .iter()
        .map(|(name, shape, bytes)| {
            Ok((name.as_str(), TensorView::new(Dtype::F32, shape.clone(), bytes).map_err(bad)?))
        })
        .collect::<Result<Vec<_>>>()?;
    safetensors::serialize(views, metadata).map_err(bad)
}

/// The values of the `F32` tensor `name` of `tensors`, which must have `shape`; the error says
/// what is wrong.
pub(crate) fn read_tensor(tensors: &SafeTensors, name: &str, shape: &[usize]) -> std::result::Result<Vec<f32>, String> {
    let t = tensors.tensor(name).map_err(|_| format!("tensor {name} is missing"))?;
    if t.dtype() != Dtype::F32 || t.shape() != shape {
        return Err(format!("tensor {name} is {:?} {:?}, expected F32 {shape:?}", t.dtype(), t.shape()));
    }
    Ok(t.data().chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect())
}

/// Gradients of a network's parameters, one entry per parameter in the order of
/// [`UNet::named_parameters`]: `None` for a parameter that is not trained (a frozen encoder's).
#[derive(Clone, Debug, PartialEq)]
pub struct Gradients(pub Vec<Option<Vec<f32>>>);

impl Gradients {
    /// Number of parameters that have a gradient.
    pub fn len(&self) -> usize {
        self.0.iter().flatten().count()
    }

    /// Whether no parameter has a gradient.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// Summary of the training run that produced a model.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TrainingInfo {
    /// Iterations run.
    pub iterations: usize,
    /// Iteration whose weights were kept, chosen on validation: `None` (`null`) without
    /// validation samples, when nothing chose them and the last iteration's were kept.
    pub best_iteration: Option<usize>,
    /// Validation mean Euclidean error at that iteration (m), if validated.
    pub best_val_mean_error: Option<f64>,
    /// Training samples.
    pub train_samples: usize,
    /// Validation samples.
    pub val_samples: usize,
    /// Training seed.
    pub seed: u64,
    /// Model file the training started from (transfer learning), if any.
    pub fine_tuned_from: Option<String>,
    /// Whether the encoder was frozen.
    pub frozen_encoder: bool,
    /// The corruption of its training inputs: with a sparsity, the network learned to take part
    /// of its input nodes, the others absent.
    #[serde(default)]
    pub corruption: Corruption,
    /// The samples of this run: training, validation (checkpoint selection) and test.
    #[serde(default)]
    pub split: Split,
    /// The splits of the runs this one was fine-tuned from, most recent first.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub pretraining: Vec<Split>,
    /// How its steps were taken (absent from models trained before it was recorded).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub schedule: Option<Schedule>,
}

/// The optimiser's settings of a training run: with the seed, the split and the corruption, what
/// retraining it takes.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Schedule {
    /// Samples per step (after capping at the training samples).
    pub batch_size: usize,
    /// Adam's learning rate at the first step.
    pub learning_rate: f64,
    /// The rate at the last step, reached along a half cosine, if it fell.
    pub final_learning_rate: Option<f64>,
    /// Steps between validations (the kept weights are chosen among them).
    pub validate_every: usize,
}

impl TrainingInfo {
    /// Every split that shaped the model: this run's and those of the runs it was fine-tuned
    /// from.
    pub fn splits(&self) -> impl Iterator<Item = &Split> {
        std::iter::once(&self.split).chain(&self.pretraining)
    }
}

/// The JSON part of a saved model.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct ModelFile {
    format: String,
    version: u32,
    layout: String,
    unet: UNetConfig,
    normalization: Normalization,
    grid: GridShape,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    placement: Option<GridPlacement>,
    input_unit: FieldUnit,
    target_unit: FieldUnit,
    weights: String,
    /// [`digest`] of the weights file: a pair written by two runs (one stopped between
    /// its two writes) is refused. Models saved before it was recorded have none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    weights_digest: Option<String>,
    training: Option<TrainingInfo>,
}

/// A digest of a file's bytes (SplitMix64 over its 8-byte words, in hex; a weights file's is
/// recorded in `model.json` as `weights_digest`, an input's in a preparation's record): not for
/// security, to tell one file from another.
pub fn digest(bytes: &[u8]) -> String {
    let digest = bytes.chunks(8).fold(splitmix64(bytes.len() as u64), |h, word| {
        let mut padded = [0u8; 8];
        padded[..word.len()].copy_from_slice(word);
        splitmix64(h ^ u64::from_le_bytes(padded))
    });
    format!("{digest:016x}")
}

/// The `format` of a U-Net's `model.json`.
pub(crate) const MODEL_FORMAT: &str = "augsim-unet";
const MODEL_VERSION: u32 = 1;

/// A trained network with everything needed to use it: configuration, normalisation, the grid
/// and units it was trained on, and a training summary.
#[derive(Debug)]
pub struct TrainedModel {
    /// Network configuration.
    pub config: UNetConfig,
    /// Input/target scales.
    pub normalization: Normalization,
    /// Grid of the training data (prediction inputs must be on it).
    pub grid: GridShape,
    /// Where that grid lies in space, when known (needed to map point clouds onto it).
    pub placement: Option<GridPlacement>,
    /// Input unit (forces or displacements).
    pub input_unit: FieldUnit,
    /// Target unit (displacements).
    pub target_unit: FieldUnit,
    /// How it was trained.
    pub training: Option<TrainingInfo>,
    /// The network's parameters.
    pub net: UNet,
}

impl TrainedModel {
    /// Saves the model: `json_path` and the weights beside it (same stem, `.safetensors`),
    /// both atomically.
    pub fn save(&self, json_path: &Path) -> Result<()> {
        let weights_path = json_path.with_extension("safetensors");
        let weights_name = weights_path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .ok_or_else(|| LearnError::InvalidInput(format!("model path {} has no file name", json_path.display())))?;
        let weights = self.net.to_safetensors()?;
        write_atomic_bytes(&weights_path, &weights)?;
        let file = ModelFile {
            format: MODEL_FORMAT.into(),
            version: MODEL_VERSION,
            layout: LAYOUT.into(),
            unet: self.config.clone(),
            normalization: self.normalization,
            grid: self.grid,
            placement: self.placement,
            input_unit: self.input_unit,
            target_unit: self.target_unit,
            weights: weights_name,
            weights_digest: Some(digest(&weights)),
            training: self.training.clone(),
        };
        let text = serde_json::to_string_pretty(&file)
            .map_err(|e| LearnError::model(json_path, format!("cannot serialize model file: {e}")))?;
        Ok(write_atomic_bytes(json_path, text.as_bytes())?)
    }

    /// The splits behind this model, when its training recorded them.
    pub fn provenance(&self) -> Option<Provenance<'_>> {
        self.training.as_ref().map(|t| Provenance { own: &t.split, earlier: &t.pretraining })
    }

    /// Loads a model saved by [`save`](Self::save).
    pub fn load(json_path: &Path) -> Result<TrainedModel> {
        let text = std::fs::read_to_string(json_path).map_err(|e| LearnError::io(json_path, e))?;
        let file: ModelFile = serde_json::from_str(&text)
            .map_err(|e| LearnError::model(json_path, format!("invalid model JSON: {e}")))?;
        if file.format != MODEL_FORMAT || file.version != MODEL_VERSION {
            return Err(LearnError::model(
                json_path,
                format!("format {:?} v{} is not {MODEL_FORMAT:?} v{MODEL_VERSION}", file.format, file.version),
            ));
        }
        file.unet.validate().map_err(|e| LearnError::model(json_path, e.to_string()))?;
        file.normalization.validate().map_err(|e| LearnError::model(json_path, e.to_string()))?;
        GridPlacement::check_in(file.placement.as_ref(), file.grid, json_path)?;
        let weights_path = weights_path(json_path, &file.weights)?;
        let bytes = read(&weights_path)?;
        // A file cut short or out of shape is told as such first; one whole but other as such.
        let net = UNet::from_safetensors(&file.unet, &bytes, &weights_path)?;
        if file.weights_digest.as_ref().is_some_and(|d| *d != digest(&bytes)) {
            return Err(LearnError::model(
                json_path,
                format!(
                    "{} is not the weights it describes (its digest differs): damaged since (a copy altered) or \
                     written by another run (one stopped between writing the two files); copy the model again from \
                     its source, or train again into this folder (it resumes)",
                    weights_path.display()
                ),
            ));
        }
        Ok(TrainedModel {
            config: file.unet,
            normalization: file.normalization,
            grid: file.grid,
            placement: file.placement,
            input_unit: file.input_unit,
            target_unit: file.target_unit,
            training: file.training,
            net,
        })
    }
}

/// The weights file named in a model JSON, which must be a plain file name beside it.
fn weights_path(json_path: &Path, name: &str) -> Result<PathBuf> {
    let p = Path::new(name);
    if p.components().count() != 1 || p.is_absolute() {
        return Err(LearnError::model(
            json_path,
            format!("weights {name:?} must be a file name beside the model file"),
        ));
    }
    Ok(json_path.with_file_name(name))
}
