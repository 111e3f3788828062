//! Masked MSE and error metrics against hand computations; input corruption.

mod common;

use augsim_learn::data::corrupt::item_rng;
use augsim_learn::training::metrics::{masked_mse_values, mean_euclidean_error};
use augsim_learn::{Corruption, ErrorStats, FieldUnit, GridShape, Sparsity};

#[test]
fn masked_mse_matches_hand_computation() {
    // Grid 2x1x1: node 0 inside, node 1 outside; two samples.
    let grid = GridShape::new(2, 1, 1);
    // [sample, channel, node]
    let pred = vec![1.0, 5.0, 2.0, 5.0, 3.0, 5.0, /* sample 2 */ 0.0, 9.0, 0.0, 9.0, 1.0, 9.0];
    let target = vec![0.0, 0.0, 0.0, 0.0, 0.0, 0.0, /* sample 2 */ 0.0, 0.0, 0.0, 0.0, -1.0, 0.0];
    let masks = vec![1u8, 0, 1, 0];
    // Sample 1, node 0: 1 + 4 + 9 = 14; sample 2, node 0: 0 + 0 + 4 = 4; mean over 2 nodes = 9.
    assert_eq!(masked_mse_values(&pred, &target, &masks, grid).unwrap(), 9.0);

    #[cfg(feature = "cpu-burn")]
    {
        // burn's loss, as its engine trains on.
        use augsim_learn::net::burn_unet::masked_mse;
        use burn::tensor::{Device, Tensor, TensorData};
        let device = Device::flex();
        let t = |v: &Vec<f32>| Tensor::<5>::from_data(TensorData::new(v.clone(), [2, 3, 2, 1, 1]), &device);
        let m = Tensor::<5>::from_data(TensorData::new(vec![1.0f32, 0.0, 1.0, 0.0], [2, 1, 2, 1, 1]), &device);
        let loss: f32 = masked_mse(t(&pred), t(&target), m).into_scalar();
        assert_eq!(loss, 9.0);
    }

    // Per-sample mean Euclidean error: sqrt(14) for sample 1.
    let e = mean_euclidean_error(&pred[..6], &target[..6], &masks[..2], grid).unwrap();
    assert!((e - 14f64.sqrt()).abs() < 1e-12);
    assert!(mean_euclidean_error(&pred[..6], &target[..6], &[0, 0], grid).is_err(), "empty mask");
    assert!(mean_euclidean_error(&pred[..5], &target[..6], &masks[..2], grid).is_err(), "lengths");
}

#[test]
fn error_stats_by_hand() {
    let s = ErrorStats::from_errors(&[1.0, 3.0, 2.0, 6.0]).unwrap();
    assert_eq!(s.mean, 3.0);
    // Population variance: (4 + 0 + 1 + 9) / 4 = 3.5.
    assert!((s.std - 3.5f64.sqrt()).abs() < 1e-15);
    assert_eq!(s.max, 6.0);
    assert_eq!(s.worst, 3);
    assert!(ErrorStats::from_errors(&[]).is_err());
}

fn nonzero_nodes(input: &[f32], grid: GridShape) -> Vec<usize> {
    let n = grid.nodes();
    (0..n).filter(|&v| (0..3).any(|c| input[c * n + v] != 0.0)).collect()
}

/// An input whose nonzero nodes are the whole plane z = nz-1 (a "visible upper face").
fn face_input(grid: GridShape) -> Vec<f32> {
    let mut input = vec![0f32; grid.field_len()];
    for i in 0..grid.nx {
        for j in 0..grid.ny {
            for c in 0..3 {
                input[grid.field_index(c, i, j, grid.nz - 1)] = 0.01 * (c + 1) as f32;
            }
        }
    }
    input
}

#[test]
fn patch_sparsity_keeps_a_contiguous_patch_of_the_requested_size() {
    let grid = GridShape::new(12, 10, 4);
    let input = face_input(grid);
    let corruption = Corruption { sparsity: Some(Sparsity::Patch { min_nodes: 13, max_nodes: 40 }), noise_std: 0.0 };
    let mut sizes = Vec::new();
    for item in 0..30 {
        let mut x = input.clone();
        corruption.apply(&mut x, grid, &mut item_rng(5, 0, item)).unwrap();
        let kept = nonzero_nodes(&x, grid);
        assert!((13..=40).contains(&kept.len()), "{}", kept.len());
        sizes.push(kept.len());
        // Kept values are unchanged, the rest zero.
        for &v in &kept {
            for c in 0..3 {
                assert_eq!(x[c * grid.nodes() + v], input[c * grid.nodes() + v]);
            }
        }
        // Contiguous: every kept node has a kept 4-neighbour in the face (patch of >= 2 nodes
        // of nearest nodes around a centre is connected in the plane).
        let set: std::collections::HashSet<usize> = kept.iter().copied().collect();
        for &v in &kept {
            let [i, j, k] = grid.node_coords(v);
            let neighbours = [(1i64, 0i64), (-1, 0), (0, 1), (0, -1)]
                .iter()
                .filter(|(di, dj)| {
                    let (a, b) = (i as i64 + di, j as i64 + dj);
                    a >= 0
                        && b >= 0
                        && (a as usize) < grid.nx
                        && (b as usize) < grid.ny
                        && set.contains(&grid.node_index(a as usize, b as usize, k))
                })
                .count();
            assert!(neighbours > 0, "isolated kept node {v}");
        }
    }
    assert!(sizes.iter().min() != sizes.iter().max(), "sizes should vary: {sizes:?}");
    // Same generator, same result.
    let (mut a, mut b) = (input.clone(), input.clone());
    corruption.apply(&mut a, grid, &mut item_rng(9, 1, 2)).unwrap();
    corruption.apply(&mut b, grid, &mut item_rng(9, 1, 2)).unwrap();
    assert_eq!(a, b);
}

#[test]
fn subset_sparsity_keeps_the_requested_fraction() {
    let grid = GridShape::new(10, 10, 3);
    let input = face_input(grid);
    let corruption =
        Corruption { sparsity: Some(Sparsity::Subset { min_fraction: 0.25, max_fraction: 0.25 }), noise_std: 0.0 };
    let mut x = input.clone();
    corruption.apply(&mut x, grid, &mut item_rng(1, 2, 3)).unwrap();
    assert_eq!(nonzero_nodes(&x, grid).len(), 25);
}

#[test]
fn noise_touches_only_visible_nodes_with_the_requested_spread() {
    let grid = GridShape::new(40, 40, 2);
    let input = face_input(grid);
    let sigma = 1e-3;
    let corruption = Corruption { sparsity: None, noise_std: sigma };
    let mut x = input.clone();
    corruption.apply(&mut x, grid, &mut item_rng(3, 0, 0)).unwrap();
    let n = grid.nodes();
    let visible = nonzero_nodes(&input, grid);
    let mut deltas = Vec::new();
    for v in 0..n {
        for c in 0..3 {
            let d = (x[c * n + v] - input[c * n + v]) as f64;
            if visible.contains(&v) {
                deltas.push(d);
            } else {
                assert_eq!(d, 0.0, "hidden node {v} changed");
            }
        }
    }
    let m = deltas.len() as f64;
    let mean = deltas.iter().sum::<f64>() / m;
    let std = (deltas.iter().map(|d| (d - mean).powi(2)).sum::<f64>() / m).sqrt();
    // 4800 draws: the sample std is within a few percent of sigma, the mean near 0.
    assert!((std / sigma - 1.0).abs() < 0.06, "std {std}");
    assert!(mean.abs() < 4.0 * sigma / m.sqrt(), "mean {mean}");

    // Invalid parameters are rejected.
    let bad = Corruption { sparsity: Some(Sparsity::Patch { min_nodes: 5, max_nodes: 2 }), noise_std: 0.0 };
    assert!(bad.apply(&mut x, grid, &mut item_rng(0, 0, 0)).is_err());
    assert!(Corruption { sparsity: None, noise_std: -1.0 }.validate().is_err());
}

#[test]
fn a_noise_in_the_wrong_unit_is_refused() {
    // Displacements of about 5 mm: 2 mm of noise is a noisy camera; 1 (meaning 1 mm) is a metre.
    let rms = 5e-3;
    let noise = |std: f64| Corruption { sparsity: None, noise_std: std };
    assert!(noise(2e-3).check_scale(rms, FieldUnit::Metre).is_ok());
    let e = noise(1.0).check_scale(rms, FieldUnit::Metre).unwrap_err().to_string();
    assert!(e.contains("a noise of 1 m on inputs whose RMS is 5.000e-3 m") && e.contains("1 mm is 0.001"), "{e}");
    // Forces of about 1 N: half a newton of noise is kept.
    assert!(noise(0.5).check_scale(1.0, FieldUnit::Newton).is_ok());
    assert!(noise(50.0).check_scale(1.0, FieldUnit::Newton).is_err());
}

/// A patch at least as large as every input's nonzero nodes keeps them all: refused, as `train`
/// and `eval` refuse it; so is a range reaching past them, whose largest draws keep them all.
#[test]
fn a_patch_that_keeps_every_input_node_is_refused() {
    let grid = GridShape::new(6, 5, 4);
    let samples = common::synthetic_samples(grid, 0, 3);
    let most = (0..3).map(|p| nonzero_nodes(samples.input(p), grid).len()).max().unwrap();
    let patch = |min_nodes: usize, max_nodes: usize| Corruption {
        sparsity: Some(Sparsity::Patch { min_nodes, max_nodes }),
        noise_std: 0.0,
    };
    assert!(patch(most - 1, most).check_sparsity(&samples).is_ok());
    let e = patch(most, most).check_sparsity(&samples).unwrap_err().to_string();
    assert!(e.contains(&format!("keeps every input node: the samples have at most {most}")), "{e}");
    // 1..=2·most: the upper half of the draws would keep every node.
    let e = patch(1, 2 * most).check_sparsity(&samples).unwrap_err().to_string();
    assert!(e.contains(&format!("reaches past the samples' input nodes (at most {most}): 50 % of the draws")), "{e}");
    assert!(Corruption::none().check_sparsity(&samples).is_ok());
}
