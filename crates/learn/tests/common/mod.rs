//! Synthetic samples for the tests: a force on a small patch of nodes, and a target that is a
//! Gaussian blur of it (a linear, translation-invariant response a U-Net can learn), inside an
//! ellipsoidal mask.

#![allow(dead_code)]

use augsim_learn::{GridShape, Progress, Sample, Samples};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

/// Networks compared between engines: (base channels, depth, kernel size, grid), from a deep
/// network on an odd grid to one without levels and a 1³ kernel.
pub const NETWORK_SHAPES: [(usize, usize, usize, [usize; 3]); 5] =
    [(4, 3, 3, [21, 23, 21]), (3, 2, 3, [5, 6, 7]), (2, 1, 5, [7, 4, 6]), (3, 0, 3, [4, 5, 3]), (2, 2, 1, [8, 8, 8])];

/// An ellipsoid filling most of the grid.
pub fn ellipsoid_mask(grid: GridShape) -> Vec<u8> {
    let [nx, ny, nz] = grid.dims();
    let mut m = vec![0u8; grid.nodes()];
    for i in 0..nx {
        for j in 0..ny {
            for k in 0..nz {
                let r = |a: usize, n: usize| (a as f64 - (n as f64 - 1.0) / 2.0) / (n as f64 / 2.0);
                if r(i, nx).powi(2) + r(j, ny).powi(2) + r(k, nz).powi(2) <= 1.0 {
                    m[grid.node_index(i, j, k)] = 1;
                }
            }
        }
    }
    m
}

/// Sample `index`: a force (N) on a 2x2x2 patch inside the mask; target (m) a blurred copy.
pub fn synthetic_sample(grid: GridShape, index: u64) -> Sample {
    let mut rng = StdRng::seed_from_u64(1000 + index);
    let mask = ellipsoid_mask(grid);
    let n = grid.nodes();
    let [nx, ny, nz] = grid.dims();
    let mut input = vec![0f32; grid.field_len()];
    let center = loop {
        let c = [rng.random_range(1..nx - 2), rng.random_range(1..ny - 2), rng.random_range(1..nz - 2)];
        if mask[grid.node_index(c[0], c[1], c[2])] == 1 {
            break c;
        }
    };
    let force: [f32; 3] = [rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0)];
    for di in 0..2 {
        for dj in 0..2 {
            for dk in 0..2 {
                for c in 0..3 {
                    input[grid.field_index(c, center[0] + di, center[1] + dj, center[2] + dk)] = force[c];
                }
            }
        }
    }
    let mut target = vec![0f32; grid.field_len()];
    for i in 0..nx {
        for j in 0..ny {
            for k in 0..nz {
                let d2 = [i, j, k].iter().zip(center).map(|(&a, b)| (a as f64 - b as f64 - 0.5).powi(2)).sum::<f64>();
                let w = (-d2 / 4.0).exp() as f32;
                for c in 0..3 {
                    target[grid.field_index(c, i, j, k)] = 0.01 * w * force[c];
                }
            }
        }
    }
    let _ = n;
    Sample { index, input, target, mask }
}

/// `count` synthetic samples with indices `first..first+count`.
pub fn synthetic_samples(grid: GridShape, first: u64, count: usize) -> Samples {
    let mut s = Samples::new(grid);
    for i in 0..count as u64 {
        s.push(&synthetic_sample(grid, first + i)).unwrap();
    }
    s
}
pub mod reference;

/// Seeded uniform values in `[lo, hi)`: the same on every run.
pub fn uniform(rng: &mut StdRng, n: usize, lo: f32, hi: f32) -> Vec<f32> {
    (0..n).map(|_| rng.random_range(lo..hi)).collect()
}

/// The seeded network of `config` with every weight and bias moved by about ±0.1 (non-zero
/// biases): one Adam step of rate 0.1 along seeded random gradients, which moves each parameter
/// by about the rate.
pub fn perturbed(config: &augsim_learn::UNetConfig) -> augsim_learn::UNet {
    let mut net = augsim_learn::UNet::new(config, 7).unwrap();
    let mut rng = StdRng::seed_from_u64(8);
    let grads = augsim_learn::Gradients(
        net.named_parameters().iter().map(|(_, v)| Some(uniform(&mut rng, v.len(), -1.0, 1.0))).collect(),
    );
    augsim_learn::training::adam::Adam::new(grads.0.len()).step(0.1, &mut net, &grads).unwrap();
    net
}

/// A seeded batch `(x, y, mask)` of `batch` samples: uniform inputs and targets, a mask with
/// zeros.
pub fn batch_values(batch: usize, grid: GridShape) -> (Vec<f32>, Vec<f32>, Vec<f32>) {
    let mut rng = StdRng::seed_from_u64(9);
    let n = batch * grid.nodes();
    let (x, y) = (uniform(&mut rng, 3 * n, -1.0, 1.0), uniform(&mut rng, 3 * n, -1.0, 1.0));
    let mask = uniform(&mut rng, n, -1.0, 1.0).iter().map(|v| if *v > -0.5 { 1.0 } else { 0.0 }).collect();
    (x, y, mask)
}

/// A progress that keeps the lines it is told.
#[derive(Default)]
pub struct Lines(pub std::sync::Mutex<Vec<String>>);

impl Progress for Lines {
    fn advance(&self, _: u64, _: u64, _: &str) {}
    fn line(&self, text: &str) {
        self.0.lock().unwrap().push(text.to_string());
    }
}
