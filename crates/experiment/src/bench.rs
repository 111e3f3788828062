//! `augsim bench`'s tables: median static-solve times, split into assembly, factorisation and
//! triangular solves (the cases of the fem-speed experiment); single-sample U-Net prediction
//! times, also over the reference solve (the `reference` module); registration frames of every
//! method, from rest and streamed, beside the co-rotational FEM's in the same run. Each line goes
//! to `print` as soon as it is measured.

use anyhow::{Context, Result};
use app::case::{case_methods, compare, synthetic_case};
use app::models::Network;
use mesh::stats::median;

use crate::fem_speed::{fbar_ratios, measure, reference_ms, CaseTiming, FRAME_LOAD_STEP, LARGE_DOFS, LARGE_RUNS};
use crate::held_out::{base_case, CASES, POINTS};

/// A table of `augsim bench`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Table {
    /// Static solves, split by phase, and F-bar's cost.
    Solves,
    /// Single-sample U-Net prediction.
    Prediction,
    /// Registration frames of every method, from rest and streamed.
    Registration,
}

impl Table {
    /// Every table, in the order `augsim bench` prints them.
    pub const ALL: [Table; 3] = [Table::Solves, Table::Prediction, Table::Registration];

    /// Its name on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Table::Solves => "solves",
            Table::Prediction => "prediction",
            Table::Registration => "registration",
        }
    }
}

impl std::str::FromStr for Table {
    type Err = String;

    fn from_str(name: &str) -> std::result::Result<Table, String> {
        Table::ALL.into_iter().find(|t| t.name() == name).ok_or_else(|| {
            let names: Vec<&str> = Table::ALL.iter().map(|t| t.name()).collect();
            format!("no table '{name}': the tables are {}", names.join(", "))
        })
    }
}

/// Runs every case of `tables` `runs` times and gives the tables' lines to `print`, a blank line
/// between tables.
pub fn bench(runs: usize, tables: &[Table], print: &mut dyn FnMut(&str)) -> Result<()> {
    for (k, table) in tables.iter().enumerate() {
        if k > 0 {
            print("");
        }
        match table {
            Table::Solves => static_solves(runs, print)?,
            Table::Prediction => unet_prediction(runs, print)?,
            Table::Registration => registration_frames(runs, print)?,
        }
    }
    Ok(())
}

/// Static solves from rest and as frames of a sequence, each case `runs` times: medians, split by
/// phase, then F-bar's cost over the standard element.
fn static_solves(runs: usize, print: &mut dyn FnMut(&str)) -> Result<()> {
    print(&format!(
        "Static solves from rest, medians of {} (at most {LARGE_RUNS} for the cases above {LARGE_DOFS} dofs); the \
         cases take turns.",
        runs_counted(runs)
    ));
    print("'setup': building a solver (pattern, ordering, symbolic analysis, buffers) and 'first': its first solve,");
    print("over as many new solvers as runs; 'median': repeated solves from rest on the last (the rest tangent's");
    print("factorisation is kept); 'iter', 'fact', 'asm': the Newton iterations, factorisations and assemblies of");
    print(&format!(
        "its last solve from rest. 'frame': a frame of a sequence whose load varies by {:.0} % per frame, warm-started \
         from the previous frame; 'fr.iter': its Newton iterations.",
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
    if let Some(reference) = reference_ms(&cases) {
        print("");
        print(&format!(
            "Over the reference, the co-rotational standard 5k liver's median from rest ({reference:.2} ms in this run):"
        ));
        print(&format!("{:<62} {:>7} {:>9} {:>7}", "case", "first", "from rest", "frame"));
        for c in &cases {
            let [first, from_rest, frame] = [c.first_ms, c.median_ms, c.frame_ms].map(|ms| ms / reference);
            print(&format!("{:<62} {first:>6.2}× {from_rest:>8.2}× {frame:>6.2}×", c.name));
        }
    }
    Ok(())
}

/// "1 run", "20 runs".
fn runs_counted(runs: usize) -> String {
    match runs {
        1 => "1 run".into(),
        n => format!("{n} runs"),
    }
}

/// Frames of the streamed registration in [`registration_frames`]: a press and release.
const BENCH_STREAM_FRAMES: usize = 11;

/// Registration frames on the first held-out case (a cloud of [`POINTS`] points, no
/// correspondences) by every method of the case (the shipped learned models where they are
/// found): median wall time of a frame from rest over `runs` registrations, each method set up
/// anew, and of the warm-started frames of one press-and-release stream; each with its ratio to
/// the co-rotational FEM's, measured in the same run.
fn registration_frames(runs: usize, print: &mut dyn FnMut(&str)) -> Result<()> {
    let load = &CASES[0];
    let scenario = load.apply(&base_case()?);
    let (models, skipped) = app::case::shipped_models()?;
    skipped.iter().for_each(|line| print(line));
    let trained_on = app::case::ar_scenario();
    let networks = Network::each(&models, &trained_on, std::path::Path::new(""));
    let methods = case_methods(&scenario, &networks)?;
    let single = synthetic_case(&scenario)?;
    let mut stream_scenario = scenario.clone();
    stream_scenario.truth.frames = BENCH_STREAM_FRAMES;
    let streamed = synthetic_case(&stream_scenario)?;
    print(&format!(
        "Registration frames, {} ({POINTS} points): median of {} from rest (each method set up anew) and of the {} \
         warm-started frames of a press and release; ×FEM: the ratio to the co-rotational FEM's median; TRE: the mean \
         target error of a frame from rest.",
        load.label,
        runs_counted(runs),
        BENCH_STREAM_FRAMES - 1
    ));
    print(&format!(
        "{:<32} {:>13} {:>7} {:>13} {:>7} {:>9}",
        "method", "from rest ms", "×FEM", "streamed ms", "×FEM", "TRE rest mm"
    ));
    let mut from_rest = vec![Vec::new(); methods.len()];
    let mut tre = vec![f64::NAN; methods.len()];
    for _ in 0..runs {
        for ((times, tre), c) in from_rest.iter_mut().zip(&mut tre).zip(compare(&single, &methods)) {
            let r = c.result.with_context(|| format!("{} from rest", c.method))?;
            times.push(mesh::stats::ms(r.outcomes[0].registration.time));
            *tre = r.summary.tre_mean_mm.unwrap_or(f64::NAN);
        }
    }
    let mut warm = Vec::new();
    for c in compare(&streamed, &methods) {
        let r = c.result.with_context(|| format!("{} streamed", c.method))?;
        warm.push(r.outcomes[1..].iter().map(|o| mesh::stats::ms(o.registration.time)).collect::<Vec<f64>>());
    }
    let rest_ms: Vec<f64> = from_rest.iter_mut().map(|t| median(t)).collect();
    let warm_ms: Vec<f64> = warm.iter_mut().map(|t| median(t)).collect();
    // The first method of the case is the co-rotational FEM (base_case).
    for (k, m) in methods.iter().enumerate() {
        print(&format!(
            "{:<32} {:>13.1} {:>6.2}× {:>13.1} {:>6.2}× {:>9.2}",
            m.name,
            rest_ms[k],
            rest_ms[k] / rest_ms[0],
            warm_ms[k],
            warm_ms[k] / warm_ms[0],
            tre[k]
        ));
    }
    Ok(())
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
    let reference_ms = crate::reference::measure()?;
    print(&format!("U-Net prediction, one sample on the liver grid {grid}, depth 3, after 3 warm-up runs; 'ref':"));
    print(&format!(
        "the median over the reference, the co-rotational 5k liver's solve from rest ({reference_ms:.1} ms here):"
    ));
    print(&format!(
        "{:<30} {:>10} {:>10} {:>10} {:>10} {:>8}",
        "first-layer channels", "params", "median ms", "min ms", "max ms", "ref"
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
            input_unit: learn::FieldUnit::Newton,
            target_unit: learn::FieldUnit::Metre,
            training: None,
            net,
        };
        let predictor = learn::Predictor::new(&model, learn::Compute::Cpu)?;
        let t = learn::time_prediction(|x| predictor.predict(x), &input, 3, runs)?;
        print(&format!(
            "{:<30} {:>10} {:>10.2} {:>10.2} {:>10.2} {:>7.2}×",
            base_channels,
            params,
            t.median * 1e3,
            t.min * 1e3,
            t.max * 1e3,
            t.median * 1e3 / reference_ms
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A table is named on the command line by its name, and an unknown name is refused with
    /// the list of names.
    #[test]
    fn tables_are_named_by_their_names() {
        for table in Table::ALL {
            assert_eq!(table.name().parse::<Table>(), Ok(table));
        }
        let err = "frames".parse::<Table>().unwrap_err();
        assert_eq!(err, "no table 'frames': the tables are solves, prediction, registration");
    }

    /// A row per network size, each with its median also over the run's reference time.
    #[test]
    fn the_unet_table_has_a_row_per_network_size() {
        let mut lines = Vec::new();
        unet_prediction(1, &mut |l| lines.push(l.to_string())).unwrap();
        assert_eq!(lines.len(), 5, "{lines:?}");
        assert!(lines[0].starts_with("U-Net prediction, one sample on the liver grid"), "{lines:?}");
        assert!(lines[3].starts_with('8') && lines[4].starts_with("16"), "{lines:?}");
        // Each row's last column is its median over the reference time the header states.
        let stated = lines[1].rsplit_once('(').and_then(|(_, r)| r.split_once(" ms here")).unwrap().0;
        let reference: f64 = stated.parse().unwrap();
        for row in &lines[3..] {
            let columns: Vec<&str> = row.split_whitespace().collect();
            let median: f64 = columns[2].parse().unwrap();
            let ratio: f64 = columns[5].trim_end_matches('×').parse().unwrap();
            let expected = median / reference;
            assert!((ratio - expected).abs() <= 0.01 + 0.01 * expected, "{row}: reference {reference} ms");
        }
    }
}
