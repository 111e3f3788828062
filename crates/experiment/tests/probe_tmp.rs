use fem::{Formulation, StaticSolver};
use std::path::Path;
fn maxu(u: &[f64]) -> f64 {
    u.chunks(3).map(|c| (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt()).fold(0.0, f64::max)
}
#[test]
#[ignore]
fn probe() {
    let path = std::env::var("PROBE_DS").unwrap();
    let idx: Vec<u64> = std::env::var("PROBE_IDX").unwrap().split(',').map(|s| s.parse().unwrap()).collect();
    let (sc, dir) = scenario::DatasetScenario::load(Path::new(&path)).unwrap();
    let gen = sc.generator(&dir).unwrap();
    for i in idx {
        let p = gen.draw_problem(i).unwrap();
        let mut line = format!("draw {i}:");
        for (form, cuts) in
            [(Formulation::Fbar, 4), (Formulation::Fbar, 12), (Formulation::Standard, 4), (Formulation::Standard, 12)]
        {
            let mut q = p.clone();
            q.material.formulation = form;
            let mut o = sc.solver.clone();
            o.max_step_cuts = cuts;
            let t = std::time::Instant::now();
            let r = StaticSolver::new(q).and_then(|mut s| s.solve(&o));
            match r {
                Ok(sol) => {
                    line += &format!(
                        " | {form:?}/{cuts} {:.1} mm ({} it, {:.1}s)",
                        1e3 * maxu(&sol.u),
                        sol.iterations,
                        t.elapsed().as_secs_f64()
                    )
                }
                Err(e) => line += &format!(" | {form:?}/{cuts} FAIL {}", &e.to_string()[..50.min(e.to_string().len())]),
            }
        }
        let mut q = p.clone();
        q.material.formulation = Formulation::Standard;
        let d = std::env::temp_dir().join(format!("ccx_probe_{i}"));
        match augsim_experiment::calculix::solve(&q, &d) {
            Ok(s) => line += &format!(" | ccx {:.1} mm", 1e3 * maxu(&s.u)),
            Err(e) => line += &format!(" | ccx FAIL {}", &e.to_string()[..80.min(e.to_string().len())]),
        }
        println!("{line}");
    }
}
