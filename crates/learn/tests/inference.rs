//! The repacked CPU inference network computes what a plain reference forward pass computes.

mod common;

use augsim_learn::{GridShape, UNetConfig};
use common::{batch_values, perturbed, reference};

#[test]
fn inference_network_matches_the_reference_forward_pass() {
    // With the channel counts of the SIMD and Winograd loops (on AVX-512 CPUs).
    for (base_channels, depth, kernel_size, grid) in common::NETWORK_SHAPES.into_iter().chain([(16, 1, 3, [8, 8, 8])]) {
        let config = UNetConfig { base_channels, depth, kernel_size, ..UNetConfig::default() };
        let net = perturbed(&config);
        let g = GridShape::new(grid[0], grid[1], grid[2]);
        let (input, _, _) = batch_values(1, g);
        let expected = reference::forward(
            &config,
            &reference::params(&net),
            &input.iter().map(|v| f64::from(*v)).collect::<Vec<_>>(),
            g,
        );
        let fast = net.to_inference().unwrap();
        let out = fast.forward(&input, g).unwrap();
        assert_eq!(out.len(), expected.len());
        let scale = expected.iter().fold(0f64, |m, v| m.max(v.abs()));
        let diff = out.iter().zip(&expected).fold(0f64, |m, (a, b)| m.max((f64::from(*a) - b).abs()));
        assert!(scale > 0.0);
        assert!(diff <= 1e-5 * scale.max(1.0), "{config:?} on {g}: max difference {diff:e} (scale {scale:e})");
        let e = fast.forward(&input[1..], g).unwrap_err().to_string();
        assert!(e.contains("expected 3 channels"), "{e}");
    }
}
