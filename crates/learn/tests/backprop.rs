//! The hand-written backward pass gives the derivatives of the loss: each parameter's gradient
//! against central differences of a plain `f64` reference forward pass along a random
//! direction. (Its comparison with burn's autodiff is in `burn_engine.rs`, `cpu-burn` feature.)

mod common;

use augsim_learn::net::backprop::loss_and_gradients;
use augsim_learn::{GridShape, UNet, UNetConfig};
use common::{batch_values, perturbed, reference, uniform};
use rand::rngs::StdRng;
use rand::SeedableRng;

/// Compares every gradient of `net` with central differences; returns the number of parameters
/// that have a gradient.
fn check_derivatives(net: &UNet, batch: usize, grid: GridShape) -> usize {
    let config = net.config().clone();
    let (x, y, mask) = batch_values(batch, grid);
    let (loss, grads) = loss_and_gradients(net, &x, &y, &mask, batch, grid).unwrap();
    let p = reference::params(net);
    let expected = reference::loss(&config, &p, &x, &y, &mask, batch, grid);
    assert!((loss - expected).abs() <= 1e-5 * expected, "loss {loss} against the reference {expected}");
    let mut rng = StdRng::seed_from_u64(3);
    // Small enough that few ReLU inputs change sign between the two evaluations.
    let h = 1e-7;
    for ((name, _), grad) in net.named_parameters().iter().zip(&grads.0) {
        let Some(grad) = grad else { continue };
        let direction = uniform(&mut rng, grad.len(), -1.0, 1.0);
        let moved = |sign: f64| {
            let mut q = p.clone();
            for (v, d) in q.get_mut(name).unwrap().iter_mut().zip(&direction) {
                *v += sign * h * f64::from(*d);
            }
            reference::loss(&config, &q, &x, &y, &mask, batch, grid)
        };
        let numeric = (moved(1.0) - moved(-1.0)) / (2.0 * h);
        let ours: f64 = grad.iter().zip(&direction).map(|(g, d)| f64::from(*g) * f64::from(*d)).sum();
        let scale: f64 = grad.iter().zip(&direction).map(|(g, d)| (f64::from(*g) * f64::from(*d)).abs()).sum();
        assert!(
            (ours - numeric).abs() <= 1e-3 * scale + 1e-7,
            "{name}: directional derivative {ours:e}, central difference {numeric:e} (scale {scale:e})"
        );
    }
    grads.len()
}

#[test]
fn gradients_are_the_derivatives_of_the_loss() {
    for (base_channels, depth, kernel_size, grid, batch) in
        [(3, 2, 3, [7, 6, 5], 2), (2, 1, 5, [5, 4, 6], 2), (2, 0, 3, [3, 4, 2], 1), (8, 1, 3, [5, 6, 4], 1)]
    {
        let config = UNetConfig { base_channels, depth, kernel_size, ..UNetConfig::default() };
        let net = perturbed(&config);
        let checked = check_derivatives(&net, batch, GridShape::new(grid[0], grid[1], grid[2]));
        assert_eq!(checked, net.named_parameters().len(), "{config:?}");
    }
}

/// A seed trains the same network on any number of threads: a batch's gradients are the same
/// bits on 1, 2 and 3 threads (rayon's splits of a batch depend on the threads).
#[test]
fn gradients_do_not_depend_on_the_threads() {
    let config = UNetConfig { base_channels: 3, depth: 1, ..UNetConfig::default() };
    let net = perturbed(&config);
    let (batch, grid) = (5, GridShape::new(6, 5, 4));
    let (x, y, mask) = batch_values(batch, grid);
    let on = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        pool.install(|| loss_and_gradients(&net, &x, &y, &mask, batch, grid).unwrap())
    };
    let (loss, grads) = on(1);
    assert!(loss > 0.0);
    for threads in [2, 3] {
        let (other_loss, other) = on(threads);
        assert_eq!(other_loss.to_bits(), loss.to_bits(), "loss on {threads} threads");
        for (g, h) in grads.0.iter().zip(&other.0) {
            let bits = |g: &Option<Vec<f32>>| g.as_ref().map(|v| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>());
            assert_eq!(bits(g), bits(h), "gradients on {threads} threads");
        }
    }
}

#[test]
fn frozen_encoder_gets_no_gradients() {
    let config = UNetConfig { base_channels: 3, depth: 2, ..UNetConfig::default() };
    let net = perturbed(&config).freeze_encoder();
    let checked = check_derivatives(&net, 2, GridShape::new(7, 6, 5));
    let names = net.named_parameters();
    let decoder = names.iter().filter(|(p, _)| !UNet::is_encoder_parameter(p)).count();
    assert_eq!(checked, decoder);
    let (_, grads) = loss_and_gradients(
        &net,
        &batch_values(1, GridShape::new(4, 4, 4)).0,
        &[0.0; 192],
        &[1.0; 64],
        1,
        GridShape::new(4, 4, 4),
    )
    .unwrap();
    for ((name, _), g) in names.iter().zip(&grads.0) {
        assert_eq!(g.is_some(), !UNet::is_encoder_parameter(name), "{name}");
    }
}

#[test]
fn bad_batches_are_refused() {
    let config = UNetConfig { base_channels: 2, depth: 1, ..UNetConfig::default() };
    let grid = GridShape::new(4, 4, 4);
    let net = UNet::new(&config, 1).unwrap();
    let (x, y, mask) = batch_values(2, grid);
    let e = loss_and_gradients(&net, &x[1..], &y, &mask, 2, grid).unwrap_err().to_string();
    assert!(e.contains("inputs"), "{e}");
    assert!(loss_and_gradients(&net, &x, &y, &mask, 3, grid).is_err());
    assert!(loss_and_gradients(&net, &[], &[], &[], 0, grid).is_err());
}
