//! Registers an intraoperative point cloud with the library, through the same front door as
//! `augsim register`, `serve` and Python: a synthetic case (the built-in `register_case_test`
//! scenario: a Neo-Hookean phantom pushed down, seen from above as a partial, noisy cloud with
//! outliers), registered by a co-rotational FEM of another mesh (the built-in static scenario
//! `liver_corotational`); the target registration error at the hidden markers.
//!
//! `cargo run --release -p augsim-app --example register_cloud`

use std::path::Path;

use augsim_app::case::synthetic_case;
use augsim_app::registration::{MethodSpec, RegistrationSpec, TargetsSpec};
use mesh::length::mm;
use mesh::stats::{mean, ms};
use register::target_errors;
use scenario::CaseScenario;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    // What the operating room gives (a cloud of positions) and what it hides (the markers' truth).
    let scenario = CaseScenario::load(Path::new("register_case_test"))?;
    let case = synthetic_case(&scenario)?;
    let (cloud, truth) = (&case.peak().cloud, &case.peak().truth);
    println!("cloud      {} points, {} hidden markers", cloud.len(), case.targets.len());

    // The preoperative model and the points to follow in it.
    let spec = RegistrationSpec::new(MethodSpec::fem("liver_corotational"), TargetsSpec::Points(case.targets.clone()));
    let mut registration = spec.build()?;
    println!("before     mean TRE {:.2} mm (no deformation)", mm(mean(&target_errors(&case.targets, truth))));

    let tracked = registration.register(cloud)?;
    let frame = &tracked.registration;
    println!(
        "after      mean TRE {:.2} mm; surface residual {:.2} mm, {} of {} points kept, {} iterations, {:.0} ms",
        mm(mean(&target_errors(&tracked.targets, truth))),
        mm(frame.surface_residual),
        frame.inliers,
        frame.points,
        frame.iterations,
        ms(frame.time)
    );
    Ok(())
}
