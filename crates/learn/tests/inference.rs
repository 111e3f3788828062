//! The repacked CPU inference network computes what the burn network computes.

use augsim_learn::training::metrics::masked_mse;
use augsim_learn::{inference_device, training_device, GridShape, UNet, UNetConfig};
use burn::module::Module;
use burn::optim::{AdamConfig, GradientsParams};
use burn::tensor::{Distribution, Tensor};

/// A network whose biases are non-zero (a few Adam steps away from the seeded start).
fn trained_a_little(config: &UNetConfig, grid: [usize; 3]) -> UNet {
    let device = training_device();
    let mut net = UNet::new(config, &device, 7).unwrap();
    let mut optim = AdamConfig::new().init();
    let shape = [2, 3, grid[0], grid[1], grid[2]];
    let x = Tensor::<5>::random(shape, Distribution::Uniform(-1.0, 1.0), &device);
    let y = Tensor::<5>::random(shape, Distribution::Uniform(-1.0, 1.0), &device);
    let mask = Tensor::<5>::ones([2, 1, grid[0], grid[1], grid[2]], &device);
    for _ in 0..3 {
        let loss = masked_mse(net.forward(x.clone()), y.clone(), mask.clone());
        let grads = GradientsParams::from_grads(loss.backward(), &net);
        net = optim.step(1e-2, net, grads);
    }
    net.valid()
}

#[test]
fn inference_network_matches_the_burn_forward_pass() {
    for (base_channels, depth, kernel_size, grid) in [
        (4, 3, 3, [21, 23, 21]),
        (3, 2, 3, [5, 6, 7]),
        (2, 1, 5, [7, 4, 6]),
        (3, 0, 3, [4, 5, 3]),
        (2, 2, 1, [8, 8, 8]),
    ] {
        let config = UNetConfig { base_channels, depth, kernel_size, ..UNetConfig::default() };
        let net = trained_a_little(&config, grid);
        let biases: f32 = net
            .named_parameters()
            .iter()
            .filter(|(p, _)| p.ends_with("bias"))
            .flat_map(|(_, v)| v.iter().map(|b| b.abs()))
            .sum();
        assert!(biases > 0.0, "the test needs non-zero biases");
        let fast = net.to_inference().unwrap();
        let device = inference_device();
        let x = Tensor::<5>::random([1, 3, grid[0], grid[1], grid[2]], Distribution::Uniform(-1.0, 1.0), &device);
        let input = x.clone().into_data().try_to_vec::<f32>().unwrap();
        let reference = net.forward(x).into_data().try_to_vec::<f32>().unwrap();
        let g = GridShape::new(grid[0], grid[1], grid[2]);
        let out = fast.forward(&input, g).unwrap();
        assert_eq!(out.len(), reference.len());
        let scale = reference.iter().fold(0f32, |m, v| m.max(v.abs()));
        let diff = out.iter().zip(&reference).fold(0f32, |m, (a, b)| m.max((a - b).abs()));
        assert!(scale > 0.0);
        assert!(diff <= 1e-5 * scale.max(1.0), "{config:?} on {g}: max difference {diff:e} (scale {scale:e})");
        let e = fast.forward(&input[1..], g).unwrap_err().to_string();
        assert!(e.contains("expected 3 channels"), "{e}");
    }
}
