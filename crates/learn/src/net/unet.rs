//! The 3D U-Net and the saved-model bundle.
//!
//! The architecture is described once, in `docs/method.md` (section 5.2); every engine ([`UNet`]
//! here, [`crate::InferenceNet`], the backward pass of [`crate::net::backprop`]) and
//! `python/augsim_unet.py` follow it.
//!
//! A saved model is a JSON file (configuration, normalisation, grid, units, training summary)
//! and a safetensors file of the weights beside it.

use std::path::{Path, PathBuf};

use burn::module::{Module, ModuleMapper, ModuleVisitor, Param};
use burn::nn::conv::{Conv3d, Conv3dConfig, ConvTranspose3d, ConvTranspose3dConfig};
use burn::nn::{Initializer, PaddingConfig3d};
use burn::store::{ModuleSnapshot, SafetensorsStore};
use burn::tensor::activation::relu;
use burn::tensor::ops::PadMode;
use burn::tensor::{Device, Tensor, TensorData};
use mesh::io::write_atomic_bytes;

use crate::data::corrupt::Corruption;
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use serde::{Deserialize, Serialize};

use crate::data::dataset::{Normalization, Samples};
use crate::data::grid::{GridPlacement, GridShape, CHANNELS, LAYOUT};
use crate::data::split::{Provenance, SampleRole, Split};
use crate::fsutil::read;
use crate::net::inference::{Block, InferenceNet, Packed};
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

impl UNetConfig {
    /// Checks the values.
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
}

/// Two convolutions with ReLU.
#[derive(Module, Debug)]
struct ConvBlock {
    conv1: Conv3d,
    conv2: Conv3d,
}

impl ConvBlock {
    fn new(c_in: usize, c_out: usize, k: usize, device: &Device) -> Self {
        let conv = |a: usize, b: usize| {
            Conv3dConfig::new([a, b], [k, k, k])
                .with_padding(PaddingConfig3d::Explicit(k / 2, k / 2, k / 2))
                .with_initializer(Initializer::Zeros)
                .init(device)
        };
        ConvBlock { conv1: conv(c_in, c_out), conv2: conv(c_out, c_out) }
    }

    fn forward(&self, x: Tensor<5>) -> Tensor<5> {
        relu(self.conv2.forward(relu(self.conv1.forward(x))))
    }
}

/// The 3D U-Net (see the module documentation).
#[derive(Module, Debug)]
pub struct UNet {
    encoder: Vec<ConvBlock>,
    down: Vec<Conv3d>,
    bottleneck: ConvBlock,
    up: Vec<ConvTranspose3d>,
    decoder: Vec<ConvBlock>,
    head: Conv3d,
}

/// Parameter-path prefixes of the contracting path (frozen by [`UNet::freeze_encoder`]).
const ENCODER_PREFIXES: [&str; 3] = ["encoder.", "down.", "bottleneck."];

/// The values of a float tensor, read back from its device.
pub(crate) fn tensor_values<const D: usize>(t: Tensor<D>) -> Result<Vec<f32>> {
    t.into_data().try_into_vec_as::<f32>().map_err(|e| LearnError::InvalidInput(format!("cannot read a tensor: {e:?}")))
}

impl UNet {
    /// A new network on `device`, with weights drawn from a generator seeded by `seed`
    /// (He-uniform weights, zero biases), independent of the backend's global random state.
    pub fn new(config: &UNetConfig, device: &Device, seed: u64) -> Result<UNet> {
        config.validate()?;
        let k = config.kernel_size;
        let ch = |l: usize| config.base_channels << l;
        let zeros = Initializer::Zeros;
        let mut encoder = Vec::new();
        let mut down = Vec::new();
        let mut up = Vec::new();
        let mut decoder = Vec::new();
        for l in 0..config.depth {
            let c_in = if l == 0 { config.in_channels } else { ch(l - 1) };
            encoder.push(ConvBlock::new(c_in, ch(l), k, device));
            down.push(
                Conv3dConfig::new([ch(l), ch(l)], [2, 2, 2])
                    .with_stride([2, 2, 2])
                    .with_initializer(zeros.clone())
                    .init(device),
            );
            up.push(
                ConvTranspose3dConfig::new([ch(l + 1), ch(l)], [2, 2, 2])
                    .with_stride([2, 2, 2])
                    .with_initializer(zeros.clone())
                    .init(device),
            );
            decoder.push(ConvBlock::new(2 * ch(l), ch(l), k, device));
        }
        let bottleneck_in = if config.depth == 0 { config.in_channels } else { ch(config.depth - 1) };
        let bottleneck = ConvBlock::new(bottleneck_in, ch(config.depth), k, device);
        let head = Conv3dConfig::new([ch(0), config.out_channels], [1, 1, 1]).with_initializer(zeros).init(device);
        let net = UNet { encoder, down, bottleneck, up, decoder, head };
        Ok(net.map(&mut SeededInit { rng: StdRng::seed_from_u64(seed), fan_in: 1 }))
    }

    /// Number of down steps.
    pub fn depth(&self) -> usize {
        self.encoder.len()
    }

    /// Runs the network on a batch `[batch, in_channels, nx, ny, nz]` (any grid size; padded
    /// internally) and returns `[batch, out_channels, nx, ny, nz]`.
    pub fn forward(&self, x: Tensor<5>) -> Tensor<5> {
        let [batch, _, nx, ny, nz] = x.dims();
        let m = 1usize << self.depth();
        let pad = |n: usize| n.div_ceil(m) * m - n;
        let (px, py, pz) = (pad(nx), pad(ny), pad(nz));
        let mut h = if px + py + pz > 0 { x.pad([(0, px), (0, py), (0, pz)], PadMode::Constant(0.0)) } else { x };
        let mut skips = Vec::with_capacity(self.depth());
        for (block, down) in self.encoder.iter().zip(&self.down) {
            h = block.forward(h);
            skips.push(h.clone());
            h = down.forward(h);
        }
        h = self.bottleneck.forward(h);
        for l in (0..self.depth()).rev() {
            h = self.up[l].forward(h);
            h = Tensor::cat(vec![h, skips[l].clone()], 1);
            h = self.decoder[l].forward(h);
        }
        let out = self.head.forward(h);
        let channels = out.dims()[1];
        if px + py + pz > 0 {
            out.slice([0..batch, 0..channels, 0..nx, 0..ny, 0..nz])
        } else {
            out
        }
    }

    /// The network repacked for fast CPU inference (same results up to rounding).
    pub fn to_inference(&self) -> Result<InferenceNet> {
        let values = tensor_values::<5>;
        let bias = |b: &Option<Param<Tensor<1>>>, n: usize| -> Result<Vec<f32>> {
            match b {
                Some(b) => tensor_values(b.val()),
                None => Ok(vec![0.0; n]),
            }
        };
        // `parts`: the input is the concatenation of that many equal channel groups.
        let conv = |c: &Conv3d, parts: usize| -> Result<Packed> {
            let [c_out, c_in, kx, ky, kz] = c.weight.dims();
            let splits = vec![c_in / parts; parts];
            Packed::conv(&values(c.weight.val())?, &bias(&c.bias, c_out)?, c_out, &splits, kx * ky * kz)
        };
        let block = |b: &ConvBlock, parts: usize| -> Result<Block> { Ok([conv(&b.conv1, parts)?, conv(&b.conv2, 1)?]) };
        let up = |u: &ConvTranspose3d| -> Result<Packed> {
            let [c_in, c_out, ..] = u.weight.dims();
            Packed::transposed(&values(u.weight.val())?, &bias(&u.bias, c_out)?, c_in, c_out)
        };
        InferenceNet::new(
            self.bottleneck.conv1.weight.dims()[2],
            self.encoder.iter().map(|b| block(b, 1)).collect::<Result<_>>()?,
            self.down.iter().map(|d| conv(d, 1)).collect::<Result<_>>()?,
            block(&self.bottleneck, 1)?,
            self.up.iter().map(up).collect::<Result<_>>()?,
            self.decoder.iter().map(|b| block(b, 2)).collect::<Result<_>>()?,
            conv(&self.head, 1)?,
        )
    }

    /// The layers, for the hand-written backward pass of [`crate::net::backprop`].
    pub(crate) fn layers(&self) -> Layers<'_> {
        fn block(b: &ConvBlock) -> [&Conv3d; 2] {
            [&b.conv1, &b.conv2]
        }
        Layers {
            encoder: self.encoder.iter().map(block).collect(),
            down: self.down.iter().collect(),
            bottleneck: block(&self.bottleneck),
            up: self.up.iter().collect(),
            decoder: self.decoder.iter().map(block).collect(),
            head: &self.head,
        }
    }

    /// Stops gradient updates of the contracting path (encoder levels, down-sampling, bottleneck).
    pub fn freeze_encoder(mut self) -> Self {
        self.encoder = self.encoder.no_grad();
        self.down = self.down.no_grad();
        self.bottleneck = self.bottleneck.no_grad();
        self
    }

    /// Whether a parameter path (as in [`named_parameters`](Self::named_parameters)) belongs to
    /// the contracting path.
    pub fn is_encoder_parameter(path: &str) -> bool {
        ENCODER_PREFIXES.iter().any(|p| path.starts_with(p))
    }

    /// Every parameter with its path (`encoder.0.conv1.weight`, ...) and values, in module order.
    pub fn named_parameters(&self) -> Vec<(String, Vec<f32>)> {
        let mut collector = NamedCollector { path: Vec::new(), out: Vec::new() };
        self.visit(&mut collector);
        collector.out
    }

    /// Serializes the weights to safetensors bytes (deterministic: the same weights give the
    /// same bytes).
    pub fn to_safetensors(&self) -> Result<Vec<u8>> {
        // One metadata entry only: burn's default metadata is a HashMap whose serialized order
        // varies between runs.
        let mut store = SafetensorsStore::from_bytes(None).clear_metadata().metadata("format", "safetensors");
        self.save_into(&mut store)
            .map_err(|e| LearnError::InvalidInput(format!("cannot serialize weights to safetensors: {e}")))?;
        store.get_bytes().map_err(|e| LearnError::InvalidInput(format!("cannot serialize weights to safetensors: {e}")))
    }

    /// Builds a network of `config` on `device` and loads safetensors weights into it; `path`
    /// only names the source in errors.
    pub fn from_safetensors(config: &UNetConfig, bytes: Vec<u8>, device: &Device, path: &Path) -> Result<UNet> {
        let mut net = UNet::new(config, device, 0)?;
        let mut store = SafetensorsStore::from_bytes(Some(bytes));
        let result = net
            .load_from(&mut store)
            .map_err(|e| LearnError::model(path, format!("cannot load weights for {config:?}: {e}")))?;
        if !result.errors.is_empty() || !result.missing.is_empty() || !result.unused.is_empty() {
            return Err(LearnError::model(path, format!("weights do not fit the configuration {config:?}: {result}")));
        }
        Ok(net)
    }

    /// A copy of this network (of `config`) on `device`, e.g. from the CPU to a GPU or back; `source` only names
    /// where the weights came from in errors.
    pub fn copied_to(&self, config: &UNetConfig, device: &Device, source: &Path) -> Result<UNet> {
        UNet::from_safetensors(config, self.to_safetensors()?, device, source)
    }
}

/// Draws He-uniform weights and zero biases from a seeded generator.
struct SeededInit {
    rng: StdRng,
    fan_in: usize,
}

impl ModuleMapper for SeededInit {
    fn map_float<const D: usize>(&mut self, param: Param<Tensor<D>>) -> Param<Tensor<D>> {
        let shape = param.lazy_shape();
        let dims = shape.clone().dims::<D>();
        let count: usize = dims.iter().product();
        let values: Vec<f32> = if D >= 3 {
            // Weights: [c_out, c_in, k...] (conv) or [c_in, c_out, k...] (transposed): fan-in
            // from dimension 1 times the kernel volume, as PyTorch does.
            self.fan_in = dims[1] * dims[2..].iter().product::<usize>();
            let bound = (6.0 / self.fan_in as f64).sqrt();
            (0..count).map(|_| self.rng.random_range(-bound..bound) as f32).collect()
        } else {
            vec![0.0; count]
        };
        param.map(|old| {
            let require_grad = old.is_require_grad();
            let t = Tensor::<D>::from_data(TensorData::new(values, shape), &old.device());
            if require_grad {
                t.require_grad()
            } else {
                t
            }
        })
    }
}

/// Collects parameter paths and values.
struct NamedCollector {
    path: Vec<String>,
    out: Vec<(String, Vec<f32>)>,
}

impl ModuleVisitor for NamedCollector {
    fn enter_module(&mut self, name: &str, _container_type: &str) {
        self.path.push(name.to_string());
    }

    fn exit_module(&mut self, _name: &str, _container_type: &str) {
        self.path.pop();
    }

    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        let values = param.val().into_data().try_into_vec_as::<f32>().unwrap_or_default();
        self.out.push((self.path.join("."), values));
    }
}

/// Summary of the training run that produced a model.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TrainingInfo {
    /// Iterations run.
    pub iterations: usize,
    /// Iteration whose weights were kept (best validation error; the last one without
    /// validation samples).
    pub best_iteration: usize,
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
    input_unit: String,
    target_unit: String,
    weights: String,
    training: Option<TrainingInfo>,
}

const MODEL_FORMAT: &str = "augsim-unet";
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
    /// Input unit ("N" or "m").
    pub input_unit: String,
    /// Target unit ("m").
    pub target_unit: String,
    /// How it was trained.
    pub training: Option<TrainingInfo>,
    /// The network (on the inference device).
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
        write_atomic_bytes(&weights_path, &self.net.to_safetensors()?)?;
        let file = ModelFile {
            format: MODEL_FORMAT.into(),
            version: MODEL_VERSION,
            layout: LAYOUT.into(),
            unet: self.config.clone(),
            normalization: self.normalization,
            grid: self.grid,
            placement: self.placement,
            input_unit: self.input_unit.clone(),
            target_unit: self.target_unit.clone(),
            weights: weights_name,
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

    /// Fails when `samples` include samples this model (or a model it was fine-tuned from) was
    /// trained or validated on; models without a recorded split pass.
    pub fn check_unseen(&self, samples: &Samples) -> Result<()> {
        self.provenance().map_or(Ok(()), |p| p.check_unseen(samples))
    }

    /// Whether `samples` come from the data this model's own run was trained on (then its
    /// recorded test split is what [`held_out`](Self::held_out) gives).
    pub fn trained_on(&self, samples: &Samples) -> bool {
        self.provenance().is_some_and(|p| p.trained_on(samples))
    }

    /// What sample `index` of the data source `source` was to this model ([`Provenance::role`]).
    pub fn role(&self, source: Option<&str>, index: u64) -> SampleRole {
        self.provenance().map_or(SampleRole::Unseen, |p| p.role(source, index))
    }

    /// The samples of `samples` held out from this model ([`Provenance::held_out`]; all of
    /// them for a model without a recorded split).
    pub fn held_out(&self, samples: &Samples) -> Result<Samples> {
        self.provenance().map_or_else(|| Ok(samples.clone()), |p| p.held_out(samples))
    }

    /// The model JSON of `path`: `path/model.json` for a model directory, else `path` itself.
    pub fn json_path(path: &Path) -> PathBuf {
        if path.is_dir() {
            path.join("model.json")
        } else {
            path.to_path_buf()
        }
    }

    /// Loads a model saved by [`save`](Self::save) onto `device`.
    pub fn load(json_path: &Path, device: &Device) -> Result<TrainedModel> {
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
        let weights_path = weights_path(json_path, &file.weights)?;
        let bytes = read(&weights_path)?;
        let net = UNet::from_safetensors(&file.unet, bytes, device, &weights_path)?;
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

/// The layers of a [`UNet`] (from `UNet::layers`), in the order of its fields, for the
/// hand-written backward pass of [`crate::net::backprop`].
pub(crate) struct Layers<'a> {
    /// The two convolutions of each encoder level.
    pub(crate) encoder: Vec<[&'a Conv3d; 2]>,
    /// The stride-2 down-sampling convolutions.
    pub(crate) down: Vec<&'a Conv3d>,
    /// The bottleneck's two convolutions.
    pub(crate) bottleneck: [&'a Conv3d; 2],
    /// The stride-2 transposed (up-sampling) convolutions.
    pub(crate) up: Vec<&'a ConvTranspose3d>,
    /// The two convolutions of each decoder level.
    pub(crate) decoder: Vec<[&'a Conv3d; 2]>,
    /// The 1×1×1 output convolution.
    pub(crate) head: &'a Conv3d,
}
