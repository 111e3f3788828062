//! `augsim bench`: median static-solve times, split into assembly,
//! factorisation and triangular solves; single-sample U-Net prediction times.

use anyhow::Result;
use fem::{Formulation, Law, Material, Problem, SolverOptions, StaticSolver};
use mesh::select::nodes_in_box;
use mesh::Mesh;

use crate::solve::ms;

struct Case {
    name: String,
    problem: Problem,
}

fn beam(law: Law) -> Result<Case> {
    let m = mesh::box_hex([0.0; 3], [4.0, 1.0, 1.0], [20, 5, 5])?;
    let mut p = Problem::new(m, Material::new(law, 300.0, 0.4));
    p.fix(&nodes_in_box(&p.mesh.nodes, [-1e-9; 3], [1.0 + 1e-9, 1.0 + 1e-9, 1e-9]));
    let top_end = nodes_in_box(&p.mesh.nodes, [3.0 - 1e-9, -1e-9, 1.0 - 1e-9], [4.0 + 1e-9, 1.0 + 1e-9, 1.0 + 1e-9]);
    p.add_traction(&top_end, [0.0, 0.0, -1.0]);
    Ok(Case { name: format!("beam 20x5x5 H8, {law:?}, {:?}", p.material.resolved_formulation()), problem: p })
}

fn liver_t4(tets: usize, law: Law, formulation: Formulation) -> Result<Case> {
    // The built-in phantom (DESIGN scenario 1 at about 5,000 tetrahedra), fixed
    // between the lobes, pressed down on one lobe by an 800 Pa traction.
    let m: Mesh = mesh::phantom::liver_phantom(tets)?;
    let material = Material::new(law, 5000.0, 0.48).with_formulation(formulation);
    let mut p = Problem::new(m, material);
    let fixed = p.mesh.region("fixed")?.to_vec();
    let push = p.mesh.region("push")?.to_vec();
    p.fix(&fixed);
    p.add_traction(&push, [0.0, 0.0, -800.0]);
    let form = material.resolved_formulation();
    Ok(Case { name: format!("liver {} T4, {law:?}, {form:?}", p.mesh.cells.len()), problem: p })
}

/// Median time (ms) and mean Newton iterations of `runs` frames whose load
/// factor moves by 2 % per frame between 0.9 and 1.1, each warm-started from the last.
fn frames(solver: &mut StaticSolver, opts: &SolverOptions, u_full: &[f64], runs: usize) -> Result<(f64, f64)> {
    let base = solver.problem().f_ext.clone();
    let mut u = u_full.to_vec();
    let (mut times, mut iterations) = (Vec::new(), 0);
    for k in 0..runs {
        let phase = (k % 20) as f64;
        let factor = 1.0 + 0.02 * if phase < 10.0 { phase - 5.0 } else { 15.0 - phase };
        solver.problem_mut().f_ext.iter_mut().zip(&base).for_each(|(f, b)| *f = factor * b);
        let s = solver.solve_from(Some(&u), opts)?;
        times.push(ms(s.timings.total));
        iterations += s.iterations;
        u = s.u;
    }
    solver.problem_mut().f_ext = base;
    Ok((median(times), iterations as f64 / runs as f64))
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(|a, b| a.total_cmp(b));
    v[v.len() / 2]
}

/// Runs every case `runs` times and prints medians: static solves, then U-Net prediction.
pub fn run(runs: usize) -> Result<()> {
    let runs = runs.max(1);
    println!("Static solves from rest. 'first': a new solver's first solve (symbolic analysis excluded);");
    println!("'median': repeated solves from rest (the rest tangent's factorisation is kept).");
    println!(
        "'frame': a frame of a sequence whose load varies by 2 % per frame, warm-started from the previous frame."
    );
    println!(
        "{:<40} {:>6} {:>5} {:>4} {:>4} {:>9} {:>9} {:>9} {:>9} {:>9} {:>9} {:>9} {:>7}",
        "case",
        "dofs",
        "iter",
        "fact",
        "asm",
        "first ms",
        "median ms",
        "assem ms",
        "factor ms",
        "solve ms",
        "max|u| m",
        "frame ms",
        "fr.iter"
    );
    let cases = [
        beam(Law::Svk)?,
        beam(Law::Corotational)?,
        liver_t4(5000, Law::Svk, Formulation::Standard)?,
        liver_t4(5000, Law::Svk, Formulation::Fbar)?,
        liver_t4(5000, Law::Corotational, Formulation::Standard)?,
        liver_t4(5000, Law::Corotational, Formulation::Fbar)?,
        liver_t4(50000, Law::Svk, Formulation::Fbar)?,
    ];
    for case in cases {
        let dofs = case.problem.num_dofs();
        // The large case is timed a few times only.
        let runs = if dofs > 20_000 { runs.min(3) } else { runs };
        let mut solver = StaticSolver::new(case.problem)?;
        let opts = SolverOptions::default();
        let first = solver.solve(&opts)?;
        let mut rows = Vec::new();
        for _ in 0..runs {
            rows.push(solver.solve(&opts)?);
        }
        let med = |f: &dyn Fn(&fem::Solution) -> f64| median(rows.iter().map(f).collect());
        let last = rows.last().expect("at least one run").clone();
        let (frame_ms, frame_iterations) = frames(&mut solver, &opts, &last.u, runs)?;
        println!(
            "{:<40} {:>6} {:>5} {:>4} {:>4} {:>9.2} {:>9.2} {:>9.2} {:>9.2} {:>9.2} {:>9.4} {:>9.2} {:>7.1}",
            case.name,
            dofs,
            last.iterations,
            last.factorizations,
            last.tangent_assemblies,
            ms(first.timings.total),
            med(&|s| ms(s.timings.total)),
            med(&|s| ms(s.timings.assembly)),
            med(&|s| ms(s.timings.factorization)),
            med(&|s| ms(s.timings.solve)),
            fem::post::max_displacement(&last.u),
            frame_ms,
            frame_iterations
        );
    }
    unet_prediction(runs)
}

/// Single-sample U-Net prediction on the scenario-1 liver grid (the path of `augsim predict`:
/// normalisation, repacked CPU network, copy back), for two network sizes. The weights are
/// random: the time does not depend on their values.
fn unet_prediction(runs: usize) -> Result<()> {
    println!();
    println!("U-Net prediction, one sample on the liver grid 21x23x21, depth 3, after 3 warm-up runs:");
    println!("{:<30} {:>10} {:>10} {:>10} {:>10}", "first-layer channels", "params", "median ms", "min ms", "max ms");
    let grid = learn::GridShape::new(21, 23, 21);
    let input: Vec<f32> = (0..grid.field_len()).map(|i| ((i * 7919) % 2001) as f32 * 1e-3 - 1.0).collect();
    for base_channels in [8, 16] {
        let config = learn::UNetConfig { base_channels, ..learn::UNetConfig::default() };
        let net = learn::UNet::new(&config, &learn::inference_device(), 0)?;
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
        let t = learn::time_prediction(&learn::Predictor::new(&model)?, &input, 3, runs)?;
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
