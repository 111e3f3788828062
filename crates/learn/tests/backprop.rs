//! The hand-written backward pass gives burn autodiff's loss and gradients.

use augsim_learn::net::backprop::loss_and_gradients;
use augsim_learn::training::metrics::masked_mse;
use augsim_learn::{inference_device, training_device, GridShape, UNet, UNetConfig};
use burn::module::{Module, ModuleMapper, ModuleVisitor, Param};
use burn::optim::{AdamConfig, GradientsParams};
use burn::tensor::{Tensor, TensorData};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

/// Uniform values in [lo, hi) from a seeded generator: the test's data and perturbations are the
/// same on every run (with burn's unseeded random tensors, about one run in thirty put a ReLU
/// input within rounding of zero, where the two backward passes may take different sides).
fn uniform(rng: &mut StdRng, n: usize, lo: f32, hi: f32) -> Vec<f32> {
    (0..n).map(|_| rng.random_range(lo..hi)).collect()
}

/// Adds seeded uniform noise in ±0.1 to every parameter (gradients still required where they were).
struct Jitter(StdRng);

impl ModuleMapper for Jitter {
    fn map_float<const D: usize>(&mut self, param: Param<Tensor<D>>) -> Param<Tensor<D>> {
        let rng = &mut self.0;
        param.map(|t| {
            let shape = t.shape();
            let noise = uniform(rng, shape.num_elements(), -0.1, 0.1);
            let noise = Tensor::<D>::from_data(TensorData::new(noise, shape), &t.device());
            let required = t.is_require_grad();
            let t = (t + noise).detach();
            if required {
                t.require_grad()
            } else {
                t
            }
        })
    }
}

/// A seeded network on the training device with every weight and bias perturbed (non-zero
/// biases).
fn perturbed(config: &UNetConfig) -> UNet {
    UNet::new(config, &training_device(), 7).unwrap().map(&mut Jitter(StdRng::seed_from_u64(8)))
}

/// A seeded batch `(x, y, mask)` of `batch` samples: uniform inputs and targets, a mask with zeros.
fn batch_values(batch: usize, grid: GridShape) -> (Vec<f32>, Vec<f32>, Vec<f32>) {
    let mut rng = StdRng::seed_from_u64(9);
    let n = batch * grid.nodes();
    let (x, y) = (uniform(&mut rng, 3 * n, -1.0, 1.0), uniform(&mut rng, 3 * n, -1.0, 1.0));
    let mask = uniform(&mut rng, n, -1.0, 1.0).iter().map(|v| if *v > -0.5 { 1.0 } else { 0.0 }).collect();
    (x, y, mask)
}

/// Compares every gradient of `reference` with `ours`, parameter by parameter.
struct Compare<'a> {
    reference: &'a GradientsParams,
    ours: &'a GradientsParams,
    path: Vec<String>,
    compared: usize,
}

impl ModuleVisitor for Compare<'_> {
    fn enter_module(&mut self, name: &str, _container_type: &str) {
        self.path.push(name.to_string());
    }

    fn exit_module(&mut self, _name: &str, _container_type: &str) {
        self.path.pop();
    }

    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        let path = self.path.join(".");
        let values = |g: Option<Tensor<D>>| g.map(|t| t.into_data().try_to_vec::<f32>().unwrap());
        let (reference, ours) = (values(self.reference.get::<D>(param.id)), values(self.ours.get::<D>(param.id)));
        let (reference, ours) = match (reference, ours) {
            (None, None) => return,
            (Some(r), Some(o)) => (r, o),
            (r, o) => panic!("{path}: burn has a gradient: {}, ours: {}", r.is_some(), o.is_some()),
        };
        assert_eq!(reference.len(), ours.len(), "{path}");
        let scale = reference.iter().fold(0f32, |m, v| m.max(v.abs()));
        let diff = reference.iter().zip(&ours).fold(0f32, |m, (a, b)| m.max((a - b).abs()));
        // f32 sums over thousands of terms, whose order depends on how the parallel work was split
        // (burn's and ours): 2e-5 of the largest gradient failed once in a loaded full-suite run. A
        // wrong gradient is off by far more than 1e-4.
        assert!(diff <= 1e-4 * scale + 1e-9, "{path}: max difference {diff:e}, largest gradient {scale:e}");
        self.compared += 1;
    }
}

/// Checks loss and gradients against burn on `net`; returns the number of parameters compared.
fn check_against_burn(net: &UNet, batch: usize, grid: GridShape) -> usize {
    let (x, y, mask) = batch_values(batch, grid);
    let device = training_device();
    let [nx, ny, nz] = grid.dims();
    let tensor =
        |v: &[f32], c: usize| Tensor::<5>::from_data(TensorData::new(v.to_vec(), [batch, c, nx, ny, nz]), &device);
    let loss = masked_mse(net.forward(tensor(&x, 3)), tensor(&y, 3), tensor(&mask, 1));
    let burn_loss = f64::from(loss.clone().into_scalar::<f32>());
    let reference = GradientsParams::from_grads(loss.backward(), net);

    let (our_loss, ours) = loss_and_gradients(net, &x, &y, &mask, batch, grid).unwrap();
    assert!((our_loss - burn_loss).abs() <= 1e-5 * burn_loss, "loss {our_loss} vs burn {burn_loss}");
    assert_eq!(ours.len(), reference.len());
    let mut compare = Compare { reference: &reference, ours: &ours, path: Vec::new(), compared: 0 };
    net.visit(&mut compare);
    assert_eq!(compare.compared, reference.len());
    compare.compared
}

#[test]
fn gradients_match_burn_autodiff() {
    for (base_channels, depth, kernel_size, grid, batch) in [
        (3, 2, 3, [7, 6, 5], 2),
        (2, 1, 5, [5, 4, 6], 3),
        (2, 0, 3, [3, 4, 2], 1),
        (4, 3, 3, [9, 8, 8], 2),
        (8, 2, 3, [7, 6, 5], 2),
        (16, 1, 3, [5, 6, 4], 2),
        // 16 tiles per slab at 8³: the Winograd loops on AVX-512 CPUs.
        (16, 1, 3, [8, 8, 8], 1),
    ] {
        let config = UNetConfig { base_channels, depth, kernel_size, ..UNetConfig::default() };
        let net = perturbed(&config);
        let compared = check_against_burn(&net, batch, GridShape::new(grid[0], grid[1], grid[2]));
        assert_eq!(compared, net.named_parameters().len(), "{config:?}");
    }
}

#[test]
fn frozen_encoder_gets_no_gradients() {
    let config = UNetConfig { base_channels: 3, depth: 2, ..UNetConfig::default() };
    let net = perturbed(&config).freeze_encoder();
    let compared = check_against_burn(&net, 2, GridShape::new(7, 6, 5));
    let decoder = net.named_parameters().iter().filter(|(p, _)| !UNet::is_encoder_parameter(p)).count();
    assert_eq!(compared, decoder);
}

#[test]
fn an_adam_step_on_our_gradients_is_burns() {
    let config = UNetConfig { base_channels: 2, depth: 2, ..UNetConfig::default() };
    let grid = GridShape::new(6, 5, 7);
    let net = perturbed(&config);
    let (x, y, mask) = batch_values(2, grid);
    let device = training_device();
    let [nx, ny, nz] = grid.dims();
    let tensor = |v: &[f32], c: usize| Tensor::<5>::from_data(TensorData::new(v.to_vec(), [2, c, nx, ny, nz]), &device);
    let loss = masked_mse(net.forward(tensor(&x, 3)), tensor(&y, 3), tensor(&mask, 1));
    let reference = GradientsParams::from_grads(loss.backward(), &net);
    let burn_net = AdamConfig::new().init().step(1e-3, net.clone(), reference);
    let (_, ours) = loss_and_gradients(&net, &x, &y, &mask, 2, grid).unwrap();
    let mut optim = AdamConfig::new().init();
    let our_net = optim.step(1e-3, net, ours);
    for ((path, a), (_, b)) in burn_net.named_parameters().iter().zip(our_net.named_parameters()) {
        let diff = a.iter().zip(&b).fold(0f32, |m, (p, q)| m.max((p - q).abs()));
        // Adam's first step moves each weight by about the learning rate whatever the gradient.
        assert!(diff <= 1e-5, "{path}: weights after one step differ by {diff:e}");
    }
    // The stepped network still trains (its parameters still require gradients).
    let (_, again) = loss_and_gradients(&our_net, &x, &y, &mask, 2, grid).unwrap();
    assert_eq!(again.len(), our_net.named_parameters().len());
    let _ = optim.step(1e-3, our_net, again);
}

#[test]
fn bad_batches_are_refused() {
    let config = UNetConfig { base_channels: 2, depth: 1, ..UNetConfig::default() };
    let grid = GridShape::new(4, 4, 4);
    let net = UNet::new(&config, &training_device(), 1).unwrap();
    let (x, y, mask) = batch_values(2, grid);
    let e = loss_and_gradients(&net, &x[1..], &y, &mask, 2, grid).unwrap_err().to_string();
    assert!(e.contains("inputs"), "{e}");
    assert!(loss_and_gradients(&net, &x, &y, &mask, 3, grid).is_err());
    assert!(loss_and_gradients(&net, &[], &[], &[], 0, grid).is_err());
    let frozen = UNet::new(&config, &inference_device(), 1).unwrap();
    let e = loss_and_gradients(&frozen, &x, &y, &mask, 2, grid).unwrap_err().to_string();
    assert!(e.contains("training device"), "{e}");
}
