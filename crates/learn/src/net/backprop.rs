//! Training gradients without autodiff: a forward pass that keeps the activations and a
//! hand-written backward pass, both on the repacked CPU engine of [`crate::net::inference`].
//!
//! [`loss_and_gradients`] returns the masked MSE loss
//! ([`masked_mse_values`](crate::training::metrics::masked_mse_values)) of the network on a batch
//! and the gradient of every trainable parameter, in the network's parameter order, for
//! [`Adam::step`](crate::training::adam::Adam::step). They equal those of burn's autodiff (the
//! `cpu-burn` feature's engine) up to summation order.
//!
//! Per layer, with activations channels-last and zero halos as in inference:
//! - stride-1 convolution: the output gradient is zeroed where the (post-ReLU) output is not
//!   positive (not for the head); the input gradient is the same kind of convolution of it with
//!   the flipped, channel-transposed weights (`same_conv`); the weight gradient of (x, y) tap
//!   offset `(a, b)` is, per x-plane, the transposed strided input view of the forward pass times
//!   the gradient plane; the bias gradient is the gradient summed over nodes;
//! - 2×2×2 stride-2 convolution: its input gradient is the transposed convolution with the same
//!   weight array (`upsample`), and the transposed convolution's input gradient is the stride-2
//!   convolution with the same weight array (`downsample`); both weight gradients are sums of
//!   gathered 2×2×2 patches (transposed) times coarse planes.
//!
//! Where the CPU has AVX-512 and a layer's output channels are a multiple of 8, the stride-1
//! convolutions (forward and input gradient) and their weight gradients run as register-blocked
//! SIMD loops instead of faer GEMMs: channels-last rows of the convolution views are broadcast
//! into fused multiply-adds with vectors of 8 or 16 output channels (see `simd`); the ReLU mask
//! of the layer below is applied as the input gradient is stored. (The AVX-512 intrinsics are
//! stable since Rust 1.89.) Where all channel counts are multiples of 16 and the volume has at
//! least 16 tiles of 2×2×2 nodes per x-plane pair, the 3×3×3 convolutions and weight gradients
//! take the Winograd F(2³, 3³) loops of the `winograd` module instead: 64 products per tile and
//! channel pair instead of 216.
//!
//! Samples run in parallel (rayon) in fixed groups, one gradient accumulator per group, the
//! groups summed in order (the same bits on any number of threads); volumes are recycled through
//! a small per-thread pool of buffers, since fresh allocations of their size cost page faults at
//! every step. Parameters that are not trained (a frozen encoder) get no gradient, and then the
//! backward pass of the contracting path is skipped.

use std::cell::RefCell;

use faer::linalg::matmul::matmul;
use faer::{Accum, MatMut, MatRef, Par};
use rayon::prelude::*;

use crate::data::grid::GridShape;
use crate::net::inference::{
    conv_layout, downsample, gather_patches, gather_plane, same_conv, tap_offsets, tap_view, upsample, Packed, Volume,
};
use crate::net::lanes::{has_avx512, vectorised};
use crate::net::unet::{Gradients, LayerKind, LayerParams, Levels, UNet};
use crate::net::winograd::{self, Winograd};
use crate::{LearnError, Result};

/// Samples of a batch whose gradients one accumulator sums before the accumulators are added:
/// the batch's samples run in parallel in groups of this many (two threads on the default batch
/// of 4).
const SAMPLES_PER_ACCUMULATOR: usize = 2;

/// The masked MSE loss of `net` on a batch and the gradients of its trainable parameters.
///
/// `inputs` is `[batch, in_channels, nx, ny, nz]`, `targets` `[batch, out_channels, nx, ny, nz]`
/// and `masks` `[batch, 1, nx, ny, nz]` (weights, 0/1 in training), all in the grid layout,
/// normalised as the network expects (as `train`'s batches are). The loss is the mask-weighted
/// mean over nodes of the squared error norm (as
/// [`masked_mse_values`](crate::training::metrics::masked_mse_values)); parameters that are not
/// trained (see [`UNet::freeze_encoder`]) get no gradient.
pub fn loss_and_gradients(
    net: &UNet,
    inputs: &[f32],
    targets: &[f32],
    masks: &[f32],
    batch: usize,
    grid: GridShape,
) -> Result<(f64, Gradients)> {
    let prepared = Prepared::new(net, grid)?;
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
    let padded = prepared.padded;
    let halo = prepared.kernel / 2;
    // One gradient accumulator per fixed group of samples, the groups summed in order: the
    // same sums in the same order on any number of threads, so that a seed trains the same
    // network on any machine with the same instruction set.
    let groups: Vec<(f64, Vec<Grad>)> = (0..batch.div_ceil(SAMPLES_PER_ACCUMULATOR))
        .into_par_iter()
        .map(|g| {
            let mut grads = prepared.zero_grads();
            let mut loss = 0.0;
            for s in g * SAMPLES_PER_ACCUMULATOR..((g + 1) * SAMPLES_PER_ACCUMULATOR).min(batch) {
                let input = Volume::from_field(&inputs[s * c_in * nodes..][..c_in * nodes], c_in, grid, padded, halo);
                let activations = prepared.forward(input);
                let target = &targets[s * c_out * nodes..][..c_out * nodes];
                let (sample_loss, d_output) =
                    output_gradient(&activations.output, target, &masks[s * nodes..][..nodes], grid, scale);
                let spent = prepared.backward(&activations, d_output, &mut grads);
                recycle(spent.into_iter().chain(activations.into_volumes()));
                loss += sample_loss;
            }
            (loss, grads)
        })
        .collect();
    let (loss, grads) = groups
        .into_iter()
        .reduce(|(loss_a, mut a), (loss_b, b)| {
            vectorised(|| {
                for (ga, gb) in a.iter_mut().zip(&b) {
                    ga.add(gb);
                }
            });
            (loss_a + loss_b, a)
        })
        .ok_or_else(|| LearnError::InvalidInput("gradients of an empty batch".into()))?;
    Ok((loss / weight, prepared.gradients(grads)))
}

/// Where one layer's gradients go.
struct Slot {
    /// Whether its parameters are trained.
    trainable: bool,
    /// The weight's shape.
    dims: [usize; 5],
    /// Number of biases (output channels).
    biases: usize,
    /// The layout of the accumulated weight gradient: that of [`conv_layout`] with these
    /// output channels, input channel parts and taps.
    layout: (usize, Vec<usize>, usize),
}

/// One layer's gradient accumulators: the weights in the packed layout of the layer (see
/// [`Slot::layout`]) and the biases.
struct Grad {
    weight: Vec<f32>,
    bias: Vec<f32>,
}

impl Grad {
    #[inline(always)]
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
    /// The Winograd transforms of `forward` and `backward`, where those loops take them (see
    /// [`crate::net::winograd`]).
    winograd: [Option<Winograd>; 2],
    /// Index of its [`Slot`] and [`Grad`].
    slot: usize,
    /// Whether its parameters are trained.
    trainable: bool,
}

impl Layer {
    /// The stride-1 convolution with ReLU of the channel concatenation of `inputs`.
    fn forward_conv(&self, inputs: &[&Volume], kernel: usize) -> Volume {
        conv(inputs, &self.forward, self.winograd[0].as_ref(), kernel, true, None)
    }

    /// The input gradient of a stride-1 convolution from its output gradient `d`, zeroed where
    /// `mask` (the ReLU output of the layer below) is not positive.
    fn input_gradient(&self, d: &Volume, kernel: usize, mask: Option<&Volume>) -> Volume {
        conv(&[d], &self.backward, self.winograd[1].as_ref(), kernel, false, mask)
    }
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

impl Activations {
    /// All the volumes.
    fn into_volumes(self) -> impl Iterator<Item = Volume> {
        let levels = self.encoder.into_iter().chain([self.bottleneck]).chain(self.decoder).flatten();
        levels.chain(self.down).chain(self.up).chain([self.input, self.output])
    }
}

thread_local! {
    /// Storage of volumes this thread used before, for reuse: fresh allocations of this size
    /// cost page faults.
    static POOL: RefCell<Vec<Vec<f32>>> = const { RefCell::new(Vec::new()) };
}

/// The most buffers a thread's pool keeps.
const POOL_SIZE: usize = 96;

/// A zero volume stored in the smallest large enough buffer of this thread's pool, if any.
fn pooled(dims: [usize; 3], halo: usize, channels: usize) -> Volume {
    let len = dims.iter().map(|d| d + 2 * halo).product::<usize>() * channels;
    let data = POOL.with_borrow_mut(|pool| {
        let best = pool.iter().enumerate().filter(|(_, b)| b.capacity() >= len).min_by_key(|(_, b)| b.capacity());
        best.map(|(i, _)| i).map(|i| pool.swap_remove(i))
    });
    Volume::zeros_in(data.unwrap_or_default(), dims, halo, channels)
}

/// Gives the storage of `volumes` to this thread's pool.
fn recycle(volumes: impl IntoIterator<Item = Volume>) {
    POOL.with_borrow_mut(|pool| {
        for v in volumes {
            if pool.len() < POOL_SIZE {
                pool.push(v.data);
            }
        }
    });
}

/// The network repacked for one step.
struct Prepared {
    kernel: usize,
    in_channels: usize,
    /// The grid padded to a multiple of `2^depth` nodes along each axis.
    padded: [usize; 3],
    encoder: Vec<[Layer; 2]>,
    down: Vec<Layer>,
    bottleneck: [Layer; 2],
    up: Vec<Layer>,
    decoder: Vec<[Layer; 2]>,
    head: Layer,
    slots: Vec<Slot>,
    /// Whether a parameter of the contracting path is trained.
    train_encoder: bool,
}

/// Packs layer `p` (on volumes of `dims` interior nodes, for a stride-1 convolution) and
/// describes its gradients.
fn prepare(p: &LayerParams, dims: [usize; 3]) -> Result<(Layer, Slot)> {
    let shape = p.layer.weight_shape();
    let (weight, bias) = (p.weight, p.bias);
    let (forward, backward, layout) = match p.layer.kind {
        LayerKind::Conv { parts, .. } => {
            let [c_out, c_in, kx, ky, kz] = shape;
            let taps = kx * ky * kz;
            let splits = vec![c_in / parts; parts];
            // `[c_in, c_out, taps]` with the taps reversed: the convolution from output to input.
            let mut flipped = vec![0.0; weight.len()];
            for (ci, flipped) in flipped.chunks_exact_mut(c_out * taps).enumerate() {
                for (co, flipped) in flipped.chunks_exact_mut(taps).enumerate() {
                    let w = &weight[(co * c_in + ci) * taps..][..taps];
                    for (f, w) in flipped.iter_mut().zip(w.iter().rev()) {
                        *f = *w;
                    }
                }
            }
            (
                Packed::conv(weight, bias, c_out, &splits, taps)?,
                Packed::conv(&flipped, &vec![0.0; c_in], c_in, &[c_out], taps)?,
                (c_out, splits, taps),
            )
        }
        LayerKind::Down => {
            let [c_out, c_in, ..] = shape;
            (
                Packed::conv(weight, bias, c_out, &[c_in], 8)?,
                Packed::transposed(weight, &vec![0.0; c_in], c_out, c_in)?,
                (c_out, vec![c_in], 8),
            )
        }
        LayerKind::Up => {
            let [c_in, c_out, ..] = shape;
            (
                Packed::transposed(weight, bias, c_in, c_out)?,
                Packed::conv(weight, &vec![0.0; c_in], c_in, &[c_out], 8)?,
                (c_in, vec![c_out], 8),
            )
        }
    };
    let slot = Slot { trainable: p.trainable, dims: shape, biases: p.layer.c_out, layout };
    // The Winograd transforms where the loops pay on the layer's volumes (see `conv`).
    let fast = matches!(p.layer.kind, LayerKind::Conv { .. }) && has_avx512() && winograd::tiles_pay(dims);
    let transform = |p: &Packed| (fast && p.taps == 27).then(|| Winograd::new(&p.parts, p.c_out)).flatten();
    let winograd = [transform(&forward), transform(&backward)];
    Ok((Layer { forward, backward, winograd, slot: p.index, trainable: p.trainable }, slot))
}

impl Prepared {
    /// Packs every layer (in parallel) for inputs on `grid`.
    fn new(net: &UNet, grid: GridShape) -> Result<Prepared> {
        let levels = net.levels()?;
        let depth = net.depth();
        let m = 1usize << depth;
        let padded = grid.dims().map(|n| n.div_ceil(m) * m);
        let level = |l: usize| padded.map(|n| n >> l);
        // Each layer with the size of its volumes, in layer order.
        let mut specs = Vec::new();
        for (l, b) in levels.encoder.iter().enumerate() {
            specs.extend(b.iter().map(|p| (p, level(l))));
        }
        specs.extend(levels.down.iter().enumerate().map(|(l, p)| (p, level(l))));
        specs.extend(levels.bottleneck.iter().map(|p| (p, level(depth))));
        specs.extend(levels.up.iter().enumerate().map(|(l, p)| (p, level(l))));
        for (l, b) in levels.decoder.iter().enumerate() {
            specs.extend(b.iter().map(|p| (p, level(l))));
        }
        specs.push((&levels.head, padded));
        let prepared = specs.into_par_iter().map(|(p, dims)| prepare(p, dims)).collect::<Result<Vec<_>>>()?;
        let (built, slots): (Vec<Layer>, Vec<Slot>) = prepared.into_iter().unzip();
        let Levels { encoder, down, bottleneck, up, decoder, head } = Levels::new(depth, built)?;
        let train_encoder = encoder.iter().flatten().chain(&down).chain(&bottleneck).any(|l| l.trainable);
        Ok(Prepared {
            kernel: net.config().kernel_size,
            padded,
            in_channels: net.config().in_channels,
            encoder,
            down,
            bottleneck,
            up,
            decoder,
            head,
            slots,
            train_encoder,
        })
    }

    fn zero_grads(&self) -> Vec<Grad> {
        self.slots
            .iter()
            .map(|s| Grad { weight: vec![0.0; s.dims.iter().product()], bias: vec![0.0; s.biases] })
            .collect()
    }

    /// Two convolutions with ReLU on the channel concatenation of `inputs`.
    fn block(&self, inputs: &[&Volume], block: &[Layer; 2]) -> [Volume; 2] {
        let mid = block[0].forward_conv(inputs, self.kernel);
        let out = block[1].forward_conv(&[&mid], self.kernel);
        [mid, out]
    }

    /// The forward pass of one sample (as [`InferenceNet::forward`](crate::InferenceNet::forward), padded).
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
            vectorised(|| add_bias_grad(dz, &mut g.bias));
            weight_grad(inputs, dz, kernel, &mut g.weight);
        }
    }

    /// Adds the weight and bias gradients of a stride-2 layer: `fine` and `coarse` are its fine
    /// and coarse sides (one the input, the other the output gradient `d_out`).
    fn stride2_grads(&self, layer: &Layer, fine: &Volume, coarse: &Volume, d_out: &Volume, grads: &mut [Grad]) {
        if layer.trainable {
            let g = &mut grads[layer.slot];
            vectorised(|| add_bias_grad(d_out, &mut g.bias));
            stride2_weight_grad(fine, coarse, &mut g.weight);
        }
    }

    /// The backward pass of one sample from the gradient of its (padded) output; returns the
    /// volumes it used (for [`recycle`]).
    fn backward(&self, a: &Activations, d_output: Volume, grads: &mut [Grad]) -> Vec<Volume> {
        let (depth, k) = (self.encoder.len(), self.kernel);
        let features = a.decoder.first().map_or(&a.bottleneck[1], |b| &b[1]);
        self.same_grads(&self.head, &[features], &d_output, 1, grads);
        // `d`: the gradient of the last convolution's pre-activation.
        let mut d = self.head.input_gradient(&d_output, 1, Some(features));
        let mut spent = vec![d_output];
        // Gradients of the decoders' concatenated inputs: their skip parts join the encoder's.
        let mut d_concat = Vec::with_capacity(depth);
        for l in 0..depth {
            let ([mid, _], layers) = (&a.decoder[l], &self.decoder[l]);
            self.same_grads(&layers[1], &[mid], &d, k, grads);
            let next = layers[1].input_gradient(&d, k, Some(mid));
            spent.push(std::mem::replace(&mut d, next));
            self.same_grads(&layers[0], &[&a.up[l], &a.encoder[l][1]], &d, k, grads);
            let concat = layers[0].input_gradient(&d, k, None);
            let mut d_up = pooled(concat.dims, concat.halo, a.up[l].channels);
            vectorised(|| add_channels(&mut d_up, &concat, 0));
            let coarse = a.decoder.get(l + 1).map_or(&a.bottleneck[1], |b| &b[1]);
            self.stride2_grads(&self.up[l], &d_up, coarse, &d_up, grads);
            d_concat.push(concat);
            if !self.train_encoder && l + 1 == depth {
                spent.extend([d, d_up]);
                spent.extend(d_concat);
                return spent;
            }
            spent.push(std::mem::replace(&mut d, downsample(&d_up, &self.up[l].backward)));
            spent.push(d_up);
            vectorised(|| relu_mask(&mut d, coarse));
        }
        if !self.train_encoder {
            spent.push(d);
            spent.extend(d_concat);
            return spent;
        }
        let mid = &a.bottleneck[0];
        self.same_grads(&self.bottleneck[1], &[mid], &d, k, grads);
        let next = self.bottleneck[1].input_gradient(&d, k, Some(mid));
        spent.push(std::mem::replace(&mut d, next));
        self.same_grads(&self.bottleneck[0], &[a.down.last().unwrap_or(&a.input)], &d, k, grads);
        // `d` is the output gradient of `first`, whose input gradient is still to be taken.
        let mut first = &self.bottleneck[0];
        for l in (0..depth).rev() {
            let d_down = first.input_gradient(&d, k, None);
            let [mid, out] = &a.encoder[l];
            self.stride2_grads(&self.down[l], out, &d_down, &d_down, grads);
            let mut d_skip = upsample(&d_down, &self.down[l].backward);
            vectorised(|| {
                add_channels(&mut d_skip, &d_concat[l], a.up[l].channels);
                relu_mask(&mut d_skip, out);
            });
            self.same_grads(&self.encoder[l][1], &[mid], &d_skip, k, grads);
            spent.push(std::mem::replace(&mut d, self.encoder[l][1].input_gradient(&d_skip, k, Some(mid))));
            spent.extend([d_down, d_skip]);
            let input = if l == 0 { &a.input } else { &a.down[l - 1] };
            self.same_grads(&self.encoder[l][0], &[input], &d, k, grads);
            first = &self.encoder[l][0];
        }
        spent.push(d);
        spent.extend(d_concat);
        spent
    }

    /// The summed gradients in the parameter order and layouts of the network: per layer its
    /// weight (reordered from the packed layout) and its bias, `None` for frozen layers.
    fn gradients(&self, grads: Vec<Grad>) -> Gradients {
        let per_layer: Vec<[Option<Vec<f32>>; 2]> = self
            .slots
            .par_iter()
            .zip(grads)
            .map(|(slot, g)| {
                if !slot.trainable {
                    return [None, None];
                }
                let mut weight = vec![0.0; g.weight.len()];
                let (c_out, splits, taps) = &slot.layout;
                conv_layout(*c_out, splits, *taps, |w, p| weight[w] = g.weight[p]);
                [Some(weight), Some(g.bias)]
            })
            .collect();
        Gradients(per_layer.into_iter().flatten().collect())
    }
}

/// The loss terms of one sample (`Σ mask · ‖pred − target‖²`) and the gradient of the padded
/// output: `scale · mask · (pred − target)` on the grid, zero on the padding.
fn output_gradient(output: &Volume, target: &[f32], mask: &[f32], grid: GridShape, scale: f32) -> (f64, Volume) {
    let (nodes, c) = (grid.nodes(), output.channels);
    let mut d = pooled(output.dims, output.halo, c);
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
#[inline(always)]
fn relu_mask(d: &mut Volume, y: &Volume) {
    for (g, v) in d.data.iter_mut().zip(&y.data) {
        if *v <= 0.0 {
            *g = 0.0;
        }
    }
}

/// Adds the gradient summed over nodes (halo nodes hold zeros).
#[inline(always)]
fn add_bias_grad(d: &Volume, bias: &mut [f32]) {
    for node in d.data.chunks_exact(d.channels) {
        for (b, v) in bias.iter_mut().zip(node) {
            *b += v;
        }
    }
}

/// Adds channels `from .. from + dst.channels` of `src` to `dst` (same grid and halo).
#[inline(always)]
fn add_channels(dst: &mut Volume, src: &Volume, from: usize) {
    let c = dst.channels;
    for (d, s) in dst.data.chunks_exact_mut(c).zip(src.data.chunks_exact(src.channels)) {
        for (a, b) in d.iter_mut().zip(&s[from..from + c]) {
            *a += b;
        }
    }
}

/// A stride-1 convolution as [`same_conv`], its output zeroed where `mask` (same shape) is not
/// positive (the ReLU of the layer below, in the backward pass): by the Winograd loops where the
/// layer has their transform `winograd` and they pay on the volumes (see [`winograd::pays`]),
/// else by the register-blocked SIMD loops of [`simd::conv_plane`] where they apply (see
/// [`simd::lanes`]).
fn conv(
    inputs: &[&Volume],
    layer: &Packed,
    winograd: Option<&Winograd>,
    kernel: usize,
    relu: bool,
    mask: Option<&Volume>,
) -> Volume {
    let first = inputs[0];
    if let Some(w) = winograd.filter(|_| winograd::pays(inputs, first)) {
        let mut out = pooled(first.dims, first.halo, layer.c_out);
        winograd::conv(inputs, layer, w, relu, mask, &mut out);
        return out;
    }
    #[cfg(target_arch = "x86_64")]
    if let Some(lanes) = simd::lanes(layer.c_out) {
        let mut out = pooled(first.dims, first.halo, layer.c_out);
        let job = ConvJob { inputs, layer, kernel, relu, mask, offsets: tap_offsets(first, kernel) };
        let plane_len = out.plane_nodes() * layer.c_out;
        out.data
            .par_chunks_mut(plane_len)
            .skip(first.halo)
            .take(first.dims[0])
            .enumerate()
            .for_each(|(i, plane)| simd::conv_plane(lanes, &job, i, plane));
        return out;
    }
    let mut out = same_conv(inputs, layer, kernel, relu);
    if let Some(mask) = mask {
        relu_mask(&mut out, mask);
    }
    out
}

/// Adds the weight gradient of a stride-1 convolution (see [`conv_weight_grad`]): by the
/// Winograd loops for 3×3×3 kernels on AVX-512 where they pay on the volumes (see
/// [`winograd::pays`]), else by the register-blocked SIMD loops of [`simd::weight_grad_part`]
/// where they apply (see [`simd::lanes`]).
fn weight_grad(inputs: &[&Volume], dz: &Volume, kernel: usize, grad: &mut [f32]) {
    if kernel == 3 && has_avx512() && winograd::pays(inputs, dz) {
        return winograd::weight_grad(inputs, dz, grad);
    }
    #[cfg(target_arch = "x86_64")]
    if let Some(lanes) = simd::lanes(dz.channels) {
        let offsets = tap_offsets(dz, kernel);
        let mut part = 0;
        for v in inputs {
            let len = kernel.pow(3) * v.channels * dz.channels;
            simd::weight_grad_part(lanes, v, dz, kernel, &offsets, &mut grad[part..part + len]);
            part += len;
        }
        return;
    }
    conv_weight_grad(inputs, dz, kernel, grad)
}

/// A stride-1 convolution: inputs (channel parts), weights, ReLU, output mask (see [`conv`]),
/// and the storage offsets of the (x, y) tap offsets ([`tap_offsets`]).
#[cfg(target_arch = "x86_64")]
struct ConvJob<'a> {
    inputs: &'a [&'a Volume],
    layer: &'a Packed,
    kernel: usize,
    relu: bool,
    mask: Option<&'a Volume>,
    offsets: Vec<isize>,
}

/// Register-blocked convolution loops on AVX-512 (16 lanes, `__m512`) or its 256-bit half
/// (8 lanes, `__m256`): each accumulator holds `L` output channels of one node (convolution) or
/// of one weight-matrix row (weight gradient), and every input value is broadcast into a fused
/// multiply-add with a vector of weights or gradients.
#[cfg(target_arch = "x86_64")]
mod simd {
    use std::arch::x86_64::*;

    use super::{ConvJob, Volume};
    use crate::net::lanes::{has_avx512, Vector};

    /// The SIMD width (16 or 8 lanes) of the loops for `channels` output channels: they need
    /// AVX-512 and a multiple of 8 channels; `None` where they do not apply (the faer GEMM path
    /// is taken instead).
    pub(super) fn lanes(channels: usize) -> Option<usize> {
        if !has_avx512() {
            None
        } else if channels.is_multiple_of(16) {
            Some(16)
        } else if channels.is_multiple_of(8) {
            Some(8)
        } else {
            None
        }
    }

    /// Calls `$body` for `$first` over `0..$n` in blocks of `$r` nodes or rows, the largest of
    /// the listed constants (the last one 1) that fits in what is left.
    macro_rules! blocked {
        ($n:expr, [$($size:literal),+], |$first:ident, $r:ident| $body:expr) => {{
            let n = $n;
            let mut $first = 0;
            while $first < n {
                $(
                    if n - $first >= $size {
                        const $r: usize = $size;
                        $body;
                        $first += $r;
                        continue;
                    }
                )+
            }
        }};
    }

    /// Output x-plane `i` (`plane`: its stored nodes) of a stride-1 convolution with `lanes`
    /// (16 or 8) SIMD lanes.
    pub(super) fn conv_plane(lanes: usize, job: &ConvJob, i: usize, plane: &mut [f32]) {
        #[target_feature(enable = "avx512f,avx2,fma")]
        fn avx512<V: Vector>(job: &ConvJob, i: usize, plane: &mut [f32]) {
            // Channel blocks per accumulator row: more when the lines are short.
            let blocks = job.layer.c_out / V::LANES;
            if blocks.is_multiple_of(4) {
                with_channels::<4, V>(job, i, plane)
            } else if blocks.is_multiple_of(2) {
                with_channels::<2, V>(job, i, plane)
            } else {
                with_channels::<1, V>(job, i, plane)
            }
        }
        // SAFETY: `lanes` is only given where the CPU has AVX-512F (checked by `lanes`).
        unsafe {
            if lanes == 16 {
                avx512::<__m512>(job, i, plane)
            } else {
                avx512::<__m256>(job, i, plane)
            }
        }
    }

    /// [`plane_loops`] with the inputs' channel count `C` a constant when it is a common one
    /// (all parts alike), 0 (read at run time) otherwise.
    #[inline(always)]
    fn with_channels<const B: usize, V: Vector>(job: &ConvJob, i: usize, plane: &mut [f32]) {
        let c = job.layer.parts[0].0;
        match c {
            _ if job.layer.parts.iter().any(|p| p.0 != c) => plane_loops::<B, 0, V>(job, i, plane),
            8 => plane_loops::<B, 8, V>(job, i, plane),
            16 => plane_loops::<B, 16, V>(job, i, plane),
            32 => plane_loops::<B, 32, V>(job, i, plane),
            64 => plane_loops::<B, 64, V>(job, i, plane),
            _ => plane_loops::<B, 0, V>(job, i, plane),
        }
    }

    /// For each y-line of plane `i`, blocks of `R` consecutive output nodes × `B · V::LANES`
    /// output channels are accumulated over the inputs' taps and channels (the input channel
    /// vectors of a node's `kernel` z-taps are contiguous, and those of consecutive nodes
    /// overlap), then biased, rectified if asked and stored; halo nodes stay zero.
    #[inline(always)]
    fn plane_loops<const B: usize, const C: usize, V: Vector>(job: &ConvJob, i: usize, plane: &mut [f32]) {
        let first = job.inputs[0];
        let [_, ny, nz] = first.dims;
        let plane_start = (i + first.halo) * first.plane_nodes();
        let c_out = job.layer.c_out;
        for j in 0..ny {
            let node = first.node(i, j, 0);
            for cb in (0..c_out).step_by(B * V::LANES) {
                let out = |n: usize| (node + n - plane_start) * c_out;
                if B == 1 {
                    blocked!(nz, [12, 8, 4, 2, 1], |n, R| conv_block::<R, B, C, V>(
                        job,
                        node + n,
                        cb,
                        &mut plane[out(n)..]
                    ));
                } else if B == 2 {
                    blocked!(nz, [6, 4, 3, 2, 1], |n, R| conv_block::<R, B, C, V>(
                        job,
                        node + n,
                        cb,
                        &mut plane[out(n)..]
                    ));
                } else {
                    blocked!(nz, [3, 2, 1], |n, R| conv_block::<R, B, C, V>(job, node + n, cb, &mut plane[out(n)..]));
                }
            }
        }
    }

    /// `R` output nodes from storage node `node`, channels `cb .. cb + B · V::LANES`, stored
    /// into `out` (from the first node's channel vector).
    #[inline(always)]
    fn conv_block<const R: usize, const B: usize, const C: usize, V: Vector>(
        job: &ConvJob,
        node: usize,
        cb: usize,
        out: &mut [f32],
    ) {
        let mut acc = [[V::zero(); B]; R];
        let c_out = job.layer.c_out;
        assert!(cb + B * V::LANES <= c_out, "channel block beyond the output channels");
        for (v, (c, matrix)) in job.inputs.iter().zip(&job.layer.parts) {
            // A constant channel count turns the node strides into address displacements.
            let c = if C == 0 { *c } else { C };
            let kc = job.kernel * c;
            for (ab, off) in job.offsets.iter().enumerate() {
                let start = (node as isize + off) as usize * c;
                let xs = &v.data[start..start + (R - 1) * c + kc];
                let w = matrix[ab * kc * c_out..][..kc * c_out].as_ptr();
                for t in 0..kc {
                    let mut wv = [V::zero(); B];
                    for (b, wv) in wv.iter_mut().enumerate() {
                        // SAFETY: t · c_out + cb + (b + 1) · LANES ≤ kc · c_out, the length of
                        // the slice behind `w` (cb + B · LANES ≤ c_out, asserted above).
                        *wv = unsafe { V::load_ptr(w.add(t * c_out + cb + b * V::LANES)) };
                    }
                    for (r, acc) in acc.iter_mut().enumerate() {
                        // SAFETY: r · c + t < (R - 1) · c + kc = xs.len().
                        let x = unsafe { *xs.get_unchecked(r * c + t) };
                        for (a, w) in acc.iter_mut().zip(&wv) {
                            *a = a.fma(x, *w);
                        }
                    }
                }
            }
        }
        let mut bias = [V::zero(); B];
        for (b, v) in bias.iter_mut().enumerate() {
            *v = V::load(&job.layer.bias[cb + b * V::LANES..]);
        }
        for (r, acc) in acc.iter().enumerate() {
            let at = r * c_out + cb;
            for (b, (a, bias)) in acc.iter().zip(bias).enumerate() {
                let at = at + b * V::LANES;
                let mask = job.mask.map(|m| V::load(&m.data[node * c_out + at..]));
                a.finish(bias, job.relu, mask).store(&mut out[at..]);
            }
        }
    }

    /// Adds the weight gradient of one input part `v` to `grad` (its matrix in the layout of
    /// [`Packed::conv`](crate::net::inference::Packed::conv)) given the output gradient `dz`, with
    /// `lanes` (16 or 8) SIMD lanes.
    pub(super) fn weight_grad_part(
        lanes: usize,
        v: &Volume,
        dz: &Volume,
        kernel: usize,
        offsets: &[isize],
        grad: &mut [f32],
    ) {
        #[target_feature(enable = "avx512f,avx2,fma")]
        fn avx512<V: Vector>(v: &Volume, dz: &Volume, kernel: usize, offsets: &[isize], grad: &mut [f32]) {
            weight_grad_loops::<V>(v, dz, kernel, offsets, grad)
        }
        // SAFETY: `lanes` is only given where the CPU has AVX-512F (checked by `lanes`).
        unsafe {
            if lanes == 16 {
                avx512::<__m512>(v, dz, kernel, offsets, grad)
            } else {
                avx512::<__m256>(v, dz, kernel, offsets, grad)
            }
        }
    }

    /// For each (x, y) tap offset, blocks of `R` matrix rows (z tap, input channel) ×
    /// `V::LANES` output channels are accumulated over all interior output nodes, line by line.
    #[inline(always)]
    fn weight_grad_loops<V: Vector>(v: &Volume, dz: &Volume, kernel: usize, offsets: &[isize], grad: &mut [f32]) {
        let (kc, c_out) = (kernel * v.channels, dz.channels);
        // Plane by plane, so that the planes read stay in cache across the passes.
        for i in 0..dz.dims[0] {
            for (ab, &off) in offsets.iter().enumerate() {
                let block = &mut grad[ab * kc * c_out..][..kc * c_out];
                for cb in (0..c_out).step_by(V::LANES) {
                    blocked!(kc, [16, 9, 8, 4, 2, 1], |row, R| weight_grad_block::<R, V>(
                        v, dz, i, off, row, cb, block
                    ));
                }
            }
        }
    }

    /// Adds the output nodes of plane `i` to rows `row .. row + R`, channels `cb ..` of the
    /// weight gradient of tap offset `off`.
    #[inline(always)]
    fn weight_grad_block<const R: usize, V: Vector>(
        v: &Volume,
        dz: &Volume,
        i: usize,
        off: isize,
        row: usize,
        cb: usize,
        block: &mut [f32],
    ) {
        let mut acc = [V::zero(); R];
        for (r, a) in acc.iter_mut().enumerate() {
            *a = V::load(&block[(row + r) * dz.channels + cb..]);
        }
        let [_, ny, nz] = dz.dims;
        let (c, c_out) = (v.channels, dz.channels);
        assert!(cb + V::LANES <= c_out, "channel block beyond the output channels");
        for j in 0..ny {
            let node = dz.node(i, j, 0);
            let ds = &dz.data[node * c_out..(node + nz) * c_out];
            let start = (node as isize + off) as usize * c + row;
            let xs = &v.data[start..start + (nz - 1) * c + R];
            let ds = ds.as_ptr();
            for n in 0..nz {
                // SAFETY: n · c_out + cb + LANES ≤ nz · c_out, the length of the slice behind
                // `ds` (cb + LANES ≤ c_out, asserted above).
                let d = unsafe { V::load_ptr(ds.add(n * c_out + cb)) };
                for (r, a) in acc.iter_mut().enumerate() {
                    // SAFETY: n · c + r < (nz - 1) · c + R = xs.len().
                    *a = a.fma(unsafe { *xs.get_unchecked(n * c + r) }, d);
                }
            }
        }
        for (r, a) in acc.iter().enumerate() {
            a.store(&mut block[(row + r) * c_out + cb..]);
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
