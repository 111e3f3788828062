//! Winograd F(2×2×2, 3×3×3) stride-1 convolutions and their weight gradients, for the training
//! engine ([`crate::net::backprop`]).
//!
//! A 3×3×3 convolution computes each 2×2×2 block of output nodes (a *tile*) from the 4×4×4 input
//! nodes around it as `Aᵀ [(G g Gᵀ) ⊙ (Bᵀ d B)] A` along each axis (Lavin & Gray, "Fast
//! algorithms for convolutional neural networks", CVPR 2016): per pair of channels, the
//! 27 · 8 multiply-adds of the direct convolution become 64 products. Summed over the input
//! channels, they are 64 matrix products (one per point of the transformed 4×4×4 tile) of
//! `tiles × c_in` transformed inputs by `c_in × c_out` transformed weights, between transforms
//! made of additions and halvings. The weight gradient is the transposed computation:
//! `Gᵀ [Σ_tiles (Bᵀ d B) ⊗ (A dy Aᵀ)] G`, 64 products of `c_in × tiles` by `tiles × c_out`.
//!
//! Channels go 16 at a time in [`Vector`]s (`__m512` on AVX-512, see [`run`]): the loops take
//! layers whose input parts and outputs all have a multiple of 16 channels, on volumes of even
//! sizes with a halo ([`takes`]), and the training engine uses them where they beat its direct
//! loops ([`pays`]). Tiles are transformed in chunks of at most [`CHUNK`], so that a chunk's
//! transformed inputs and products stay in the core's cache.

use std::cell::RefCell;
use std::ops::Range;

use rayon::prelude::*;

use crate::net::inference::{Packed, Volume};
use crate::net::lanes::{run, Kernel, Vector, LANES};

/// Points of a transformed tile (4 × 4 × 4).
const POINTS: usize = 64;

/// The most tiles transformed together.
const CHUNK: usize = 48;

/// Tiles per register block of the forward products; chunks are padded to a multiple of it.
const ROWS: usize = 8;

/// The weights of a 3×3×3 convolution transformed to `G g Gᵀ`: `[point][c_in][c_out]`, the
/// input channels of all parts concatenated.
pub(crate) struct Winograd {
    u: Vec<f32>,
}

impl Winograd {
    /// Transforms the part matrices of a 3×3×3 convolution (the layout of [`Packed::conv`]) with
    /// `c_out` output channels; `None` unless every part and the output have a multiple of 16
    /// channels.
    pub(crate) fn new(parts: &[(usize, Vec<f32>)], c_out: usize) -> Option<Winograd> {
        Winograd::with(parts, c_out, false)
    }

    /// [`Winograd::new`] with portable vectors if `portable`.
    fn with(parts: &[(usize, Vec<f32>)], c_out: usize, portable: bool) -> Option<Winograd> {
        if !c_out.is_multiple_of(LANES)
            || parts.iter().any(|(c, m)| !c.is_multiple_of(LANES) || m.len() != 27 * c * c_out)
        {
            return None;
        }
        let c_in: usize = parts.iter().map(|p| p.0).sum();
        let mut u = vec![0.0; POINTS * c_in * c_out];
        run(TransformWeights { parts, c_out, c_in, u: &mut u }, portable);
        Some(Winograd { u })
    }
}

/// Writes `G g Gᵀ` of every channel pair of `parts` into `u`.
struct TransformWeights<'a> {
    parts: &'a [(usize, Vec<f32>)],
    c_out: usize,
    c_in: usize,
    u: &'a mut [f32],
}

impl Kernel for TransformWeights<'_> {
    type Output = ();
    #[inline(always)]
    fn run<V: Vector>(self) {
        let (c_out, c_in) = (self.c_out, self.c_in);
        let mut x = [V::zero(); POINTS];
        let mut c0 = 0;
        for (c, matrix) in self.parts {
            for ci in 0..*c {
                for cb in (0..c_out).step_by(LANES) {
                    for tap in 0..27 {
                        x[at(tap / 9, tap / 3 % 3, tap % 3)] = V::load(&matrix[row(tap, *c, ci) * c_out + cb..]);
                    }
                    cube(&mut x, weight_transform);
                    for (p, w) in x.iter().enumerate() {
                        w.store(&mut self.u[(p * c_in + c0 + ci) * c_out + cb..]);
                    }
                }
            }
            c0 += c;
        }
    }
}

/// The row of input channel `ci` at tap `tap` (x, y, z order, z fastest) in a part matrix of
/// [`Packed::conv`] with `c` input channels and 3×3×3 taps.
#[inline(always)]
fn row(tap: usize, c: usize, ci: usize) -> usize {
    (tap / 3) * 3 * c + (tap % 3) * c + ci
}

/// `G g`: a weight triple to the 4 points.
#[inline(always)]
fn weight_transform<V: Vector>([g0, g1, g2]: [V; 3]) -> [V; 4] {
    let (outer, middle) = (g0.add(g2), g1);
    [g0, outer.add(middle).scale(0.5), outer.sub(middle).scale(0.5), g2]
}

/// `Bᵀ d`: 4 input nodes to the 4 points.
#[inline(always)]
fn input_transform<V: Vector>([d0, d1, d2, d3]: [V; 4]) -> [V; 4] {
    [d0.sub(d2), d1.add(d2), d2.sub(d1), d1.sub(d3)]
}

/// `Aᵀ m`: 4 points to the 2 output nodes.
#[inline(always)]
fn output_transform<V: Vector>([m0, m1, m2, m3]: [V; 4]) -> [V; 2] {
    [m0.add(m1).add(m2), m1.sub(m2).sub(m3)]
}

/// `A dy`: the gradients of 2 output nodes to the 4 points (transpose of [`output_transform`]).
#[inline(always)]
fn output_gradient_transform<V: Vector>([y0, y1]: [V; 2]) -> [V; 4] {
    [y0, y0.add(y1), y0.sub(y1), V::zero().sub(y1)]
}

/// `Gᵀ m`: the gradients of the 4 points to the weight triple (transpose of
/// [`weight_transform`]).
#[inline(always)]
fn weight_gradient_transform<V: Vector>([m0, m1, m2, m3]: [V; 4]) -> [V; 3] {
    let (sum, diff) = (m1.add(m2).scale(0.5), m1.sub(m2).scale(0.5));
    [m0.add(sum), diff, sum.add(m3)]
}

/// The position of node or point `(a, b, c)` in a cube buffer (4 per axis, x, y, z order).
#[inline(always)]
fn at(a: usize, b: usize, c: usize) -> usize {
    (a * 4 + b) * 4 + c
}

/// Applies the 1D transform `f` (`N` values to `M`) along the three axes of the `N³` cube held
/// in `x` (positions [`at`]), in place: the `M³` result is at the same positions.
#[inline(always)]
fn cube<V: Vector, const N: usize, const M: usize>(x: &mut [V; POINTS], f: impl Fn([V; N]) -> [V; M]) {
    for a in 0..N {
        for b in 0..N {
            line(x, at(a, b, 0), 1, &f);
        }
    }
    for a in 0..N {
        for c in 0..M {
            line(x, at(a, 0, c), 4, &f);
        }
    }
    for b in 0..M {
        for c in 0..M {
            line(x, at(0, b, c), 16, &f);
        }
    }
}

/// Applies `f` to the line of `N` values of `x` at `start + k · stride`, writing its `M` values
/// there.
#[inline(always)]
fn line<V: Vector, const N: usize, const M: usize>(
    x: &mut [V; POINTS],
    start: usize,
    stride: usize,
    f: &impl Fn([V; N]) -> [V; M],
) {
    let mut values = [V::zero(); N];
    for (k, v) in values.iter_mut().enumerate() {
        *v = x[start + k * stride];
    }
    for (k, r) in f(values).into_iter().enumerate() {
        x[start + k * stride] = r;
    }
}

/// Whether the loops take a convolution of `inputs` (and output or output gradient `dz` of the
/// same shape): a multiple of 16 channels in each, even sizes, a halo.
pub(crate) fn takes(inputs: &[&Volume], dz: &Volume) -> bool {
    inputs.iter().chain([&dz]).all(|v| {
        v.dims == dz.dims
            && v.halo == dz.halo
            && v.halo >= 1
            && v.channels.is_multiple_of(LANES)
            && v.dims.iter().all(|&n| n > 0 && n.is_multiple_of(2))
    })
}

/// Whether the loops take a convolution of `inputs` with output (gradient) `dz` ([`takes`]) and
/// beat the direct loops of [`crate::net::backprop`] on it ([`tiles_pay`]).
pub(crate) fn pays(inputs: &[&Volume], dz: &Volume) -> bool {
    takes(inputs, dz) && tiles_pay(dz.dims)
}

/// Whether volumes of `dims` nodes have enough tiles for the loops to beat the direct ones: at
/// least 16 per x-slab (at 6³ nodes, chunks of 9 tiles padded to 16 rows gained nothing overall;
/// see the README's measurements).
pub(crate) fn tiles_pay(dims: [usize; 3]) -> bool {
    (dims[1] / 2) * (dims[2] / 2) >= 2 * ROWS
}

/// The tiles of a volume, in chunks: within each x-slab (tiles of one x index), runs of tiles in
/// (y, z) order.
struct Tiling {
    /// Tiles along x, y, z.
    n: [usize; 3],
    /// Tiles per chunk (the last of a slab may have fewer).
    chunk: usize,
    /// Stored nodes along y and z.
    stored: (usize, usize),
    halo: usize,
}

impl Tiling {
    fn new(v: &Volume) -> Tiling {
        let n = v.dims.map(|d| d / 2);
        let slab = n[1] * n[2];
        let chunks = slab.div_ceil(CHUNK);
        Tiling { n, chunk: slab.div_ceil(chunks), stored: v.stored_yz(), halo: v.halo }
    }

    /// The chunks of slab `tx`: ranges of tile numbers within the slab.
    fn chunks(&self) -> impl Iterator<Item = Range<usize>> + '_ {
        let slab = self.n[1] * self.n[2];
        (0..slab).step_by(self.chunk).map(move |s| s..(s + self.chunk).min(slab))
    }

    /// Stored nodes in one x-plane.
    #[inline(always)]
    fn plane(&self) -> usize {
        self.stored.0 * self.stored.1
    }

    /// The storage node, within its x-plane, of the low corner of output tile `t` of a slab
    /// (its 2×2×2 output nodes are `+ j · sz + k` in planes `2 tx + i`).
    #[inline(always)]
    fn in_plane(&self, t: usize) -> usize {
        let (ty, tz) = (t / self.n[2], t % self.n[2]);
        (2 * ty + self.halo) * self.stored.1 + 2 * tz + self.halo
    }

    /// The storage node of the low corner of the 4×4×4 input nodes of tile `t` of slab `tx`.
    #[inline(always)]
    fn input_corner(&self, tx: usize, t: usize) -> usize {
        (2 * tx + self.halo - 1) * self.plane() + self.in_plane(t) - self.stored.1 - 1
    }
}

/// The stride of the rows (tiles) of a transformed buffer of `width` channels per point: one
/// vector more than the row, so that the rows a register block reads at once are not a multiple
/// of 4 KiB apart (they would all fall in the same sets of the L1 cache).
#[inline(always)]
fn pitch(width: usize) -> usize {
    POINTS * width + LANES
}

/// Rows of a chunk of `len` tiles in the transformed buffers (a multiple of [`ROWS`]).
fn padded(len: usize) -> usize {
    len.div_ceil(ROWS) * ROWS
}

thread_local! {
    /// Transformed inputs, products or output gradients, and weight-gradient sums of this
    /// thread, reused across calls.
    static BUFFERS: RefCell<[Vec<f32>; 3]> = const { RefCell::new([Vec::new(), Vec::new(), Vec::new()]) };
}

/// `buffer` holding at least `len` values (contents unspecified).
fn sized(buffer: &mut Vec<f32>, len: usize) -> &mut [f32] {
    if buffer.len() < len {
        buffer.resize(len, 0.0);
    }
    &mut buffer[..len]
}

/// Writes `Bᵀ d B` of the 4×4×4 input nodes of tiles `tiles` of slab `tx` of every part of
/// `inputs` into rows `0..` of `v` (`[row][point][c_in]`, rows [`pitch`] apart, parts concatenated).
#[inline(always)]
fn transform_inputs<V: Vector>(inputs: &[&Volume], tiling: &Tiling, tx: usize, tiles: Range<usize>, v: &mut [f32]) {
    let (sy, sz) = tiling.stored;
    let c_in: usize = inputs.iter().map(|v| v.channels).sum();
    let mut x = [V::zero(); POINTS];
    let mut c0 = 0;
    for vol in inputs {
        let c = vol.channels;
        for (r, t) in tiles.clone().enumerate() {
            let corner = tiling.input_corner(tx, t);
            for cb in (0..c).step_by(LANES) {
                for (n, x) in x.iter_mut().enumerate() {
                    let node = corner + (n / 16 * sy + n / 4 % 4) * sz + n % 4;
                    *x = V::load(&vol.data[node * c + cb..]);
                }
                cube(&mut x, input_transform);
                for (p, x) in x.iter().enumerate() {
                    x.store(&mut v[r * pitch(c_in) + p * c_in + c0 + cb..]);
                }
            }
        }
        c0 += c;
    }
}

/// `m[p] = v[p] · u[p]` for every point `p`: `rows × c_in` by `c_in × c_out`, in register
/// blocks of `R` rows × `B` vectors of output channels (`v` and `m` are `[row][point][channel]`, rows [`pitch`] apart).
#[inline(always)]
fn multiply<V: Vector, const R: usize, const B: usize>(
    v: &[f32],
    u: &[f32],
    rows: usize,
    c_in: usize,
    c_out: usize,
    m: &mut [f32],
) {
    assert!(v.len() >= rows * pitch(c_in) && rows.is_multiple_of(R), "rows beyond the transformed inputs");
    for p in 0..POINTS {
        let up = &u[p * c_in * c_out..][..c_in * c_out];
        for cb in (0..c_out).step_by(B * LANES) {
            assert!(cb + B * LANES <= c_out, "register block beyond the output channels");
            for t in (0..rows).step_by(R) {
                let mut xs = [v.as_ptr(); R];
                for (r, xs) in xs.iter_mut().enumerate() {
                    // SAFETY: (t + r) · pitch + (p + 1) · c_in ≤ rows · pitch ≤ v.len().
                    *xs = unsafe { xs.add((t + r) * pitch(c_in) + p * c_in) };
                }
                let mut acc = [[V::zero(); B]; R];
                for ci in 0..c_in {
                    let mut w = [V::zero(); B];
                    for (b, w) in w.iter_mut().enumerate() {
                        // SAFETY: ci · c_out + cb + (b + 1) · LANES ≤ c_in · c_out = up.len()
                        // (asserted above).
                        *w = unsafe { V::load_ptr(up.as_ptr().add(ci * c_out + cb + b * LANES)) };
                    }
                    for (acc, xs) in acc.iter_mut().zip(xs) {
                        // SAFETY: `xs` starts a row of c_in > ci values (above).
                        let x = unsafe { *xs.add(ci) };
                        for (a, w) in acc.iter_mut().zip(w) {
                            *a = a.fma(x, w);
                        }
                    }
                }
                for (r, acc) in acc.iter().enumerate() {
                    for (b, a) in acc.iter().enumerate() {
                        a.store(&mut m[(t + r) * pitch(c_out) + p * c_out + cb + b * LANES..]);
                    }
                }
            }
        }
    }
}

/// What the forward loops write: biases, ReLU, the mask of the output (see [`conv`]).
struct Finish<'a> {
    bias: &'a [f32],
    relu: bool,
    mask: Option<&'a Volume>,
}

/// A stride-1 3×3×3 convolution of the channel concatenation of `inputs` by `layer` (whose
/// transformed weights are `w`) into `out` (zero, the shape of the inputs with `layer.c_out`
/// channels): biased, rectified if `relu`, zeroed where `mask` (same shape) is not positive.
/// The caller checks [`takes`].
pub(crate) fn conv(
    inputs: &[&Volume],
    layer: &Packed,
    w: &Winograd,
    relu: bool,
    mask: Option<&Volume>,
    out: &mut Volume,
) {
    conv_with(inputs, layer, w, relu, mask, out, false)
}

/// [`conv`] with portable vectors if `portable`.
fn conv_with(
    inputs: &[&Volume],
    layer: &Packed,
    w: &Winograd,
    relu: bool,
    mask: Option<&Volume>,
    out: &mut Volume,
    portable: bool,
) {
    let tiling = Tiling::new(inputs[0]);
    let finish = Finish { bias: &layer.bias, relu, mask };
    let mut planes: Vec<&mut [f32]> =
        out.data.chunks_mut(tiling.plane() * layer.c_out).skip(out.halo).take(out.dims[0]).collect();
    planes.par_chunks_mut(2).enumerate().for_each(|(tx, pair)| {
        BUFFERS.with_borrow_mut(|[v, m, _]| {
            let slab = ConvSlab { inputs, layer, w, finish: &finish, tiling: &tiling, tx, pair, v, m };
            run(slab, portable)
        })
    });
}

/// Slab `tx` of a convolution (see [`conv`]): its output planes `pair` and this thread's buffers
/// `v` and `m`.
struct ConvSlab<'a, 'b> {
    inputs: &'a [&'a Volume],
    layer: &'a Packed,
    w: &'a Winograd,
    finish: &'a Finish<'a>,
    tiling: &'a Tiling,
    tx: usize,
    pair: &'a mut [&'b mut [f32]],
    v: &'a mut Vec<f32>,
    m: &'a mut Vec<f32>,
}

impl Kernel for ConvSlab<'_, '_> {
    type Output = ();
    #[inline(always)]
    fn run<V: Vector>(self) {
        let (c_in, c_out) = (self.layer.c_in, self.layer.c_out);
        for tiles in self.tiling.chunks() {
            let rows = padded(tiles.len());
            let v = sized(self.v, rows * pitch(c_in));
            let m = sized(self.m, rows * pitch(c_out));
            transform_inputs::<V>(self.inputs, self.tiling, self.tx, tiles.clone(), v);
            match c_out / LANES {
                n if n % 4 == 0 => multiply::<V, 2, 4>(v, &self.w.u, rows, c_in, c_out, m),
                n if n % 2 == 0 => multiply::<V, 4, 2>(v, &self.w.u, rows, c_in, c_out, m),
                _ => multiply::<V, 8, 1>(v, &self.w.u, rows, c_in, c_out, m),
            }
            write_outputs::<V>(m, c_out, self.tiling, self.tx, tiles, self.finish, self.pair);
        }
    }
}

/// Transforms the products `m` of tiles `tiles` of slab `tx` to their 2×2×2 output nodes and
/// stores them, finished, into the slab's two output planes `pair`.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn write_outputs<V: Vector>(
    m: &[f32],
    c_out: usize,
    tiling: &Tiling,
    tx: usize,
    tiles: Range<usize>,
    finish: &Finish,
    pair: &mut [&mut [f32]],
) {
    let sz = tiling.stored.1;
    let mut x = [V::zero(); POINTS];
    for (r, t) in tiles.enumerate() {
        let q = tiling.in_plane(t);
        for cb in (0..c_out).step_by(LANES) {
            for (p, x) in x.iter_mut().enumerate() {
                *x = V::load(&m[r * pitch(c_out) + p * c_out + cb..]);
            }
            cube(&mut x, output_transform);
            let bias = V::load(&finish.bias[cb..]);
            for n in 0..8 {
                let (i, j, k) = (n / 4, n / 2 % 2, n % 2);
                let node = q + j * sz + k;
                let mask = finish.mask.map(|mask| {
                    let global = (2 * tx + i + tiling.halo) * tiling.plane() + node;
                    V::load(&mask.data[global * c_out + cb..])
                });
                x[at(i, j, k)].finish(bias, finish.relu, mask).store(&mut pair[i][node * c_out + cb..]);
            }
        }
    }
}

/// Adds the weight gradient of a stride-1 3×3×3 convolution of the channel concatenation of
/// `inputs` with output gradient `dz` to `grad`, laid out as the concatenation of the part
/// matrices of [`Packed::conv`]. The caller checks [`takes`].
pub(crate) fn weight_grad(inputs: &[&Volume], dz: &Volume, grad: &mut [f32]) {
    weight_grad_with(inputs, dz, grad, false)
}

/// [`weight_grad`] with portable vectors if `portable`.
fn weight_grad_with(inputs: &[&Volume], dz: &Volume, grad: &mut [f32], portable: bool) {
    BUFFERS.with_borrow_mut(|[v, y, sums]| run(WeightGrad { inputs, dz, grad, v, y, sums }, portable))
}

/// A weight gradient (see [`weight_grad`]) with this thread's buffers.
struct WeightGrad<'a> {
    inputs: &'a [&'a Volume],
    dz: &'a Volume,
    grad: &'a mut [f32],
    v: &'a mut Vec<f32>,
    y: &'a mut Vec<f32>,
    sums: &'a mut Vec<f32>,
}

impl Kernel for WeightGrad<'_> {
    type Output = ();
    #[inline(always)]
    fn run<V: Vector>(self) {
        let (inputs, dz) = (self.inputs, self.dz);
        let tiling = Tiling::new(dz);
        let (c_in, c_out) = (inputs.iter().map(|v| v.channels).sum::<usize>(), dz.channels);
        let sums = sized(self.sums, POINTS * c_in * c_out);
        sums.fill(0.0);
        for tx in 0..tiling.n[0] {
            for tiles in tiling.chunks() {
                let rows = padded(tiles.len());
                let v = sized(self.v, rows * pitch(c_in));
                let y = sized(self.y, rows * pitch(c_out));
                transform_inputs::<V>(inputs, &tiling, tx, tiles.clone(), v);
                transform_output_gradients::<V>(dz, &tiling, tx, tiles, rows, y);
                if c_out % (2 * LANES) == 0 {
                    accumulate::<V, 8, 2>(v, y, rows, c_in, c_out, sums);
                } else {
                    accumulate::<V, 16, 1>(v, y, rows, c_in, c_out, sums);
                }
            }
        }
        let (mut part, mut c0) = (0, 0);
        let mut x = [V::zero(); POINTS];
        for vol in inputs {
            let c = vol.channels;
            for ci in 0..c {
                for cb in (0..c_out).step_by(LANES) {
                    for (p, x) in x.iter_mut().enumerate() {
                        *x = V::load(&sums[(p * c_in + c0 + ci) * c_out + cb..]);
                    }
                    cube(&mut x, weight_gradient_transform);
                    for tap in 0..27 {
                        x[at(tap / 9, tap / 3 % 3, tap % 3)]
                            .add_to(&mut self.grad[part + row(tap, c, ci) * c_out + cb..]);
                    }
                }
            }
            part += 27 * c * c_out;
            c0 += c;
        }
    }
}

/// Writes `A dy Aᵀ` of the 2×2×2 output gradients of tiles `tiles` of slab `tx` into rows `0..`
/// of `y` (`[row][point][c_out]`, rows [`pitch`] apart), zeros in the padding rows.
#[inline(always)]
fn transform_output_gradients<V: Vector>(
    dz: &Volume,
    tiling: &Tiling,
    tx: usize,
    tiles: Range<usize>,
    rows: usize,
    y: &mut [f32],
) {
    let (c, sz) = (dz.channels, tiling.stored.1);
    let plane = tiling.plane();
    let len = tiles.len();
    let mut x = [V::zero(); POINTS];
    for (r, t) in tiles.enumerate() {
        let corner = (2 * tx + tiling.halo) * plane + tiling.in_plane(t);
        for cb in (0..c).step_by(LANES) {
            for n in 0..8 {
                let (i, j, k) = (n / 4, n / 2 % 2, n % 2);
                x[at(i, j, k)] = V::load(&dz.data[(corner + i * plane + j * sz + k) * c + cb..]);
            }
            cube(&mut x, output_gradient_transform);
            for (p, x) in x.iter().enumerate() {
                x.store(&mut y[r * pitch(c) + p * c + cb..]);
            }
        }
    }
    y[len * pitch(c)..rows * pitch(c)].fill(0.0);
}

/// `sums[p] += v[p]ᵀ · y[p]` for every point `p`: `c_in × rows` by `rows × c_out`, in register
/// blocks of `R` input channels × `B` vectors of output channels (`v` and `y` are
/// `[row][point][channel]`, rows [`pitch`] apart).
#[inline(always)]
fn accumulate<V: Vector, const R: usize, const B: usize>(
    v: &[f32],
    y: &[f32],
    rows: usize,
    c_in: usize,
    c_out: usize,
    sums: &mut [f32],
) {
    assert!(y.len() >= rows * pitch(c_out), "rows beyond the transformed gradients");
    for p in 0..POINTS {
        let sp = &mut sums[p * c_in * c_out..][..c_in * c_out];
        for cb in (0..c_out).step_by(B * LANES) {
            assert!(cb + B * LANES <= c_out, "register block beyond the output channels");
            for ci in (0..c_in).step_by(R) {
                let mut acc = [[V::zero(); B]; R];
                for (r, acc) in acc.iter_mut().enumerate() {
                    for (b, a) in acc.iter_mut().enumerate() {
                        *a = V::load(&sp[(ci + r) * c_out + cb + b * LANES..]);
                    }
                }
                for t in 0..rows {
                    let at_y = t * pitch(c_out) + p * c_out + cb;
                    let mut d = [V::zero(); B];
                    for (b, d) in d.iter_mut().enumerate() {
                        // SAFETY: at_y + (b + 1) · LANES ≤ t · pitch + (p + 1) · c_out ≤
                        // rows · pitch ≤ y.len() (asserted above).
                        *d = unsafe { V::load_ptr(y.as_ptr().add(at_y + b * LANES)) };
                    }
                    let xs = &v[t * pitch(c_in) + p * c_in + ci..][..R];
                    for (acc, &x) in acc.iter_mut().zip(xs) {
                        for (a, d) in acc.iter_mut().zip(d) {
                            *a = a.fma(x, d);
                        }
                    }
                }
                for (r, acc) in acc.iter().enumerate() {
                    for (b, a) in acc.iter().enumerate() {
                        a.store(&mut sp[(ci + r) * c_out + cb + b * LANES..]);
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `n` seeded values in [-1, 1) (a linear congruential generator).
    fn seeded(n: usize, seed: u64) -> Vec<f32> {
        let mut state = seed;
        (0..n)
            .map(|_| {
                state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                (state >> 40) as f32 / (1u64 << 23) as f32 - 1.0
            })
            .collect()
    }

    /// A volume of seeded values on the interior, zero halo of 1.
    fn random_volume(dims: [usize; 3], channels: usize, seed: u64) -> Volume {
        let mut v = Volume::zeros(dims, 1, channels);
        let mut values = seeded(dims.iter().product::<usize>() * channels, seed).into_iter();
        for i in 0..dims[0] {
            for j in 0..dims[1] {
                for k in 0..dims[2] {
                    let at = v.node(i, j, k) * channels;
                    v.data[at..at + channels].iter_mut().for_each(|x| *x = values.next().unwrap());
                }
            }
        }
        v
    }

    /// Whether every value of the halo nodes of `v` is zero.
    fn halo_is_zero(v: &Volume) -> bool {
        let (sy, sz) = v.stored_yz();
        let inside = |n: usize, d: usize| n >= v.halo && n < d + v.halo;
        v.data.chunks_exact(v.channels).enumerate().all(|(node, values)| {
            let (i, j, k) = (node / (sy * sz), node / sz % sy, node % sz);
            (inside(i, v.dims[0]) && inside(j, v.dims[1]) && inside(k, v.dims[2])) || values.iter().all(|x| *x == 0.0)
        })
    }

    /// The storage node of interior node `(i, j, k)` moved by tap `(a, b, c)` of a 3×3×3 kernel
    /// (offsets −1, 0, 1 along each axis).
    fn tap_node(v: &Volume, [i, j, k]: [usize; 3], [a, b, c]: [usize; 3]) -> usize {
        v.node(i + a, j + b, k + c) - v.plane_nodes() - v.stored_yz().1 - 1
    }

    /// The direct convolution, node by node: `Σ w[co][ci][a][b][c] · x[i + a - 1][j + b - 1][k + c - 1][ci]`.
    fn direct(inputs: &[&Volume], weight: &[f32], bias: &[f32], c_out: usize) -> Vec<f32> {
        let [nx, ny, nz] = inputs[0].dims;
        let c_in: usize = inputs.iter().map(|v| v.channels).sum();
        let mut out = vec![0.0f64; nx * ny * nz * c_out];
        for i in 0..nx {
            for j in 0..ny {
                for k in 0..nz {
                    for co in 0..c_out {
                        let mut s = f64::from(bias[co]);
                        let mut c0 = 0;
                        for v in inputs {
                            for ci in 0..v.channels {
                                for tap in 0..27 {
                                    let (a, b, c) = (tap / 9, tap / 3 % 3, tap % 3);
                                    let node = tap_node(v, [i, j, k], [a, b, c]);
                                    let x = v.data[node * v.channels + ci];
                                    s += f64::from(weight[(co * c_in + c0 + ci) * 27 + tap]) * f64::from(x);
                                }
                            }
                            c0 += v.channels;
                        }
                        out[((i * ny + j) * nz + k) * c_out + co] = s;
                    }
                }
            }
        }
        out.into_iter().map(|v| v as f32).collect()
    }

    /// Both builds of the loops: AVX-512 (where the CPU has it) and portable.
    const BUILDS: [bool; 2] = [false, true];

    #[test]
    fn convolution_equals_the_direct_sum() {
        // One chunk of 3 tiles per slab (padded rows), and two chunks of 28 per slab.
        for dims in [[4, 6, 2], [2, 16, 14]] {
            let (a, b) = (random_volume(dims, 16, 1), random_volume(dims, 32, 2));
            let c_out = 32;
            let weight = seeded(c_out * 48 * 27, 3);
            let bias: Vec<f32> = (0..c_out).map(|c| c as f32 * 0.01 - 0.1).collect();
            let layer = Packed::conv(&weight, &bias, c_out, &[16, 32], 27).unwrap();
            let inputs = [&a, &b];
            assert!(takes(&inputs, &a));
            let want = direct(&inputs, &weight, &bias, c_out);
            let mask = random_volume(dims, c_out, 4);
            for portable in BUILDS {
                let w = Winograd::with(&layer.parts, c_out, portable).expect("16-multiples take the Winograd loops");
                for (relu, mask) in [(false, None), (true, None), (false, Some(&mask))] {
                    let mut out = Volume::zeros(dims, 1, c_out);
                    conv_with(&inputs, &layer, &w, relu, mask, &mut out, portable);
                    let mut checked = 0;
                    for i in 0..dims[0] {
                        for j in 0..dims[1] {
                            for k in 0..dims[2] {
                                for co in 0..c_out {
                                    let node = out.node(i, j, k);
                                    let mut y = want[((i * dims[1] + j) * dims[2] + k) * c_out + co];
                                    if relu {
                                        y = y.max(0.0);
                                    }
                                    if mask.is_some_and(|m| m.data[node * c_out + co] <= 0.0) {
                                        y = 0.0;
                                    }
                                    let got = out.data[node * c_out + co];
                                    let at = format!("({i},{j},{k}) ch {co}, portable {portable}");
                                    assert!((got - y).abs() <= 1e-4 * (1.0 + y.abs()), "{at}: {got} vs {y}");
                                    checked += 1;
                                }
                            }
                        }
                    }
                    assert_eq!(checked, dims.iter().product::<usize>() * c_out);
                    assert!(halo_is_zero(&out), "the halo stays zero");
                }
            }
        }
    }

    #[test]
    fn weight_gradient_equals_the_direct_sum() {
        for dims in [[2, 4, 6], [2, 16, 14]] {
            let (a, b) = (random_volume(dims, 32, 5), random_volume(dims, 16, 6));
            let dz = random_volume(dims, 16, 7);
            let inputs = [&a, &b];
            assert!(takes(&inputs, &dz));
            for portable in BUILDS {
                let mut grad = vec![1.0; 27 * 48 * 16];
                weight_grad_with(&inputs, &dz, &mut grad, portable);
                // Direct: d w[tap][ci][co] = Σ_nodes x[node + tap - 1][ci] · dz[node][co], in the part layout.
                let mut part = 0;
                for v in inputs {
                    let c = v.channels;
                    for tap in 0..27 {
                        let (ta, tb, tc) = (tap / 9, tap / 3 % 3, tap % 3);
                        for ci in 0..c {
                            for co in 0..16 {
                                let mut s = 0.0f64;
                                for i in 0..dims[0] {
                                    for j in 0..dims[1] {
                                        for k in 0..dims[2] {
                                            let node = tap_node(v, [i, j, k], [ta, tb, tc]);
                                            let d = dz.data[dz.node(i, j, k) * 16 + co];
                                            s += f64::from(v.data[node * c + ci]) * f64::from(d);
                                        }
                                    }
                                }
                                let got = f64::from(grad[part + row(tap, c, ci) * 16 + co] - 1.0);
                                let at = format!("tap {tap} ch {ci}->{co}, portable {portable}");
                                assert!((got - s).abs() <= 1e-4 * (1.0 + s.abs()), "{at}: {got} vs {s}");
                            }
                        }
                    }
                    part += 27 * c * 16;
                }
            }
        }
    }

    #[test]
    fn other_shapes_are_left_to_the_direct_loops() {
        let dims = [4, 4, 4];
        assert!(Winograd::new(&[(8, vec![0.0; 27 * 8 * 16])], 16).is_none());
        assert!(Winograd::new(&[(16, vec![0.0; 27 * 16 * 8])], 8).is_none());
        let (v, odd) = (random_volume(dims, 16, 1), random_volume([4, 3, 4], 16, 1));
        assert!(!takes(&[&odd], &odd));
        assert!(!takes(&[&v], &random_volume(dims, 8, 1)));
        assert!(!takes(&[&v], &Volume::zeros(dims, 0, 16)));
    }
}
