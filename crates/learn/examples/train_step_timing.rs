//! Times a full training step (loss, gradients, Adam) on the liver grid 21x23x21 with the
//! hand-written backward pass ([`loss_and_gradients`]), and with burn's autodiff when built with
//! the `cpu-burn` feature, at 8 and 16 first-layer channels (depth 3, kernel 3), median of the runs
//! after warm-up steps.
//!
//! `cargo run --release -p augsim-learn --example train_step_timing [--features cpu-burn] -- [runs] [batch] [channels...]`
//! (defaults: 20 runs, batch 4, channels 8 and 16). Compare with
//! `bench/torch_unet_twin.py --base C --grid 24 24 24 --threads 2` in the repository root (the twin takes the
//! padded grid).

use std::time::Instant;

use augsim_learn::net::backprop::loss_and_gradients;
use augsim_learn::training::adam::Adam;
use augsim_learn::{GridShape, Timing, UNet, UNetConfig};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

const WARM_UP: usize = 3;

/// Statistics of `runs` timed calls of `step` after `WARM_UP` untimed ones.
fn time(runs: usize, mut step: impl FnMut()) -> Timing {
    let durations = (0..WARM_UP + runs)
        .map(|_| {
            let t0 = Instant::now();
            step();
            t0.elapsed().as_secs_f64()
        })
        .skip(WARM_UP)
        .collect();
    Timing::from_durations(durations).expect("runs > 0")
}

fn report(name: &str, t: &Timing) {
    let [median, min, max] = [t.median, t.min, t.max].map(|s| s * 1e3);
    println!("  {name}: median {median:.1} ms (min {min:.1}, max {max:.1}, {} runs)", t.runs);
}

fn main() {
    let args: Vec<usize> = std::env::args().skip(1).filter_map(|a| a.parse().ok()).collect();
    let runs = args.first().copied().unwrap_or(20).max(1);
    let batch = args.get(1).copied().unwrap_or(4).max(1);
    let channels = if args.len() > 2 { args[2..].to_vec() } else { vec![8, 16] };
    let grid = GridShape::new(21, 23, 21);
    let mut rng = StdRng::seed_from_u64(0);
    let mut random = |n: usize| -> Vec<f32> { (0..n).map(|_| rng.random_range(-1.0..1.0)).collect() };
    let (x, y) = (random(batch * grid.field_len()), random(batch * grid.field_len()));
    let mask = vec![1.0f32; batch * grid.nodes()];
    for base_channels in channels {
        let config = UNetConfig { base_channels, depth: 3, kernel_size: 3, ..UNetConfig::default() };
        let mut net = UNet::new(&config, 0).expect("valid config");
        println!("{base_channels} channels, depth 3, batch {batch}, grid {grid}, {} parameters", net.num_params());

        let mut adam = Adam::new(net.named_parameters().len());
        let gradients = time(runs, || {
            std::hint::black_box(loss_and_gradients(&net, &x, &y, &mask, batch, grid).expect("gradients"));
        });
        let ours = time(runs, || {
            let (_, grads) = loss_and_gradients(&net, &x, &y, &mask, batch, grid).expect("gradients");
            adam.step(1e-3, &mut net, &grads).expect("Adam step");
        });
        report("hand-written gradients (no Adam)", &gradients);
        report("hand-written step (gradients + Adam)", &ours);

        #[cfg(feature = "cpu-burn")]
        {
            use augsim_learn::net::burn_unet::BurnUNet;
            let device = augsim_learn::Compute::CpuBurn.training_device().expect("burn's CPU device");
            let mut adam = Adam::new(net.named_parameters().len());
            let autodiff = time(runs, || {
                let burn = BurnUNet::new(&net, &device).expect("burn network");
                let (_, grads) = burn.loss_and_gradients(&x, &y, &mask, batch, grid, &device).expect("gradients");
                adam.step(1e-3, &mut net, &grads).expect("Adam step");
            });
            report("burn autodiff step", &autodiff);
            println!("  speed-up over autodiff: {:.2}x", autodiff.median / ours.median);
        }
    }
}
