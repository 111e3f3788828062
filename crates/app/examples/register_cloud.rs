//! Registers an intraoperative point cloud with the library: a synthetic case (the built-in
//! `register_case_test` scenario: a Neo-Hookean phantom pushed down, seen from above as a partial,
//! noisy cloud with outliers), then a co-rotational FEM of another mesh pulled onto the cloud by
//! data springs, frame by frame; the target registration error at the hidden markers.
//!
//! `cargo run --release -p augsim-app --example register_cloud`

use std::path::Path;

use augsim_app::case::{corotational_model, synthetic_case};
use register::organ::displaced;
use register::{register_frame, target_errors, RegistrationOptions};
use scenario::CaseScenario;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    // What the operating room gives (a cloud of positions) and what it hides (the markers' truth).
    let scenario = CaseScenario::load(Path::new("register_case_test"))?;
    let case = synthetic_case(&scenario)?;
    println!("cloud      {} points, {} hidden markers", case.peak().cloud.len(), case.targets.len());

    // The preoperative model: the organ (its mesh and surface) and what deforms it.
    let (organ, mut deformer) = corotational_model()?;
    let stencils = organ.locate(&case.targets, "target")?;
    let tre = |u: &[f64]| {
        1e3 * mesh::stats::mean(&target_errors(&displaced(&case.targets, &stencils, u), &case.peak().truth))
    };
    println!("before     mean TRE {:.2} mm (no deformation)", tre(&vec![0.0; 3 * organ.mesh().num_nodes()]));

    let frame = register_frame(&organ, &mut deformer, &case.peak().cloud, None, &RegistrationOptions::default())?;
    println!(
        "after      mean TRE {:.2} mm; surface residual {:.2} mm, {} of {} points kept, {} iterations, {:.0} ms",
        tre(&frame.u),
        frame.surface_residual * 1e3,
        frame.inliers,
        frame.points,
        frame.iterations,
        frame.time.as_secs_f64() * 1e3
    );
    Ok(())
}
