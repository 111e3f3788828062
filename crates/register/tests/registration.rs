//! Registration of the phantom to clouds of a deformation computed on another
//! mesh with another law (no inverse crime): the targets must be recovered.

use augsim_register as register;
use fem::{Law, Material, Problem, SolverOptions, StaticSolver};
use mesh::{Mesh, Point};
use register::organ::displaced;
use register::{register_frame, simulate_cloud, CameraModel, FemDeformer, Organ, RegistrationOptions};

/// Ground truth: a finer Neo-Hookean phantom pushed down on one lobe by 1.5 N
/// (the markers move by 14 mm on average).
fn truth() -> (Mesh, Vec<f64>) {
    let m = mesh::phantom::liver_phantom(9000).unwrap();
    let mut p = Problem::new(m, Material::new(Law::NeoHookean, 5000.0, 0.48));
    let fixed = p.mesh.region("fixed").unwrap().to_vec();
    let push = p.mesh.region("push").unwrap().to_vec();
    p.fix(&fixed);
    p.add_force(&push, [0.0, 0.0, -1.5]);
    let u = StaticSolver::new(p.clone()).unwrap().solve(&SolverOptions::default()).unwrap().u;
    (p.mesh, u)
}

fn mean_distance(a: &[Point], b: &[Point]) -> f64 {
    a.iter().zip(b).map(|(p, q)| register::register::distance(*p, *q)).sum::<f64>() / a.len() as f64
}

/// TRE (m) of a co-rotational FEM registration on a coarser phantom, and the
/// no-deformation TRE, for a cloud of the visible half of the truth.
fn fem_tre(camera: &CameraModel) -> (f64, f64, f64) {
    let (truth_mesh, u_truth) = truth();
    let markers: Vec<usize> = truth_mesh.region("markers").unwrap().to_vec();
    let rest: Vec<Point> = markers.iter().map(|&n| truth_mesh.nodes[n]).collect();
    let moved: Vec<Point> =
        markers.iter().map(|&n| std::array::from_fn(|d| truth_mesh.nodes[n][d] + u_truth[3 * n + d])).collect();
    let truth_organ = Organ::new(truth_mesh, None).unwrap();
    let cloud = simulate_cloud(&truth_organ.deformed_surface(&u_truth), camera, 7).unwrap();

    let m = mesh::phantom::liver_phantom(3000).unwrap();
    let mut problem = Problem::new(m.clone(), Material::new(Law::Corotational, 5000.0, 0.48));
    problem.fix(&m.region("fixed").unwrap().to_vec());
    let stiffness = FemDeformer::default_stiffness(&problem);
    let mut deformer = FemDeformer::new(problem, stiffness, SolverOptions::default()).unwrap();
    let organ = Organ::new(m, None).unwrap();
    let stencils = organ.locate(&rest, "target").unwrap();
    let frame = register_frame(&organ, &mut deformer, &cloud, None, &RegistrationOptions::default()).unwrap();
    let registered = displaced(&rest, &stencils, &frame.u);
    (mean_distance(&registered, &moved), mean_distance(&rest, &moved), frame.surface_residual)
}

#[test]
fn fem_registration_recovers_hidden_markers_from_a_partial_cloud() {
    let camera = CameraModel { view: [0.0, 0.0, -1.0], points: 1500, noise: 0.0, outliers: 0.0 };
    let (tre, rigid, residual) = fem_tre(&camera);
    eprintln!("TRE {:.2} mm, no deformation {:.2} mm, residual {:.2} mm", tre * 1e3, rigid * 1e3, residual * 1e3);
    assert!(rigid > 1e-2, "the markers must move: {rigid}");
    assert!(tre < 0.2 * rigid, "TRE {tre} against {rigid} without deformation");
    assert!(residual < 5e-4, "the surface must meet the cloud: {residual}");
    let noisy = CameraModel { noise: 1e-3, outliers: 0.1, ..camera };
    let (tre_noisy, _, residual_noisy) = fem_tre(&noisy);
    eprintln!("noisy: TRE {:.2} mm, residual {:.2} mm", tre_noisy * 1e3, residual_noisy * 1e3);
    assert!(tre_noisy < tre + 1e-3, "1 mm noise and 10 % outliers: TRE {tre_noisy} against {tre}");
}
