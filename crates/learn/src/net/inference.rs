//! Fast CPU inference for a trained U-Net.
//!
//! burn's `flex` backend runs a 3D convolution as an element-by-element im2col followed by a
//! GEMM; at the small channel counts of a real-time network the im2col dominates. Here the
//! weights are repacked once and activations are kept channels-last with a zero halo of
//! `kernel / 2` nodes. A stride-1 convolution then needs no copy at all: for one x-plane of the
//! output and one (x, y) tap offset, the inputs of all output nodes and all z taps form a
//! strided view of the stored data (rows overlap), so the layer is `kernel²` accumulated matrix
//! products (faer) per plane. The 2×2×2 down- and up-sampling gather their small patches.
//! Planes run in parallel (rayon). The result equals a plain `f64` forward pass up to
//! floating-point summation order (checked by the tests): 3× faster than burn on 2 cores
//! for the liver network with 8 first-layer channels.

use faer::linalg::matmul::matmul;
use faer::{Accum, MatMut, MatRef, Par};
use rayon::prelude::*;

use crate::data::grid::GridShape;
use crate::{LearnError, Result};

/// A volume of `channels` values per node, channels-last (`[x, y, z, channel]`, channel
/// fastest), with a zero halo of `halo` nodes on every side of the `dims` interior nodes.
pub(crate) struct Volume {
    pub(crate) dims: [usize; 3],
    pub(crate) halo: usize,
    pub(crate) channels: usize,
    pub(crate) data: Vec<f32>,
}

impl Volume {
    pub(crate) fn zeros(dims: [usize; 3], halo: usize, channels: usize) -> Volume {
        Volume::zeros_in(Vec::new(), dims, halo, channels)
    }

    /// A zero volume stored in `data` (cleared and resized; reusing its allocation).
    pub(crate) fn zeros_in(mut data: Vec<f32>, dims: [usize; 3], halo: usize, channels: usize) -> Volume {
        data.clear();
        data.resize(dims.iter().map(|d| d + 2 * halo).product::<usize>() * channels, 0.0);
        Volume { dims, halo, channels, data }
    }

    /// The volume of interior `padded` (at least `grid`) holding a channel-major field
    /// (`[channels, nx, ny, nz]`, `channels · grid.nodes()` values) at its low corner, zero elsewhere.
    pub(crate) fn from_field(
        field: &[f32],
        channels: usize,
        grid: GridShape,
        padded: [usize; 3],
        halo: usize,
    ) -> Volume {
        let nodes = grid.nodes();
        let mut v = Volume::zeros(padded, halo, channels);
        for c in 0..channels {
            for node in 0..nodes {
                let [i, j, k] = grid.node_coords(node);
                let at = v.node(i, j, k) * channels + c;
                v.data[at] = field[c * nodes + node];
            }
        }
        v
    }

    /// Stored nodes along y and z (interior plus halo).
    pub(crate) fn stored_yz(&self) -> (usize, usize) {
        (self.dims[1] + 2 * self.halo, self.dims[2] + 2 * self.halo)
    }

    /// Stored nodes in one x-plane.
    pub(crate) fn plane_nodes(&self) -> usize {
        let (sy, sz) = self.stored_yz();
        sy * sz
    }

    /// Storage position (node number) of interior node `(i, j, k)`.
    pub(crate) fn node(&self, i: usize, j: usize, k: usize) -> usize {
        let (sy, sz) = self.stored_yz();
        ((i + self.halo) * sy + j + self.halo) * sz + k + self.halo
    }

    /// Stored nodes from interior node `(i, 0, 0)` to `(i, ny - 1, nz - 1)` of a plane (the rows
    /// of the tap views of [`same_conv`], halo nodes between the y-lines included).
    pub(crate) fn plane_rows(&self) -> usize {
        (self.dims[1] - 1) * self.stored_yz().1 + self.dims[2]
    }

    /// Channel vector of the node at storage position `node`.
    pub(crate) fn at(&self, node: usize) -> &[f32] {
        &self.data[node * self.channels..(node + 1) * self.channels]
    }
}

/// One layer's weights and bias. The input channels may come from several volumes (the
/// decoder's concatenation of up-sampled and skip features): each such part has its own
/// `(taps · channels) × c_out` row-major matrix, rows tap-major (taps in x, y, z order, z fastest).
pub(crate) struct Packed {
    pub(crate) parts: Vec<(usize, Vec<f32>)>,
    pub(crate) bias: Vec<f32>,
    pub(crate) c_in: usize,
    pub(crate) c_out: usize,
    pub(crate) taps: usize,
}

impl Packed {
    /// Packs a convolution: `weight` is `[c_out, c_in, taps]` (burn's `[c_out, c_in, kx, ky,
    /// kz]`), `bias` is `[c_out]`; the input channels are split into parts of `splits` channels.
    pub(crate) fn conv(weight: &[f32], bias: &[f32], c_out: usize, splits: &[usize], taps: usize) -> Result<Packed> {
        let c_in: usize = splits.iter().sum();
        check_len("convolution", weight.len(), bias.len(), c_out * c_in * taps, c_out)?;
        let mut rest = vec![0.0; weight.len()];
        conv_layout(c_out, splits, taps, |w, p| rest[p] = weight[w]);
        let mut parts = Vec::with_capacity(splits.len());
        for &c in splits {
            let tail = rest.split_off(taps * c * c_out);
            parts.push((c, rest));
            rest = tail;
        }
        Ok(Packed { parts, bias: bias.to_vec(), c_in, c_out, taps })
    }

    /// Packs a 2×2×2 stride-2 transposed convolution: `weight` is `[c_in, c_out, 8]` (burn's
    /// `[c_in, c_out, kx, ky, kz]`), `bias` is `[c_out]`. The matrix is two `c_in × (4 · c_out)`
    /// blocks, one per x-offset, columns tap-major.
    pub(crate) fn transposed(weight: &[f32], bias: &[f32], c_in: usize, c_out: usize) -> Result<Packed> {
        check_len("transposed convolution", weight.len(), bias.len(), c_in * c_out * 8, c_out)?;
        let mut matrix = vec![0.0; weight.len()];
        transposed_layout(c_in, c_out, |w, p| matrix[p] = weight[w]);
        Ok(Packed { parts: vec![(c_in, matrix)], bias: bias.to_vec(), c_in, c_out, taps: 8 })
    }

    /// The weight matrix of a single-part layer.
    pub(crate) fn matrix(&self) -> &[f32] {
        &self.parts[0].1
    }
}

/// Calls `f(w, p)` for each weight of a convolution: `w` its index in burn's `[c_out, c_in,
/// taps]` order, `p` its position in the concatenation of the part matrices of
/// [`Packed::conv`]. The order of the calls fills those matrices 16 output channels (a cache
/// line) at a time, reading 16 weight rows: their rows are `c_out` apart, often a multiple of
/// 4 KiB, and a plain scatter thrashes the cache.
pub(crate) fn conv_layout(c_out: usize, splits: &[usize], taps: usize, mut f: impl FnMut(usize, usize)) {
    let c_in: usize = splits.iter().sum();
    for block in (0..c_out).step_by(16) {
        let (mut offset, mut first) = (0, 0);
        for &c in splits {
            for ci in 0..c {
                for t in 0..taps {
                    for co in block..c_out.min(block + 16) {
                        f((co * c_in + first + ci) * taps + t, offset + (t * c + ci) * c_out + co);
                    }
                }
            }
            offset += taps * c * c_out;
            first += c;
        }
    }
}

/// Calls `f(w, p)` for each weight of a 2×2×2 transposed convolution: `w` its index in burn's
/// `[c_in, c_out, 8]` order (increasing), `p` its position in the matrix of [`Packed::transposed`].
pub(crate) fn transposed_layout(c_in: usize, c_out: usize, mut f: impl FnMut(usize, usize)) {
    for ci in 0..c_in {
        for co in 0..c_out {
            for t in 0..8 {
                f((ci * c_out + co) * 8 + t, ((t / 4) * c_in + ci) * 4 * c_out + (t % 4) * c_out + co);
            }
        }
    }
}

fn check_len(what: &str, weights: usize, bias: usize, want_w: usize, want_b: usize) -> Result<()> {
    if weights != want_w || bias != want_b {
        return Err(LearnError::InvalidInput(format!(
            "{what}: {weights} weights and {bias} biases, expected {want_w} and {want_b}"
        )));
    }
    Ok(())
}

/// Two convolutions with ReLU, as in the U-Net's levels.
pub(crate) type Block = [Packed; 2];

/// The U-Net repacked for inference on the CPU (see the module documentation). Built by
/// [`UNet::to_inference`](crate::UNet::to_inference).
pub struct InferenceNet {
    kernel: usize,
    in_channels: usize,
    encoder: Vec<Block>,
    down: Vec<Packed>,
    bottleneck: Block,
    up: Vec<Packed>,
    decoder: Vec<Block>,
    head: Packed,
}

impl InferenceNet {
    /// Assembles the layers (each checked against its neighbours).
    pub(crate) fn new(
        kernel: usize,
        encoder: Vec<Block>,
        down: Vec<Packed>,
        bottleneck: Block,
        up: Vec<Packed>,
        decoder: Vec<Block>,
        head: Packed,
    ) -> Result<InferenceNet> {
        let depth = encoder.len();
        let bad = |m: String| Err(LearnError::InvalidInput(format!("inference network: {m}")));
        if kernel.is_multiple_of(2) || down.len() != depth || up.len() != depth || decoder.len() != depth {
            return bad(format!("kernel {kernel} or level counts do not fit depth {depth}"));
        }
        let in_channels = encoder.first().unwrap_or(&bottleneck)[0].c_in;
        let chain_ok = encoder.iter().zip(&down).all(|(b, d)| b[1].c_out == d.c_in)
            && up.iter().zip(&decoder).all(|(u, b)| b[0].parts.iter().map(|p| p.0).eq([u.c_out, b[1].c_out]))
            && head.taps == 1;
        if !chain_ok {
            return bad("channel counts of consecutive layers do not match".into());
        }
        Ok(InferenceNet { kernel, in_channels, encoder, down, bottleneck, up, decoder, head })
    }

    /// Runs the network on one input field (`[in_channels, nx, ny, nz]`, channel-major as in
    /// the grid layout, already normalised) and returns `[out_channels, nx, ny, nz]`.
    pub fn forward(&self, input: &[f32], grid: GridShape) -> Result<Vec<f32>> {
        let dims = grid.dims();
        let nodes = grid.nodes();
        if input.len() != self.in_channels * nodes {
            return Err(LearnError::InvalidInput(format!(
                "inference input has {} values, expected {} channels on grid {grid}",
                input.len(),
                self.in_channels
            )));
        }
        let m = 1usize << self.encoder.len();
        let padded = dims.map(|n| n.div_ceil(m) * m);
        let mut h = Volume::from_field(input, self.in_channels, grid, padded, self.kernel / 2);
        let mut skips = Vec::with_capacity(self.encoder.len());
        for (block, down) in self.encoder.iter().zip(&self.down) {
            h = self.block(&[&h], block);
            let next = downsample(&h, down);
            skips.push(h);
            h = next;
        }
        h = self.block(&[&h], &self.bottleneck);
        for ((up, block), skip) in self.up.iter().zip(&self.decoder).zip(skips).rev() {
            h = upsample(&h, up);
            h = self.block(&[&h, &skip], block);
        }
        let out = same_conv(&[&h], &self.head, 1, false);
        let c_out = self.head.c_out;
        let mut field = vec![0.0; c_out * nodes];
        for node in 0..nodes {
            let [i, j, k] = grid.node_coords(node);
            for (c, v) in out.at(out.node(i, j, k)).iter().enumerate() {
                field[c * nodes + node] = *v;
            }
        }
        Ok(field)
    }

    /// Two same-size convolutions with ReLU on the channel concatenation of `inputs`.
    fn block(&self, inputs: &[&Volume], block: &Block) -> Volume {
        let mid = same_conv(inputs, &block[0], self.kernel, true);
        same_conv(&[&mid], &block[1], self.kernel, true)
    }
}

/// A stride-1 convolution with zero padding `kernel / 2` (at most the halo) on the channel
/// concatenation of `inputs` (same grid and halo). In channels-last storage, the input nodes a
/// tap multiplies for all interior nodes of an output x-plane form one contiguous run (from
/// node `(i, 0, 0)` to `(i, ny-1, nz-1)`, shifted by the tap's offset), and the `kernel` taps
/// along z are neighbours in it; so each (x, y) tap offset is one matrix product on a strided
/// view of the stored data (row `n` = the channel vectors of nodes `n .. n + kernel` of the run),
/// accumulated. Halo rows inside the run are computed and dropped.
pub(crate) fn same_conv(inputs: &[&Volume], layer: &Packed, kernel: usize, relu: bool) -> Volume {
    let first = inputs[0];
    let (dims, halo) = (first.dims, first.halo);
    debug_assert!(kernel / 2 <= halo && inputs.iter().all(|v| v.dims == dims && v.halo == halo));
    debug_assert!(inputs.iter().zip(&layer.parts).all(|(v, (c, _))| v.channels == *c));
    let mut out = Volume::zeros(dims, halo, layer.c_out);
    let (sy, sz) = out.stored_yz();
    let c_out = layer.c_out;
    let k = kernel;
    let offsets = tap_offsets(&out, kernel);
    let rows = out.plane_rows();
    let corner = out.node(0, 0, 0);
    out.data.par_chunks_mut(sy * sz * c_out).skip(halo).take(dims[0]).enumerate().for_each_init(
        || vec![0.0f32; rows * c_out],
        |product, (i, plane)| {
            let base = (corner + i * sy * sz) as isize;
            let mut accumulate = false;
            for (ab, off) in offsets.iter().enumerate() {
                let start = (base + off) as usize;
                for (v, (c, matrix)) in inputs.iter().zip(&layer.parts) {
                    let lhs = tap_view(v, start, rows, k);
                    gemm(product, lhs, &matrix[ab * k * c * c_out..][..k * c * c_out], c_out, accumulate);
                    accumulate = true;
                }
            }
            let first_node = corner - halo * sy * sz;
            for j in 0..dims[1] {
                let at = first_node + j * sz;
                let out = &mut plane[at * c_out..(at + dims[2]) * c_out];
                write_nodes(out, product, rows, j * sz, 0, &layer.bias, relu);
            }
        },
    );
    out
}

/// Storage offsets (in nodes) from an output node of `v` to the first input node of each
/// (x, y) tap offset `(a, b, 0)` of a `kernel`-sized stride-1 convolution, `a`-major.
pub(crate) fn tap_offsets(v: &Volume, kernel: usize) -> Vec<isize> {
    let (sy, sz) = v.stored_yz();
    let (r, k) = ((kernel / 2) as isize, kernel);
    (0..k * k).map(|ab| (((ab / k) as isize - r) * sy as isize + (ab % k) as isize - r) * sz as isize - r).collect()
}

/// The strided view of `v` (`rows × (kernel · channels)`) whose row `n` is the `kernel` channel
/// vectors along z from node `start + n`, contiguous in channels-last storage (rows overlap).
pub(crate) fn tap_view(v: &Volume, start: usize, rows: usize, kernel: usize) -> MatRef<'_, f32> {
    let c = v.channels;
    let data = &v.data[start * c..(start + rows - 1) * c + kernel * c];
    MatRef::from_row_major_slice_with_stride(data, rows, kernel * c, c)
}

/// The 2×2×2 stride-2 convolution (no padding): for each output x-plane, the 8 input channel
/// vectors under every output node are gathered into a patch matrix, then one matrix product.
pub(crate) fn downsample(fine: &Volume, layer: &Packed) -> Volume {
    let dims = fine.dims.map(|n| n / 2);
    let mut out = Volume::zeros(dims, fine.halo, layer.c_out);
    let (halo, (sy, sz)) = (out.halo, out.stored_yz());
    let (c_out, k_len) = (layer.c_out, layer.taps * layer.c_in);
    let rows = dims[1] * dims[2];
    out.data.par_chunks_mut(sy * sz * c_out).skip(halo).take(dims[0]).enumerate().for_each_init(
        || (vec![0.0f32; rows * k_len], vec![0.0f32; rows * c_out]),
        |(patches, product), (i, plane)| {
            gather_patches(fine, i, patches);
            gemm(product, MatRef::from_row_major_slice(&patches[..], rows, k_len), layer.matrix(), c_out, false);
            for j in 0..dims[1] {
                let at = ((j + halo) * sz + halo) * c_out;
                write_nodes(&mut plane[at..at + dims[2] * c_out], product, rows, j * dims[2], 0, &layer.bias, false);
            }
        },
    );
    out
}

/// Gathers the 2×2×2 patches of `fine` under the nodes of coarse x-plane `i` into `patches`
/// (row `j · (ny / 2) + k`: the 8 channel vectors, taps in x, y, z order, z fastest).
pub(crate) fn gather_patches(fine: &Volume, i: usize, patches: &mut [f32]) {
    let [_, ny, nz] = fine.dims.map(|n| n / 2);
    let c = fine.channels;
    for j in 0..ny {
        for k in 0..nz {
            let row = &mut patches[(j * nz + k) * 8 * c..][..8 * c];
            for (t, tap) in row.chunks_exact_mut(c).enumerate() {
                tap.copy_from_slice(fine.at(fine.node(2 * i + t / 4, 2 * j + (t / 2) % 2, 2 * k + t % 2)));
            }
        }
    }
}

/// Gathers the interior nodes of x-plane `i` of `v` into `rows` (row `j · nz + k`).
pub(crate) fn gather_plane(v: &Volume, i: usize, rows: &mut [f32]) {
    let [_, ny, nz] = v.dims;
    let c = v.channels;
    for j in 0..ny {
        for k in 0..nz {
            rows[(j * nz + k) * c..][..c].copy_from_slice(v.at(v.node(i, j, k)));
        }
    }
}

/// The 2×2×2 stride-2 transposed convolution: output plane `i` takes coarse plane `i / 2` and
/// the weight block of x-offset `i % 2`.
pub(crate) fn upsample(coarse: &Volume, layer: &Packed) -> Volume {
    let dims = coarse.dims.map(|n| 2 * n);
    let mut out = Volume::zeros(dims, coarse.halo, layer.c_out);
    let (halo, (_, sz)) = (out.halo, out.stored_yz());
    let plane_len = out.plane_nodes() * layer.c_out;
    let (c_in, c_out) = (layer.c_in, layer.c_out);
    let [_, ny, nz] = coarse.dims;
    let rows = ny * nz;
    let n = 4 * c_out;
    out.data.par_chunks_mut(plane_len).skip(halo).take(dims[0]).enumerate().for_each_init(
        || (vec![0.0f32; rows * c_in], vec![0.0f32; rows * n]),
        |(patches, product), (i, plane)| {
            gather_plane(coarse, i / 2, patches);
            let lhs = MatRef::from_row_major_slice(&patches[..], rows, c_in);
            gemm(product, lhs, &layer.matrix()[(i % 2) * c_in * n..][..c_in * n], n, false);
            for j in 0..ny {
                for k in 0..nz {
                    for (t, (b, c)) in [(0, 0), (0, 1), (1, 0), (1, 1)].into_iter().enumerate() {
                        let at = ((2 * j + b + halo) * sz + 2 * k + c + halo) * c_out;
                        let out = &mut plane[at..at + c_out];
                        write_nodes(out, product, rows, j * nz + k, t * c_out, &layer.bias, false);
                    }
                }
            }
        },
    );
    out
}

/// `product (rows × n) (+)= lhs (rows × k) · matrix (k × n)`: `matrix` row-major, `product`
/// column-major (the long dimension contiguous suits the GEMM kernels); added to the product
/// when `accumulate`, replacing it otherwise.
pub(crate) fn gemm(product: &mut [f32], lhs: MatRef<'_, f32>, matrix: &[f32], n: usize, accumulate: bool) {
    let (rows, k) = (lhs.nrows(), lhs.ncols());
    let dst = MatMut::from_column_major_slice_mut(&mut product[..rows * n], rows, n);
    let rhs = MatRef::from_row_major_slice(matrix, k, n);
    let beta = if accumulate { Accum::Add } else { Accum::Replace };
    matmul(dst, beta, lhs, rhs, 1.0f32, Par::Seq);
}

/// Writes `out[n · c + co] = product[(col0 + co) · rows + first + n] + bias[co]` for the nodes
/// `n` of `out` (`c` = `bias.len()` values per node; `product` column-major with `rows` rows),
/// then ReLU if asked.
fn write_nodes(out: &mut [f32], product: &[f32], rows: usize, first: usize, col0: usize, bias: &[f32], relu: bool) {
    for (n, node) in out.chunks_exact_mut(bias.len()).enumerate() {
        for (co, (o, b)) in node.iter_mut().zip(bias).enumerate() {
            let x = product[(col0 + co) * rows + first + n] + b;
            *o = if relu { x.max(0.0) } else { x };
        }
    }
}
