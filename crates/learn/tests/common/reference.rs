//! A plain reference U-Net forward pass in `f64`, written from the architecture of
//! `docs/method.md` with direct loops: what the repacked engines must compute.

use std::collections::HashMap;

use augsim_learn::{GridShape, UNet, UNetConfig};

/// A field `[channel, x, y, z]`.
#[derive(Clone)]
pub struct Field {
    pub channels: usize,
    pub dims: [usize; 3],
    pub values: Vec<f64>,
}

impl Field {
    fn zeros(channels: usize, dims: [usize; 3]) -> Field {
        Field { channels, dims, values: vec![0.0; channels * dims[0] * dims[1] * dims[2]] }
    }

    fn at(&self, c: usize, i: usize, j: usize, k: usize) -> usize {
        ((c * self.dims[0] + i) * self.dims[1] + j) * self.dims[2] + k
    }
}

/// Parameters by path, in `f64`.
pub type Params = HashMap<String, Vec<f64>>;

/// The parameters of `net` by path.
pub fn params(net: &UNet) -> Params {
    net.named_parameters().into_iter().map(|(n, v)| (n, v.into_iter().map(f64::from).collect())).collect()
}

/// Stride-1 convolution `k³` with zero padding `k / 2`, optionally rectified.
fn conv(x: &Field, p: &Params, name: &str, c_out: usize, k: usize, relu: bool) -> Field {
    let (w, b) = (&p[&format!("{name}.weight")], &p[&format!("{name}.bias")]);
    let mut out = Field::zeros(c_out, x.dims);
    let h = (k / 2) as isize;
    let [nx, ny, nz] = x.dims.map(|n| n as isize);
    for (co, &bias) in b.iter().enumerate() {
        for i in 0..nx {
            for j in 0..ny {
                for l in 0..nz {
                    let mut s = bias;
                    for ci in 0..x.channels {
                        for a in 0..k as isize {
                            for bb in 0..k as isize {
                                for c in 0..k as isize {
                                    let (u, v, t) = (i + a - h, j + bb - h, l + c - h);
                                    if u < 0 || v < 0 || t < 0 || u >= nx || v >= ny || t >= nz {
                                        continue;
                                    }
                                    let wi =
                                        (((co * x.channels + ci) * k + a as usize) * k + bb as usize) * k + c as usize;
                                    s += w[wi] * x.values[x.at(ci, u as usize, v as usize, t as usize)];
                                }
                            }
                        }
                    }
                    let at = out.at(co, i as usize, j as usize, l as usize);
                    out.values[at] = if relu { s.max(0.0) } else { s };
                }
            }
        }
    }
    out
}

/// 2×2×2 stride-2 convolution, weights `[c_out, c_in, 2, 2, 2]`.
fn down(x: &Field, p: &Params, name: &str) -> Field {
    let (w, b) = (&p[&format!("{name}.weight")], &p[&format!("{name}.bias")]);
    let c_out = b.len();
    let mut out = Field::zeros(c_out, x.dims.map(|n| n / 2));
    let [mx, my, mz] = out.dims;
    for (co, &bias) in b.iter().enumerate() {
        for (i, j, l) in (0..mx).flat_map(|i| (0..my).flat_map(move |j| (0..mz).map(move |l| (i, j, l)))) {
            let mut s = bias;
            for ci in 0..x.channels {
                for t in 0..8 {
                    let (a, bb, c) = (t / 4, t / 2 % 2, t % 2);
                    s += w[(co * x.channels + ci) * 8 + t] * x.values[x.at(ci, 2 * i + a, 2 * j + bb, 2 * l + c)];
                }
            }
            let at = out.at(co, i, j, l);
            out.values[at] = s;
        }
    }
    out
}

/// 2×2×2 stride-2 transposed convolution, weights `[c_in, c_out, 2, 2, 2]`.
fn up(x: &Field, p: &Params, name: &str) -> Field {
    let (w, b) = (&p[&format!("{name}.weight")], &p[&format!("{name}.bias")]);
    let c_out = b.len();
    let mut out = Field::zeros(c_out, x.dims.map(|n| 2 * n));
    let [nx, ny, nz] = out.dims;
    for (co, &bias) in b.iter().enumerate() {
        for (i, j, l) in (0..nx).flat_map(|i| (0..ny).flat_map(move |j| (0..nz).map(move |l| (i, j, l)))) {
            let t = (i % 2) * 4 + (j % 2) * 2 + l % 2;
            let mut s = bias;
            for ci in 0..x.channels {
                s += w[(ci * c_out + co) * 8 + t] * x.values[x.at(ci, i / 2, j / 2, l / 2)];
            }
            let at = out.at(co, i, j, l);
            out.values[at] = s;
        }
    }
    out
}

/// The channel concatenation of `a` and `b`.
fn cat(a: &Field, b: &Field) -> Field {
    Field { channels: a.channels + b.channels, dims: a.dims, values: [&a.values[..], &b.values[..]].concat() }
}

/// The network of `config` with parameters `p` on `input` (`[in_channels, nx, ny, nz]`):
/// zero-padded to a multiple of `2^depth`, run, cropped back.
pub fn forward(config: &UNetConfig, p: &Params, input: &[f64], grid: GridShape) -> Vec<f64> {
    let (k, depth) = (config.kernel_size, config.depth);
    let ch = |l: usize| config.base_channels << l;
    let padded = grid.dims().map(|n| config.padded(n));
    let mut h = Field::zeros(config.in_channels, padded);
    let n = grid.nodes();
    for c in 0..config.in_channels {
        for node in 0..n {
            let [i, j, l] = grid.node_coords(node);
            let at = h.at(c, i, j, l);
            h.values[at] = input[c * n + node];
        }
    }
    let block = |x: &Field, name: &str, c_out: usize| {
        conv(&conv(x, p, &format!("{name}.conv1"), c_out, k, true), p, &format!("{name}.conv2"), c_out, k, true)
    };
    let mut skips = Vec::new();
    for l in 0..depth {
        h = block(&h, &format!("encoder.{l}"), ch(l));
        skips.push(h.clone());
        h = down(&h, p, &format!("down.{l}"));
    }
    h = block(&h, "bottleneck", ch(depth));
    for l in (0..depth).rev() {
        h = up(&h, p, &format!("up.{l}"));
        h = block(&cat(&h, &skips[l]), &format!("decoder.{l}"), ch(l));
    }
    let out = conv(&h, p, "head", config.out_channels, 1, false);
    let mut field = vec![0.0; config.out_channels * n];
    for c in 0..config.out_channels {
        for node in 0..n {
            let [i, j, l] = grid.node_coords(node);
            field[c * n + node] = out.values[out.at(c, i, j, l)];
        }
    }
    field
}

/// The masked MSE of the reference forward pass on a batch (as `loss_and_gradients` takes it).
pub fn loss(config: &UNetConfig, p: &Params, x: &[f32], y: &[f32], mask: &[f32], batch: usize, grid: GridShape) -> f64 {
    let n = grid.nodes();
    let (c_in, c_out) = (config.in_channels, config.out_channels);
    let mut total = 0.0;
    for s in 0..batch {
        let input: Vec<f64> = x[s * c_in * n..][..c_in * n].iter().map(|v| f64::from(*v)).collect();
        let out = forward(config, p, &input, grid);
        for node in 0..n {
            let m = f64::from(mask[s * n + node]);
            for c in 0..c_out {
                let d = out[c * n + node] - f64::from(y[(s * c_out + c) * n + node]);
                total += m * d * d;
            }
        }
    }
    total / mask.iter().map(|m| f64::from(*m)).sum::<f64>().max(1.0)
}
