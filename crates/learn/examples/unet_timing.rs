//! Times a U-Net on the liver grid 21x23x21 (padded to a multiple of 2^depth): inference forward
//! pass and full training step (forward, backward, Adam) for a batch, and a single-sample
//! prediction with burn and with the repacked [`InferenceNet`](augsim_learn::InferenceNet).
//!
//! `cargo run --release -p augsim-learn --example unet_timing -- [batch] [runs] [base_channels] [depth]`
//! (defaults: 4, 5 and the default configuration, 16 channels, depth 3).

use std::time::Instant;

use augsim_learn::training::metrics::masked_mse;
use augsim_learn::{inference_device, training_device, GridShape, Timing, UNet, UNetConfig};
use burn::module::Module;
use burn::optim::{AdamConfig, GradientsParams};
use burn::tensor::{Distribution, Tensor};

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
    let shape = [batch, 3, 21, 23, 21];
    println!("U-Net {config:?}, batch {batch}, grid 21x23x21");

    let device = inference_device();
    let net = UNet::new(&config, &device, 0).expect("valid config");
    let x = Tensor::<5>::random(shape, Distribution::Uniform(-1.0, 1.0), &device);
    report(
        "forward",
        &time(runs, || {
            let _ = net.forward(x.clone()).into_data();
        }),
    );
    let x1 = Tensor::<5>::random([1, 3, 21, 23, 21], Distribution::Uniform(-1.0, 1.0), &device);
    report(
        "forward, batch 1",
        &time(runs, || {
            let _ = net.forward(x1.clone()).into_data();
        }),
    );
    let fast = net.to_inference().expect("repacked network");
    let input = x1.into_data().try_to_vec::<f32>().expect("f32 input");
    let grid = GridShape::new(21, 23, 21);
    report(
        "InferenceNet, batch 1",
        &time(runs, || {
            std::hint::black_box(fast.forward(&input, grid).expect("forward"));
        }),
    );

    let device = training_device();
    let mut net = UNet::new(&config, &device, 0).expect("valid config");
    let mut optim = AdamConfig::new().init();
    let x = Tensor::<5>::random(shape, Distribution::Uniform(-1.0, 1.0), &device);
    let y = Tensor::<5>::random(shape, Distribution::Uniform(-1.0, 1.0), &device);
    let mask = Tensor::<5>::ones([batch, 1, 21, 23, 21], &device);
    report(
        "train step",
        &time(runs, || {
            let loss = masked_mse(net.forward(x.clone()), y.clone(), mask.clone());
            let grads = GradientsParams::from_grads(loss.backward(), &net);
            net = optim.step(1e-3, net.clone(), grads);
            let _ = net.clone().valid();
        }),
    );
    println!("parameters: {}", net.num_params());
}
