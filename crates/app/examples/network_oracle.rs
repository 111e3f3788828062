//! How far the U-Net registration of a case is from what its network can do. Three figures:
//! - the shipped network given the *true* normal motion of its input nodes (the motion of the
//!   truth's surface point nearest to each): the best any matching loop could give it;
//! - the loop's surface fit computed on the *true* deformed surface: whether the truth is a
//!   fixed point of matching and fitting;
//! - the match-and-fit loop itself, with the case's settings (`register --model` runs the learned
//!   registration of `augsim_app::registration`, its own settings).
//!
//! `cargo run --release -p augsim-app --example network_oracle -- [CASE.toml] [FORCE]`
//! (default: the built-in `register_case` scenario; FORCE in N replaces its force).

use std::path::Path;

use augsim_app::case::{ar_network_model, network_from_truth, synthetic_case};
use learn::Model;
use mesh::length::mm;
use mesh::Point;
use register::{observe, target_errors, RigidTransform};
use scenario::CaseScenario;

const MODEL: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../../models/liver_ar/model.json");

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let mut scenario = match args.first() {
        Some(path) => CaseScenario::load(Path::new(path))?,
        None => CaseScenario::builtin(),
    };
    if let Some(force) = args.get(1) {
        scenario.truth.force = force.parse()?;
    }
    let case = synthetic_case(&scenario)?;
    if case.pose != RigidTransform::identity() {
        return Err("the oracle compares with the truth in the model's frame: remove the case's misalignment".into());
    }
    let model = Model::load(Path::new(MODEL))?;
    let (organ, deformer) = ar_network_model(&model)?;
    let mesh = organ.mesh().clone();
    // The truth at each node of the network's mesh: interpolated in the finer mesh, or its nearest
    // node's for a node just outside it (the two meshes' surfaces differ by their facets).
    let truth_at = |x: Point| -> Point {
        match case.truth_organ.locate(&[x], "node") {
            Ok(stencil) => stencil[0].vector(&case.peak().truth_u),
            Err(_) => {
                let nodes = &case.truth_organ.mesh().nodes;
                let k = (0..nodes.len())
                    .min_by(|&a, &b| mesh::distance(nodes[a], x).total_cmp(&mesh::distance(nodes[b], x)));
                let k = k.unwrap_or(0);
                std::array::from_fn(|d| case.peak().truth_u[3 * k + d])
            }
        }
    };
    let truth_u: Vec<f64> = mesh.nodes.iter().flat_map(|&x| truth_at(x)).collect();
    let node_truth = |n: usize| -> Point { std::array::from_fn(|d| truth_u[3 * n + d]) };
    let stencils = organ.locate(&case.targets, "target")?;
    let tre = |u: &[f64]| {
        let registered = register::organ::displaced(&case.targets, &stencils, u);
        let e = target_errors(&registered, &case.peak().truth);
        (mm(mesh::stats::mean(&e)), mm(mesh::stats::max(&e)))
    };
    println!("case       {} at {} N; markers move {:.1} mm on average", scenario.name, scenario.truth.force, {
        let rest = target_errors(&case.targets, &case.peak().truth);
        mm(mesh::stats::mean(&rest))
    });
    let (mean, max) = tre(&truth_u);
    println!("truth on the network's mesh            TRE {mean:.2} / {max:.2} mm (interpolation alone)");

    // The network given the true normal motion of its input nodes.
    let errors = network_from_truth(&case, &organ, &deformer)?;
    let (mean, max) = (mm(mesh::stats::mean(&errors)), mm(mesh::stats::max(&errors)));
    println!("network, true normal motion in         TRE {mean:.2} / {max:.2} mm");

    let visible = mesh.region("visible")?.to_vec();
    let normals = mesh.surface_normals();
    // The loop's fit on the true deformed surface, against the true normal motion.
    let options = &scenario.registration;
    let view = options.view.or(Some(scenario.camera.view));
    let observations = observe(&organ, &organ.deformed_surface(&truth_u), &case.peak().cloud, options, 0.0, view)?;
    let fit = deformer.surface_estimate(&observations, &truth_u);
    let misfit: Vec<f64> = visible
        .iter()
        .zip(&fit)
        .map(|(&n, f)| (mesh::dot(*f, normals[n]) - mesh::dot(node_truth(n), normals[n])).abs())
        .collect();
    println!(
        "fit on the true surface                normal motion off by {:.2} mm on average, {:.2} mm at most",
        mm(mesh::stats::mean(&misfit)),
        mm(mesh::stats::max(&misfit))
    );

    let targets = case.targets.clone();
    let mut registration =
        register::Registration::new(organ, Box::new(deformer), "U-Net", targets, Vec::new(), options.clone())?;
    let frame = registration.register(&case.peak().cloud)?.registration;
    let (mean, max) = tre(&frame.u);
    println!("match-and-fit loop, the case's settings TRE {mean:.2} / {max:.2} mm in {} iterations", frame.iterations);
    Ok(())
}
