//! burn's U-Net (the `cpu-burn` feature): the layers of [`UNetConfig::layers`](crate::UNetConfig)
//! as burn modules, with the parameters of a [`UNet`], on the CPU (`flex`) or a GPU, with
//! autodiff for training. It runs [`Compute::CpuBurn`](crate::Compute) and
//! [`Compute::Gpu`](crate::Compute); the parameters stay in the [`UNet`], and this network is
//! built from them where it runs.

use burn::module::{Module, ModuleMapper, ModuleVisitor, Param};
use burn::nn::conv::{Conv3d, Conv3dConfig, ConvTranspose3d, ConvTranspose3dConfig};
use burn::nn::{Initializer, PaddingConfig3d};
use burn::optim::GradientsParams;
use burn::tensor::activation::relu;
use burn::tensor::ops::PadMode;
use burn::tensor::{Device, Tensor, TensorData};

use crate::data::grid::GridShape;
use crate::net::unet::{Gradients, LayerKind, LayerParams, Levels, UNet};
use crate::{LearnError, Result};

/// Masked MSE loss of a batch: `pred`, `target` `[B, 3, nx, ny, nz]`, `mask` `[B, 1, nx, ny, nz]`
/// (0/1), as burn tensors (on arrays: [`masked_mse_values`](crate::training::metrics::masked_mse_values)).
/// Returns a one-element tensor; zero when the mask is empty.
pub fn masked_mse(pred: Tensor<5>, target: Tensor<5>, mask: Tensor<5>) -> Tensor<1> {
    let diff = pred - target;
    let squared_norm = diff.clone().mul(diff).sum_dim(1);
    let total = squared_norm.mul(mask.clone()).sum();
    let nodes = mask.sum().clamp_min(1.0);
    total.div(nodes)
}

/// Two convolutions with ReLU.
#[derive(Module, Debug)]
struct ConvBlock {
    conv1: Conv3d,
    conv2: Conv3d,
}

impl ConvBlock {
    fn forward(&self, x: Tensor<5>) -> Tensor<5> {
        relu(self.conv2.forward(relu(self.conv1.forward(x))))
    }
}

/// The U-Net as burn modules (see the module documentation); its parameter paths are those of
/// [`UNet::named_parameters`].
#[derive(Module, Debug)]
pub struct BurnUNet {
    encoder: Vec<ConvBlock>,
    down: Vec<Conv3d>,
    bottleneck: ConvBlock,
    up: Vec<ConvTranspose3d>,
    decoder: Vec<ConvBlock>,
    head: Conv3d,
}

/// The values of a float tensor, read back from its device.
pub(crate) fn tensor_values<const D: usize>(t: Tensor<D>) -> Result<Vec<f32>> {
    t.into_data().try_into_vec_as::<f32>().map_err(|e| LearnError::InvalidInput(format!("cannot read a tensor: {e:?}")))
}

impl BurnUNet {
    /// The network of `net` on `device`: on an autodiff device its trained parameters require
    /// gradients (not those of a frozen encoder).
    pub fn new(net: &UNet, device: &Device) -> Result<BurnUNet> {
        let levels = net.levels()?;
        let conv = |p: &LayerParams| {
            let (c_in, c_out) = (p.layer.c_in, p.layer.c_out);
            let config = match p.layer.kind {
                LayerKind::Conv { kernel: k, .. } => Conv3dConfig::new([c_in, c_out], [k, k, k])
                    .with_padding(PaddingConfig3d::Explicit(k / 2, k / 2, k / 2)),
                LayerKind::Down | LayerKind::Up => Conv3dConfig::new([c_in, c_out], [2, 2, 2]).with_stride([2, 2, 2]),
            };
            config.with_initializer(Initializer::Zeros).init(device)
        };
        let block = |b: &[LayerParams; 2]| ConvBlock { conv1: conv(&b[0]), conv2: conv(&b[1]) };
        let up = |p: &LayerParams| {
            ConvTranspose3dConfig::new([p.layer.c_in, p.layer.c_out], [2, 2, 2])
                .with_stride([2, 2, 2])
                .with_initializer(Initializer::Zeros)
                .init(device)
        };
        let Levels { encoder, down, bottleneck, up: ups, decoder, head } = &levels;
        let mut burn = BurnUNet {
            encoder: encoder.iter().map(block).collect(),
            down: down.iter().map(conv).collect(),
            bottleneck: block(bottleneck),
            up: ups.iter().map(up).collect(),
            decoder: decoder.iter().map(block).collect(),
            head: conv(head),
        }
        .map(&mut Load { values: net.values().iter() });
        if net.frozen_encoder() {
            burn.encoder = burn.encoder.no_grad();
            burn.down = burn.down.no_grad();
            burn.bottleneck = burn.bottleneck.no_grad();
        }
        Ok(burn)
    }

    /// Runs the network on a batch `[batch, in_channels, nx, ny, nz]` (any grid size; padded
    /// internally) and returns `[batch, out_channels, nx, ny, nz]`.
    pub fn forward(&self, x: Tensor<5>) -> Tensor<5> {
        let [batch, _, nx, ny, nz] = x.dims();
        let m = 1usize << self.encoder.len();
        let pad = |n: usize| n.div_ceil(m) * m - n;
        let (px, py, pz) = (pad(nx), pad(ny), pad(nz));
        let mut h = if px + py + pz > 0 { x.pad([(0, px), (0, py), (0, pz)], PadMode::Constant(0.0)) } else { x };
        let mut skips = Vec::with_capacity(self.encoder.len());
        for (block, down) in self.encoder.iter().zip(&self.down) {
            h = block.forward(h);
            skips.push(h.clone());
            h = down.forward(h);
        }
        h = self.bottleneck.forward(h);
        for l in (0..self.encoder.len()).rev() {
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

    /// The masked MSE loss ([`masked_mse`]) on a batch and its gradients by burn's autodiff, the
    /// network being on the autodiff `device`; the batch is as for
    /// [`loss_and_gradients`](crate::net::backprop::loss_and_gradients).
    pub fn loss_and_gradients(
        &self,
        inputs: &[f32],
        targets: &[f32],
        masks: &[f32],
        batch: usize,
        grid: GridShape,
        device: &Device,
    ) -> Result<(f64, Gradients)> {
        let [nx, ny, nz] = grid.dims();
        let tensor = |values: &[f32]| -> Result<Tensor<5>> {
            let channels = values.len() / (batch * grid.nodes()).max(1);
            if batch == 0 || values.len() != batch * channels * grid.nodes() {
                return Err(LearnError::InvalidInput(format!(
                    "{} batch values do not fill {batch} samples on grid {grid}",
                    values.len()
                )));
            }
            Ok(Tensor::<5>::from_data(TensorData::new(values.to_vec(), [batch, channels, nx, ny, nz]), device))
        };
        let loss = masked_mse(self.forward(tensor(inputs)?), tensor(targets)?, tensor(masks)?);
        let value = tensor_values(loss.clone())?.first().copied().unwrap_or(f32::NAN);
        let grads = GradientsParams::from_grads(loss.backward(), self);
        let mut collect = Collect { grads: &grads, out: Vec::new() };
        self.visit(&mut collect);
        Ok((f64::from(value), Gradients(collect.out.into_iter().collect::<Result<_>>()?)))
    }

    /// Every parameter with its path and values, in module order (that of
    /// [`UNet::named_parameters`]).
    pub fn named_parameters(&self) -> Vec<(String, Vec<f32>)> {
        let mut collector = Named { path: Vec::new(), out: Vec::new() };
        self.visit(&mut collector);
        collector.out
    }
}

/// Replaces the parameters, in module order, by the values of a [`UNet`] (same order and shapes,
/// both built from the same layers).
struct Load<'a> {
    values: std::slice::Iter<'a, Vec<f32>>,
}

impl ModuleMapper for Load<'_> {
    fn map_float<const D: usize>(&mut self, param: Param<Tensor<D>>) -> Param<Tensor<D>> {
        let shape = param.lazy_shape();
        let values = self.values.next().cloned().unwrap_or_default();
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

/// Reads the gradient of every parameter, in module order.
struct Collect<'a> {
    grads: &'a GradientsParams,
    out: Vec<Result<Option<Vec<f32>>>>,
}

impl ModuleVisitor for Collect<'_> {
    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        self.out.push(self.grads.get::<D>(param.id).map(tensor_values).transpose());
    }
}

/// Collects parameter paths and values.
struct Named {
    path: Vec<String>,
    out: Vec<(String, Vec<f32>)>,
}

impl ModuleVisitor for Named {
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
