//! Simulated intraoperative clouds: what a camera looking along a direction
//! sees of a deformed surface, with noise and outliers.

use mesh::sampling::sample_visible;
use mesh::{Point, TriSurface};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, Normal};

use anyhow::{anyhow, Result};
use scenario::registration::CameraSpec;

/// A cloud of `camera.points` points on the visible part of `surface` (outward oriented), each
/// moved by isotropic Gaussian noise, plus `camera.outliers` × `camera.points` points uniform in
/// the surface's bounding box grown by 10 %; reproducible from the camera's seed.
pub fn simulate_cloud(surface: &TriSurface, camera: &CameraSpec) -> Result<Vec<Point>> {
    let seed = camera.seed;
    camera.validate().map_err(|e| anyhow!("the simulated camera's {e}"))?;
    let samples = sample_visible(surface, camera.view, camera.points, seed)?;
    let mut rng = StdRng::seed_from_u64(seed ^ 0x9e37_79b9_7f4a_7c15);
    let noise = Normal::new(0.0, camera.noise).map_err(|e| anyhow!("camera noise: {e}"))?;
    let mut cloud: Vec<Point> = samples.iter().map(|s| s.point.map(|x| x + noise.sample(&mut rng))).collect();
    let (lo, hi) = mesh::bounds(&surface.vertices);
    let extra = (camera.outliers * camera.points as f64).round() as usize;
    for _ in 0..extra {
        cloud.push(std::array::from_fn(|d| {
            let pad = 0.05 * (hi[d] - lo[d]);
            rng.random_range(lo[d] - pad..=hi[d] + pad)
        }));
    }
    Ok(cloud)
}
