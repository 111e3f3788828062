//! `augsim bench`'s tables: median static-solve times, split into assembly, factorisation and
//! triangular solves (the cases of the fem-speed experiment); single-sample U-Net prediction
//! times. Each line goes to `print` as soon as it is measured.

use anyhow::Result;

use crate::fem_speed::{fbar_ratios, measure, CaseTiming, FRAME_LOAD_STEP};

/// Runs every case `runs` times and gives the tables' lines to `print`: static solves, then
/// U-Net prediction.
pub fn bench(runs: usize, print: &mut dyn FnMut(&str)) -> Result<()> {
    print("Static solves from rest, medians; the cases take turns. 'setup': building a solver (pattern,");
    print("ordering, symbolic analysis, buffers) and 'first': its first solve, over as many new solvers as runs;");
    print("'median': repeated solves from rest on the last (the rest tangent's factorisation is kept).");
    print(&format!(
        "'frame': a frame of a sequence whose load varies by {:.0} % per frame, warm-started from the previous frame.",
        100.0 * FRAME_LOAD_STEP
    ));
    print(&format!(
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
    ));
    let cases = measure(runs, true, &mut |c| print(&case_row(c)))?;
    print("");
    print("F-bar over the standard element, by the medians above:");
    print(&format!("{:<62} {:>7} {:>9} {:>7}", "pair", "first", "from rest", "frame"));
    for r in fbar_ratios(&cases) {
        print(&format!("{:<62} {:>6.2}× {:>8.2}× {:>6.2}×", r.pair, r.first, r.from_rest, r.frame));
    }
    print("");
    unet_prediction(runs, print)
}

/// A static-solve case's row of the table.
fn case_row(c: &CaseTiming) -> String {
    format!(
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
}

/// Single-sample U-Net prediction on the scenario-1 liver grid (the path of `augsim predict`:
/// normalisation, repacked CPU network, copy back), for two network sizes. The weights are
/// random: the time does not depend on their values.
fn unet_prediction(runs: usize, print: &mut dyn FnMut(&str)) -> Result<()> {
    let grid = learn::GridShape::new(21, 23, 21);
    print(&format!("U-Net prediction, one sample on the liver grid {grid}, depth 3, after 3 warm-up runs:"));
    print(&format!(
        "{:<30} {:>10} {:>10} {:>10} {:>10}",
        "first-layer channels", "params", "median ms", "min ms", "max ms"
    ));
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
        print(&format!(
            "{:<30} {:>10} {:>10.2} {:>10.2} {:>10.2}",
            base_channels,
            params,
            t.median * 1e3,
            t.min * 1e3,
            t.max * 1e3
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_unet_table_has_a_row_per_network_size() {
        let mut lines = Vec::new();
        unet_prediction(1, &mut |l| lines.push(l.to_string())).unwrap();
        assert_eq!(lines.len(), 4, "{lines:?}");
        assert!(lines[0].starts_with("U-Net prediction, one sample on the liver grid"), "{lines:?}");
        assert!(lines[2].starts_with('8') && lines[3].starts_with("16"), "{lines:?}");
    }
}
