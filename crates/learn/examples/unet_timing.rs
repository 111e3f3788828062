//! Times a U-Net on the liver grid 21x23x21 (padded to a multiple of 2^depth): a single-sample
//! prediction with the repacked [`InferenceNet`](augsim_learn::InferenceNet) and a full training
//! step (forward, backward, Adam) for a batch, and the same with burn's engine when built with the
//! `cpu-burn` feature.
//!
//! `cargo run --release -p augsim-learn --example unet_timing [--features cpu-burn] -- [batch] [runs] [base_channels] [depth]`
//! (defaults: 4, 5 and the default configuration, 16 channels, depth 3).

use std::time::Instant;

use augsim_learn::net::backprop::loss_and_gradients;
use augsim_learn::training::adam::Adam;
use augsim_learn::{GridShape, Timing, UNet, UNetConfig};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

fn time(runs: usize, mut f: impl FnMut()) -> Timing {
    f();
    let d = (0..runs)
        .map(|_| {
            let t0 = Instant::now();
            f();
            t0.elapsed().as_secs_f64()
        })
        .collect();
    Timing::from_durations(d).expect("runs > 0")
}

fn report(name: &str, t: &Timing) {
    println!(
        "{name}: median {:.1} ms, mean {:.1} ± {:.1} ms, min {:.1}, max {:.1} ({} runs)",
        t.median * 1e3,
        t.mean * 1e3,
        t.std * 1e3,
        t.min * 1e3,
        t.max * 1e3,
        t.runs
    );
}

fn main() {
    let args: Vec<usize> = std::env::args().skip(1).filter_map(|a| a.parse().ok()).collect();
    let batch = args.first().copied().unwrap_or(4);
    let runs = args.get(1).copied().unwrap_or(5);
    let default = UNetConfig::default();
    let config = UNetConfig {
        base_channels: args.get(2).copied().unwrap_or(default.base_channels),
        depth: args.get(3).copied().unwrap_or(default.depth),
        ..default
    };
    let grid = GridShape::new(21, 23, 21);
    println!("U-Net {config:?}, batch {batch}, grid {grid}");
    let mut rng = StdRng::seed_from_u64(0);
    let mut random = |n: usize| -> Vec<f32> { (0..n).map(|_| rng.random_range(-1.0..1.0)).collect() };
    let (x, y) = (random(batch * grid.field_len()), random(batch * grid.field_len()));
    let mask = vec![1.0f32; batch * grid.nodes()];

    let mut net = UNet::new(&config, 0).expect("valid config");
    let fast = net.to_inference().expect("repacked network");
    let input = &x[..grid.field_len()];
    report(
        "InferenceNet, batch 1",
        &time(runs, || {
            std::hint::black_box(fast.forward(input, grid).expect("forward"));
        }),
    );
    let mut adam = Adam::new(net.named_parameters().len());
    report(
        "train step",
        &time(runs, || {
            let (_, grads) = loss_and_gradients(&net, &x, &y, &mask, batch, grid).expect("gradients");
            adam.step(1e-3, &mut net, &grads).expect("Adam step");
        }),
    );

    #[cfg(feature = "cpu-burn")]
    {
        use augsim_learn::net::burn_unet::BurnUNet;
        use augsim_learn::Compute;
        use burn::tensor::{Tensor, TensorData};
        let device = Compute::CpuBurn.device().expect("burn's CPU device");
        let burn = BurnUNet::new(&net, &device).expect("burn network");
        let [nx, ny, nz] = grid.dims();
        let xt = Tensor::<5>::from_data(TensorData::new(x.clone(), [batch, 3, nx, ny, nz]), &device);
        report(
            "burn forward",
            &time(runs, || {
                let _ = burn.forward(xt.clone()).into_data();
            }),
        );
        let x1 = Tensor::<5>::from_data(TensorData::new(input.to_vec(), [1, 3, nx, ny, nz]), &device);
        report(
            "burn forward, batch 1",
            &time(runs, || {
                let _ = burn.forward(x1.clone()).into_data();
            }),
        );
        let device = Compute::CpuBurn.training_device().expect("burn's CPU device");
        report(
            "burn train step",
            &time(runs, || {
                let burn = BurnUNet::new(&net, &device).expect("burn network");
                let (_, grads) = burn.loss_and_gradients(&x, &y, &mask, batch, grid, &device).expect("gradients");
                adam.step(1e-3, &mut net, &grads).expect("Adam step");
            }),
        );
    }
    println!("parameters: {}", net.num_params());
}
