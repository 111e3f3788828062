//! `augsim bench`: median static-solve times, split into assembly, factorisation and
//! triangular solves (the cases of `augsim experiment fem-speed`); single-sample U-Net
//! prediction times.

use anyhow::Result;

/// Runs every case `runs` times and prints medians: static solves, then U-Net prediction.
pub fn run(runs: usize) -> Result<()> {
    println!("Static solves from rest, medians; the cases take turns. 'setup': building a solver (pattern,");
    println!("ordering, symbolic analysis, buffers) and 'first': its first solve, over as many new solvers as runs;");
    println!("'median': repeated solves from rest on the last (the rest tangent's factorisation is kept).");
    println!(
        "'frame': a frame of a sequence whose load varies by {:.0} % per frame, warm-started from the previous frame.",
        100.0 * experiment::FRAME_LOAD_STEP
    );
    println!(
        "{:<42} {:>6} {:>5} {:>4} {:>4} {:>9} {:>9} {:>9} {:>9} {:>9} {:>9} {:>9} {:>9} {:>7}",
        "case",
        "dofs",
        "iter",
        "fact",
        "asm",
        "setup ms",
        "first ms",
        "median ms",
        "assem ms",
        "factor ms",
        "solve ms",
        "max|u| m",
        "frame ms",
        "fr.iter"
    );
    let cases = experiment::measure_fem_speed(runs, true, &mut |c| {
        println!(
            "{:<42} {:>6} {:>5} {:>4} {:>4} {:>9.2} {:>9.2} {:>9.2} {:>9.2} {:>9.2} {:>9.2} {:>9.4} {:>9.2} {:>7.1}",
            c.name,
            c.dofs,
            c.iterations,
            c.factorizations,
            c.assemblies,
            c.setup_ms,
            c.first_ms,
            c.median_ms,
            c.assembly_ms,
            c.factorization_ms,
            c.solve_ms,
            c.max_displacement,
            c.frame_ms,
            c.frame_iterations
        )
    })?;
    println!();
    println!("F-bar over the standard element, by the medians above:");
    println!("{:<62} {:>7} {:>9} {:>7}", "pair", "first", "from rest", "frame");
    for r in experiment::fbar_ratios(&cases) {
        println!("{:<62} {:>6.2}× {:>8.2}× {:>6.2}×", r.pair, r.first, r.from_rest, r.frame);
    }
    unet_prediction(runs)
}

/// Single-sample U-Net prediction on the scenario-1 liver grid (the path of `augsim predict`:
/// normalisation, repacked CPU network, copy back), for two network sizes. The weights are
/// random: the time does not depend on their values.
fn unet_prediction(runs: usize) -> Result<()> {
    println!();
    let grid = learn::GridShape::new(21, 23, 21);
    println!("U-Net prediction, one sample on the liver grid {grid}, depth 3, after 3 warm-up runs:");
    println!("{:<30} {:>10} {:>10} {:>10} {:>10}", "first-layer channels", "params", "median ms", "min ms", "max ms");
    let input: Vec<f32> = (0..grid.field_len()).map(|i| ((i * 7919) % 2001) as f32 * 1e-3 - 1.0).collect();
    for base_channels in [8, 16] {
        let config = learn::UNetConfig { base_channels, ..learn::UNetConfig::default() };
        let net = learn::UNet::new(&config, 0)?;
        let params: usize = net.named_parameters().iter().map(|(_, v)| v.len()).sum();
        let model = learn::TrainedModel {
            config,
            normalization: learn::Normalization { input_scale: 1.0, target_scale: 1.0 },
            grid,
            placement: None,
            input_unit: "N".into(),
            target_unit: "m".into(),
            training: None,
            net,
        };
        let predictor = learn::Predictor::new(&model, learn::Compute::Cpu)?;
        let t = learn::time_prediction(|x| predictor.predict(x), &input, 3, runs)?;
        println!(
            "{:<30} {:>10} {:>10.2} {:>10.2} {:>10.2}",
            base_channels,
            params,
            t.median * 1e3,
            t.min * 1e3,
            t.max * 1e3
        );
    }
    Ok(())
}
