//! Training gradients without autodiff: a forward pass that keeps the activations and a
//! hand-written backward pass, both on the repacked CPU engine of [`crate::inference`].
//!
//! [`loss_and_gradients`] returns the masked MSE loss ([`masked_mse`](crate::metrics::masked_mse))
//! of [`UNet::forward`] on a batch and the gradient of every trainable parameter, registered
//! under the network's parameter ids, so that burn's optimiser takes them unchanged
//! (`optim.step(lr, net, grads)`): checkpoints and Adam state are those of the autodiff path.
//!
//! Per layer, with activations channels-last and zero halos as in inference:
//! - stride-1 convolution: the output gradient is zeroed where the (post-ReLU) output is not
//!   positive (not for the head); the input gradient is the same kind of convolution of it with
//!   the flipped, channel-transposed weights ([`same_conv`]); the weight gradient of (x, y) tap
//!   offset `(a, b)` is, per x-plane, the transposed strided input view of the forward pass times
//!   the gradient plane; the bias gradient is the gradient summed over nodes;
//! - 2×2×2 stride-2 convolution: its input gradient is the transposed convolution with the same
//!   weight array ([`upsample`]), and the transposed convolution's input gradient is the stride-2
//!   convolution with the same weight array ([`downsample`]); both weight gradients are sums of
//!   gathered 2×2×2 patches (transposed) times coarse planes.
//!
//! Samples run in parallel (rayon), each with its own gradient accumulators, summed at the end.
//! Parameters that do not require gradients (a frozen encoder) get none, and when no parameter
//! of the contracting path requires one, its backward pass is skipped.

use burn::module::{Param, ParamId};
use burn::nn::conv::{Conv3d, ConvTranspose3d};
use burn::optim::GradientsParams;
use burn::tensor::{Device, Tensor, TensorData};
use faer::linalg::matmul::matmul;
use faer::{Accum, MatMut, MatRef, Par};
use rayon::prelude::*;

use crate::grid::GridShape;
use crate::inference::{
    conv_order, downsample, gather_patches, gather_plane, same_conv, tap_offsets, tap_view, upsample, Packed, Volume,
};
use crate::unet::UNet;
use crate::{LearnError, Result};

/// The layers of a [`UNet`] (from `UNet::layers`), in the order of its fields.
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

/// The masked MSE loss of `net` on a batch and the gradients of its trainable parameters.
///
/// `inputs` is `[batch, in_channels, nx, ny, nz]`, `targets` `[batch, out_channels, nx, ny, nz]`
/// and `masks` `[batch, 1, nx, ny, nz]` (weights, 0/1 in training), all in the grid layout,
/// normalised as the network expects (as `train`'s batches are). The loss is
/// [`masked_mse`](crate::metrics::masked_mse) of [`UNet::forward`]; the gradients equal burn's
/// autodiff ones up to summation order, and are registered under the parameter ids of `net`
/// (which must be on the training device, where its parameters require gradients) for
/// [`ModuleOptimizer::step`](burn::optim::ModuleOptimizer::step). Parameters that do not
/// require gradients (see [`UNet::freeze_encoder`]) are left out.
pub fn loss_and_gradients(
    net: &UNet,
    inputs: &[f32],
    targets: &[f32],
    masks: &[f32],
    batch: usize,
    grid: GridShape,
) -> Result<(f64, GradientsParams)> {
    let prepared = Prepared::new(net)?;
    let nodes = grid.nodes();
    let (c_in, c_out) = (prepared.in_channels, prepared.head.forward.c_out);
    if batch == 0 || nodes == 0 {
        return Err(LearnError::InvalidInput(format!("gradients of an empty batch ({batch} samples on grid {grid})")));
    }
    if inputs.len() != batch * c_in * nodes || targets.len() != batch * c_out * nodes || masks.len() != batch * nodes {
        return Err(LearnError::InvalidInput(format!(
            "batch of {batch} on grid {grid}: {} inputs, {} targets, {} mask values; expected {}, {} and {}",
            inputs.len(),
            targets.len(),
            masks.len(),
            batch * c_in * nodes,
            batch * c_out * nodes,
            batch * nodes
        )));
    }
    let weight = masks.iter().map(|&m| f64::from(m)).sum::<f64>().max(1.0);
    let scale = (2.0 / weight) as f32;
    let m = 1usize << prepared.encoder.len();
    let padded = grid.dims().map(|n| n.div_ceil(m) * m);
    let halo = prepared.kernel / 2;
    let (loss, grads) = (0..batch)
        .into_par_iter()
        .map(|s| {
            let input = Volume::from_field(&inputs[s * c_in * nodes..][..c_in * nodes], c_in, grid, padded, halo);
            let activations = prepared.forward(input);
            let target = &targets[s * c_out * nodes..][..c_out * nodes];
            let (loss, d_output) =
                output_gradient(&activations.output, target, &masks[s * nodes..][..nodes], grid, scale);
            let mut grads = prepared.zero_grads();
            prepared.backward(&activations, d_output, &mut grads);
            (loss, grads)
        })
        .reduce_with(|(loss_a, mut a), (loss_b, b)| {
            for (ga, gb) in a.iter_mut().zip(&b) {
                ga.add(gb);
            }
            (loss_a + loss_b, a)
        })
        .ok_or_else(|| LearnError::InvalidInput("gradients of an empty batch".into()))?;
    Ok((loss / weight, prepared.register(grads)))
}

/// Where one layer's gradients go.
struct Slot {
    /// The weight's id, when it requires a gradient.
    weight: Option<ParamId>,
    /// burn's weight shape.
    dims: [usize; 5],
    /// The bias's id, when there is one and it requires a gradient.
    bias: Option<ParamId>,
    /// Number of biases (output channels).
    biases: usize,
    /// Position of each weight (burn's order) in the accumulated gradient.
    order: Vec<usize>,
}

/// One layer's gradient accumulators: the weights in the packed layout of the layer (see
/// [`Slot::order`]) and the biases.
struct Grad {
    weight: Vec<f32>,
    bias: Vec<f32>,
}

impl Grad {
    fn add(&mut self, other: &Grad) {
        for (a, b) in self.weight.iter_mut().chain(&mut self.bias).zip(other.weight.iter().chain(&other.bias)) {
            *a += b;
        }
    }
}

/// One layer prepared for a step.
struct Layer {
    /// Weights of the forward pass.
    forward: Packed,
    /// Weights of the input gradient: the flipped, channel-transposed convolution (stride 1),
    /// the transposed convolution (down-sampling) or the stride-2 convolution (up-sampling).
    backward: Packed,
    /// Index of its [`Slot`] and [`Grad`].
    slot: usize,
    /// Whether any of its parameters requires a gradient.
    trainable: bool,
}

/// The activations of one sample: the post-ReLU outputs double as ReLU masks.
struct Activations {
    input: Volume,
    encoder: Vec<[Volume; 2]>,
    down: Vec<Volume>,
    bottleneck: [Volume; 2],
    /// Indexed by level.
    up: Vec<Volume>,
    /// Indexed by level.
    decoder: Vec<[Volume; 2]>,
    output: Volume,
}

/// The network repacked for one step.
struct Prepared {
    kernel: usize,
    in_channels: usize,
    encoder: Vec<[Layer; 2]>,
    down: Vec<Layer>,
    bottleneck: [Layer; 2],
    up: Vec<Layer>,
    decoder: Vec<[Layer; 2]>,
    head: Layer,
    slots: Vec<Slot>,
    /// Whether a parameter of the contracting path requires a gradient.
    train_encoder: bool,
    device: Device,
}

/// Collects the slots while the layers are packed.
struct Packer {
    slots: Vec<Slot>,
}

fn values<const D: usize>(p: &Param<Tensor<D>>) -> Result<Vec<f32>> {
    p.val()
        .into_data()
        .try_into_vec_as::<f32>()
        .map_err(|e| LearnError::InvalidInput(format!("cannot read parameters: {e:?}")))
}

impl Packer {
    /// Biases (zeros without) and the slot of a layer.
    fn slot(
        &mut self,
        weight: &Param<Tensor<5>>,
        bias: &Option<Param<Tensor<1>>>,
        n: usize,
        order: Vec<usize>,
    ) -> Result<(Vec<f32>, usize, bool)> {
        let values = match bias {
            Some(b) => values(b)?,
            None => vec![0.0; n],
        };
        let slot = Slot {
            weight: weight.is_require_grad().then_some(weight.id),
            dims: weight.dims(),
            bias: bias.as_ref().filter(|b| b.is_require_grad()).map(|b| b.id),
            biases: n,
            order,
        };
        let trainable = slot.weight.is_some() || slot.bias.is_some();
        self.slots.push(slot);
        Ok((values, self.slots.len() - 1, trainable))
    }

    /// A stride-1 convolution (kernel `k³`) whose input is the concatenation of `parts` equal
    /// channel groups.
    fn same(&mut self, c: &Conv3d, parts: usize) -> Result<Layer> {
        let [c_out, c_in, kx, ky, kz] = c.weight.dims();
        if kx != ky || ky != kz || parts == 0 || c_in % parts != 0 {
            return Err(LearnError::InvalidInput(format!(
                "convolution {c_out}x{c_in}x{kx}x{ky}x{kz} of {parts} parts"
            )));
        }
        let taps = kx * ky * kz;
        let splits = vec![c_in / parts; parts];
        let weight = values(&c.weight)?;
        let (bias, slot, trainable) = self.slot(&c.weight, &c.bias, c_out, conv_order(c_out, &splits, taps))?;
        let forward = Packed::conv(&weight, &bias, c_out, &splits, taps)?;
        // `[c_in, c_out, taps]` with the taps reversed: the convolution from output to input.
        let mut flipped = vec![0.0; weight.len()];
        for co in 0..c_out {
            for ci in 0..c_in {
                for t in 0..taps {
                    flipped[(ci * c_out + co) * taps + t] = weight[(co * c_in + ci) * taps + taps - 1 - t];
                }
            }
        }
        let backward = Packed::conv(&flipped, &vec![0.0; c_in], c_in, &[c_out], taps)?;
        Ok(Layer { forward, backward, slot, trainable })
    }

    /// A 2×2×2 stride-2 convolution `[c_out, c_in, 2, 2, 2]`.
    fn down(&mut self, c: &Conv3d) -> Result<Layer> {
        let [c_out, c_in, ..] = c.weight.dims();
        let weight = values(&c.weight)?;
        let (bias, slot, trainable) = self.slot(&c.weight, &c.bias, c_out, conv_order(c_out, &[c_in], 8))?;
        let forward = Packed::conv(&weight, &bias, c_out, &[c_in], 8)?;
        let backward = Packed::transposed(&weight, &vec![0.0; c_in], c_out, c_in)?;
        Ok(Layer { forward, backward, slot, trainable })
    }

    /// A 2×2×2 stride-2 transposed convolution `[c_in, c_out, 2, 2, 2]`.
    fn up(&mut self, u: &ConvTranspose3d) -> Result<Layer> {
        let [c_in, c_out, ..] = u.weight.dims();
        let weight = values(&u.weight)?;
        let (bias, slot, trainable) = self.slot(&u.weight, &u.bias, c_out, conv_order(c_in, &[c_out], 8))?;
        let forward = Packed::transposed(&weight, &bias, c_in, c_out)?;
        let backward = Packed::conv(&weight, &vec![0.0; c_in], c_in, &[c_out], 8)?;
        Ok(Layer { forward, backward, slot, trainable })
    }

    fn block(&mut self, b: [&Conv3d; 2], parts: usize) -> Result<[Layer; 2]> {
        Ok([self.same(b[0], parts)?, self.same(b[1], 1)?])
    }
}

impl Prepared {
    fn new(net: &UNet) -> Result<Prepared> {
        let layers = net.layers();
        let mut p = Packer { slots: Vec::new() };
        let encoder = layers.encoder.iter().map(|b| p.block(*b, 1)).collect::<Result<Vec<_>>>()?;
        let down = layers.down.iter().map(|d| p.down(d)).collect::<Result<Vec<_>>>()?;
        let bottleneck = p.block(layers.bottleneck, 1)?;
        let up = layers.up.iter().map(|u| p.up(u)).collect::<Result<Vec<_>>>()?;
        let decoder = layers.decoder.iter().map(|b| p.block(*b, 2)).collect::<Result<Vec<_>>>()?;
        let head = p.same(layers.head, 1)?;
        let train_encoder = encoder.iter().flatten().chain(&down).chain(&bottleneck).any(|l| l.trainable);
        if !train_encoder && up.iter().chain(decoder.iter().flatten()).chain([&head]).all(|l| !l.trainable) {
            return Err(LearnError::InvalidInput(
                "no parameter requires a gradient (is the network on the training device?)".into(),
            ));
        }
        Ok(Prepared {
            kernel: layers.bottleneck[0].weight.dims()[2],
            in_channels: encoder.first().unwrap_or(&bottleneck)[0].forward.c_in,
            encoder,
            down,
            bottleneck,
            up,
            decoder,
            head,
            slots: p.slots,
            train_encoder,
            device: layers.head.weight.val().device(),
        })
    }

    fn zero_grads(&self) -> Vec<Grad> {
        self.slots.iter().map(|s| Grad { weight: vec![0.0; s.order.len()], bias: vec![0.0; s.biases] }).collect()
    }

    /// Two convolutions with ReLU on the channel concatenation of `inputs`.
    fn block(&self, inputs: &[&Volume], block: &[Layer; 2]) -> [Volume; 2] {
        let mid = same_conv(inputs, &block[0].forward, self.kernel, true);
        let out = same_conv(&[&mid], &block[1].forward, self.kernel, true);
        [mid, out]
    }

    /// The forward pass of one sample (as [`UNet::forward`], padded).
    fn forward(&self, input: Volume) -> Activations {
        let depth = self.encoder.len();
        let (mut encoder, mut down) = (Vec::with_capacity(depth), Vec::with_capacity(depth));
        for (block, layer) in self.encoder.iter().zip(&self.down) {
            let out = self.block(&[down.last().unwrap_or(&input)], block);
            down.push(downsample(&out[1], &layer.forward));
            encoder.push(out);
        }
        let bottleneck = self.block(&[down.last().unwrap_or(&input)], &self.bottleneck);
        let (mut up, mut decoder) = (Vec::with_capacity(depth), Vec::<[Volume; 2]>::with_capacity(depth));
        for l in (0..depth).rev() {
            let coarse = decoder.last().map_or(&bottleneck[1], |b| &b[1]);
            let upsampled = upsample(coarse, &self.up[l].forward);
            decoder.push(self.block(&[&upsampled, &encoder[l][1]], &self.decoder[l]));
            up.push(upsampled);
        }
        up.reverse();
        decoder.reverse();
        let features = decoder.first().map_or(&bottleneck[1], |b| &b[1]);
        let output = same_conv(&[features], &self.head.forward, 1, false);
        Activations { input, encoder, down, bottleneck, up, decoder, output }
    }

    /// Adds the weight and bias gradients of stride-1 convolution `layer` from its inputs and its
    /// (ReLU-masked) output gradient `dz`.
    fn same_grads(&self, layer: &Layer, inputs: &[&Volume], dz: &Volume, kernel: usize, grads: &mut [Grad]) {
        if layer.trainable {
            let g = &mut grads[layer.slot];
            add_bias_grad(dz, &mut g.bias);
            conv_weight_grad(inputs, dz, kernel, &mut g.weight);
        }
    }

    /// Adds the weight and bias gradients of a stride-2 layer: `fine` and `coarse` are its fine
    /// and coarse sides (one the input, the other the output gradient `d_out`).
    fn stride2_grads(&self, layer: &Layer, fine: &Volume, coarse: &Volume, d_out: &Volume, grads: &mut [Grad]) {
        if layer.trainable {
            let g = &mut grads[layer.slot];
            add_bias_grad(d_out, &mut g.bias);
            stride2_weight_grad(fine, coarse, &mut g.weight);
        }
    }

    /// The backward pass of one sample from the gradient of its (padded) output.
    fn backward(&self, a: &Activations, d_output: Volume, grads: &mut [Grad]) {
        let (depth, k) = (self.encoder.len(), self.kernel);
        let features = a.decoder.first().map_or(&a.bottleneck[1], |b| &b[1]);
        self.same_grads(&self.head, &[features], &d_output, 1, grads);
        let mut d = same_conv(&[&d_output], &self.head.backward, 1, false);
        // Gradients of the decoders' concatenated inputs: their skip parts join the encoder's.
        let mut d_concat = Vec::with_capacity(depth);
        for l in 0..depth {
            let ([mid, out], layers) = (&a.decoder[l], &self.decoder[l]);
            relu_mask(&mut d, out);
            self.same_grads(&layers[1], &[mid], &d, k, grads);
            d = same_conv(&[&d], &layers[1].backward, k, false);
            relu_mask(&mut d, mid);
            self.same_grads(&layers[0], &[&a.up[l], &a.encoder[l][1]], &d, k, grads);
            let concat = same_conv(&[&d], &layers[0].backward, k, false);
            let mut d_up = Volume::zeros(concat.dims, concat.halo, a.up[l].channels);
            add_channels(&mut d_up, &concat, 0);
            let coarse = a.decoder.get(l + 1).map_or(&a.bottleneck[1], |b| &b[1]);
            self.stride2_grads(&self.up[l], &d_up, coarse, &d_up, grads);
            d_concat.push(concat);
            if !self.train_encoder && l + 1 == depth {
                return;
            }
            d = downsample(&d_up, &self.up[l].backward);
        }
        if !self.train_encoder {
            return;
        }
        let [mid, out] = &a.bottleneck;
        relu_mask(&mut d, out);
        self.same_grads(&self.bottleneck[1], &[mid], &d, k, grads);
        d = same_conv(&[&d], &self.bottleneck[1].backward, k, false);
        relu_mask(&mut d, mid);
        self.same_grads(&self.bottleneck[0], &[a.down.last().unwrap_or(&a.input)], &d, k, grads);
        // `d` is the output gradient of `first`, whose input gradient is still to be taken.
        let mut first = &self.bottleneck[0];
        for l in (0..depth).rev() {
            let d_down = same_conv(&[&d], &first.backward, k, false);
            let [mid, out] = &a.encoder[l];
            self.stride2_grads(&self.down[l], out, &d_down, &d_down, grads);
            let mut d_skip = upsample(&d_down, &self.down[l].backward);
            add_channels(&mut d_skip, &d_concat[l], a.up[l].channels);
            relu_mask(&mut d_skip, out);
            self.same_grads(&self.encoder[l][1], &[mid], &d_skip, k, grads);
            d = same_conv(&[&d_skip], &self.encoder[l][1].backward, k, false);
            relu_mask(&mut d, mid);
            let input = if l == 0 { &a.input } else { &a.down[l - 1] };
            self.same_grads(&self.encoder[l][0], &[input], &d, k, grads);
            first = &self.encoder[l][0];
        }
    }

    /// The summed gradients as burn tensors under the parameter ids.
    fn register(&self, grads: Vec<Grad>) -> GradientsParams {
        let mut out = GradientsParams::new();
        for (slot, g) in self.slots.iter().zip(grads) {
            if let Some(id) = slot.weight {
                let values: Vec<f32> = slot.order.iter().map(|&at| g.weight[at]).collect();
                out.register(id, Tensor::<5>::from_data(TensorData::new(values, slot.dims), &self.device).inner());
            }
            if let Some(id) = slot.bias {
                let n = g.bias.len();
                out.register(id, Tensor::<1>::from_data(TensorData::new(g.bias, [n]), &self.device).inner());
            }
        }
        out
    }
}

/// The loss terms of one sample (`Σ mask · ‖pred − target‖²`) and the gradient of the padded
/// output: `scale · mask · (pred − target)` on the grid, zero on the padding.
fn output_gradient(output: &Volume, target: &[f32], mask: &[f32], grid: GridShape, scale: f32) -> (f64, Volume) {
    let (nodes, c) = (grid.nodes(), output.channels);
    let mut d = Volume::zeros(output.dims, output.halo, c);
    let mut loss = 0.0f64;
    for (node, &m) in mask.iter().enumerate() {
        let [i, j, k] = grid.node_coords(node);
        let at = output.node(i, j, k) * c;
        for ch in 0..c {
            let diff = output.data[at + ch] - target[ch * nodes + node];
            loss += f64::from(m) * f64::from(diff) * f64::from(diff);
            d.data[at + ch] = scale * m * diff;
        }
    }
    (loss, d)
}

/// Zeroes the gradient where the post-ReLU output `y` is not positive.
fn relu_mask(d: &mut Volume, y: &Volume) {
    for (g, v) in d.data.iter_mut().zip(&y.data) {
        if *v <= 0.0 {
            *g = 0.0;
        }
    }
}

/// Adds the gradient summed over nodes (halo nodes hold zeros).
fn add_bias_grad(d: &Volume, bias: &mut [f32]) {
    for node in d.data.chunks_exact(d.channels) {
        for (b, v) in bias.iter_mut().zip(node) {
            *b += v;
        }
    }
}

/// Adds channels `from .. from + dst.channels` of `src` to `dst` (same grid and halo).
fn add_channels(dst: &mut Volume, src: &Volume, from: usize) {
    let c = dst.channels;
    for (d, s) in dst.data.chunks_exact_mut(c).zip(src.data.chunks_exact(src.channels)) {
        for (a, b) in d.iter_mut().zip(&s[from..from + c]) {
            *a += b;
        }
    }
}

/// Adds the weight gradient of a stride-1 convolution (`kernel³`, zero padding) of the channel
/// concatenation of `inputs` with output gradient `dz` to `grad`, laid out as the concatenation
/// of the part matrices of [`Packed::conv`]: per x-plane and (x, y) tap offset, the transposed
/// strided input view of [`same_conv`] times the gradient plane (its halo rows are zero).
fn conv_weight_grad(inputs: &[&Volume], dz: &Volume, kernel: usize, grad: &mut [f32]) {
    let c_out = dz.channels;
    let offsets = tap_offsets(dz, kernel);
    let rows = dz.plane_rows();
    let plane = dz.plane_nodes();
    let corner = dz.node(0, 0, 0);
    for i in 0..dz.dims[0] {
        let base = corner + i * plane;
        let rhs = MatRef::from_row_major_slice(&dz.data[base * c_out..(base + rows) * c_out], rows, c_out);
        let mut part = 0;
        for v in inputs {
            let block = kernel * v.channels * c_out;
            for (ab, off) in offsets.iter().enumerate() {
                let lhs = tap_view(v, (base as isize + off) as usize, rows, kernel);
                let dst = MatMut::from_row_major_slice_mut(
                    &mut grad[part + ab * block..][..block],
                    kernel * v.channels,
                    c_out,
                );
                matmul(dst, Accum::Add, lhs.transpose(), rhs, 1.0f32, Par::Seq);
            }
            part += kernel * kernel * block;
        }
    }
}

/// Adds `Σ_planes patches(fine)ᵀ · plane(coarse)` to `grad` (`8 · fine.channels ×
/// coarse.channels`, row-major): the weight gradient of a 2×2×2 stride-2 convolution from input
/// `fine` with output gradient `coarse` in the layout of [`Packed::conv`], and equally that of a
/// transposed convolution from input `coarse` with output gradient `fine`, laid out as the
/// convolution with the same weight array.
fn stride2_weight_grad(fine: &Volume, coarse: &Volume, grad: &mut [f32]) {
    let rows = coarse.dims[1] * coarse.dims[2];
    let (k_len, c) = (8 * fine.channels, coarse.channels);
    let (mut patches, mut plane) = (vec![0.0; rows * k_len], vec![0.0; rows * c]);
    for i in 0..coarse.dims[0] {
        gather_patches(fine, i, &mut patches);
        gather_plane(coarse, i, &mut plane);
        let dst = MatMut::from_row_major_slice_mut(grad, k_len, c);
        let lhs = MatRef::from_row_major_slice(&patches, rows, k_len);
        matmul(dst, Accum::Add, lhs.transpose(), MatRef::from_row_major_slice(&plane, rows, c), 1.0f32, Par::Seq);
    }
}
