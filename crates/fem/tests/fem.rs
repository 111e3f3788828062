//! Verification of the finite-element engine against analytic solutions,
//! finite differences and invariances.

use augsim_fem as fem;
use fem::{Formulation, Law, Material, PointSpring, Problem, SolverOptions, StaticSolver};
use mesh::{boundary_nodes, box_hex, box_tet, CellKind, Mesh};
use nalgebra::{Matrix3, Rotation3, Vector3};

const LAWS: [Law; 4] = [Law::Linear, Law::Corotational, Law::Svk, Law::NeoHookean];
const FORMULATIONS: [Formulation; 2] = [Formulation::Standard, Formulation::Fbar];

/// Deterministic pseudo-random numbers in [-1, 1].
fn noise(seed: usize) -> f64 {
    let x = (seed as f64 * 12.9898 + 78.233).sin() * 43758.5453;
    2.0 * (x - x.floor()) - 1.0
}

const KINDS: [CellKind; 3] = [CellKind::Tet4, CellKind::Hex8, CellKind::Tet10];

/// Moves the interior nodes of `m` randomly, by up to `amplitude`.
fn perturb_interior(m: &mut Mesh, amplitude: f64) {
    let boundary = boundary_nodes(m);
    for (i, p) in m.nodes.iter_mut().enumerate() {
        if boundary.binary_search(&i).is_err() {
            for (d, pd) in p.iter_mut().enumerate() {
                *pd += amplitude * noise(3 * i + d);
            }
        }
    }
}

/// A unit-ish box with its interior nodes moved randomly (a distorted mesh); for T10, the
/// distorted T4 mesh with mid-edge nodes (straight edges).
fn distorted(kind: CellKind, n: usize) -> Mesh {
    let linear = if kind == CellKind::Hex8 { CellKind::Hex8 } else { CellKind::Tet4 };
    let mut m = mesh::box_mesh(linear, [0.0; 3], [1.0, 0.8, 0.6], [n; 3]).unwrap();
    perturb_interior(&mut m, 0.2 * 0.6 / n as f64);
    if kind == CellKind::Tet10 {
        m = m.quadratic().unwrap();
    }
    m.validate().unwrap();
    m
}

/// Every element kind × law × formulation.
fn cases() -> impl Iterator<Item = (CellKind, Law, Formulation)> {
    KINDS.into_iter().flat_map(|kind| LAWS.into_iter().flat_map(move |l| FORMULATIONS.map(|f| (kind, l, f))))
}

#[test]
fn patch_test_reproduces_homogeneous_deformation() {
    let a = Matrix3::new(0.02, 0.01, -0.015, 0.005, -0.01, 0.02, 0.01, 0.0, 0.03);
    let b = Vector3::new(0.001, -0.002, 0.003);
    for (kind, law, form) in cases() {
        {
            let m = distorted(kind, 3);
            let exact = |p: &[f64; 3]| a * Vector3::from(*p) + b;
            let mut problem = Problem::new(m.clone(), Material::new(law, 5000.0, 0.3).with_formulation(form));
            for n in boundary_nodes(&m) {
                let u = exact(&m.nodes[n]);
                problem.prescribe(&[n], [u.x, u.y, u.z]);
            }
            let mut solver = StaticSolver::new(problem).unwrap();
            let sol = solver.solve(&SolverOptions { rtol: 1e-12, utol: 1e-12, ..Default::default() }).unwrap();
            let err = m
                .nodes
                .iter()
                .enumerate()
                .map(|(i, p)| (Vector3::from_column_slice(&sol.u[3 * i..3 * i + 3]) - exact(p)).norm())
                .fold(0.0, f64::max);
            assert!(err < 1e-10, "{kind:?} {law:?} {form:?}: patch test error {err:e}");
        }
    }
}

#[test]
fn tangent_matches_finite_difference_of_internal_force() {
    for (kind, law, form) in cases() {
        {
            let m = distorted(kind, 2);
            let n = m.num_nodes();
            let mut problem = Problem::new(m, Material::new(law, 3000.0, 0.42).with_formulation(form));
            problem.fix(&[0]);
            problem.add_springs(&[1, 2], 50.0);
            let s = 1.0 / 3f64.sqrt();
            // A point-to-plane spring on one node, and a spring on a point of the first cell.
            let cell = problem.mesh.cells.cell(0).to_vec();
            problem.point_springs = vec![
                PointSpring {
                    nodes: vec![(2, 1.0)],
                    target: [0.01, 0.0, -0.02],
                    stiffness: 0.0,
                    normal: [s, -s, s],
                    normal_stiffness: 80.0,
                },
                PointSpring {
                    nodes: vec![(cell[1], 0.2), (cell[2], 0.5), (cell[3], 0.3)],
                    target: [0.02, -0.01, 0.03],
                    stiffness: 10.0,
                    normal: [0.0, 0.6, 0.8],
                    normal_stiffness: 30.0,
                },
            ];
            let mut solver = StaticSolver::new(problem).unwrap();
            let u: Vec<f64> = (0..3 * n).map(|i| if i < 3 { 0.0 } else { 0.05 * noise(7 * i + 1) }).collect();
            let k = solver.tangent_dense(&u).unwrap();
            let h = 1e-7;
            let mut worst: f64 = 0.0;
            let scale = k.iter().flatten().fold(0.0f64, |a, b| a.max(b.abs()));
            for dof in 3..3 * n {
                let j = solver.free_index(dof).unwrap();
                let mut up = u.clone();
                up[dof] += h;
                let mut um = u.clone();
                um[dof] -= h;
                let fp = solver.internal_force(&up).unwrap();
                let fm = solver.internal_force(&um).unwrap();
                for row in 3..3 * n {
                    let i = solver.free_index(row).unwrap();
                    worst = worst.max(((fp[row] - fm[row]) / (2.0 * h) - k[i][j]).abs());
                }
            }
            assert!(worst < 1e-6 * scale, "{kind:?} {law:?} {form:?}: tangent error {worst:e} (scale {scale:e})");
        }
    }
}

#[test]
fn rigid_rotation_produces_no_internal_force() {
    let rot = Rotation3::from_euler_angles(0.7, -0.4, 1.1);
    // The displacement that turns mesh `m` rigidly by `rot` about the origin.
    let rotated = |m: &Mesh| -> Vec<f64> {
        m.nodes.iter().flat_map(|p| (rot * Vector3::from(*p) - Vector3::from(*p)).data.0[0]).collect()
    };
    for kind in KINDS {
        for (law, form) in
            [Law::Corotational, Law::Svk, Law::NeoHookean].into_iter().flat_map(|l| FORMULATIONS.map(|f| (l, f)))
        {
            let m = distorted(kind, 2);
            let u = rotated(&m);
            let material = Material::new(law, 5000.0, 0.45).with_formulation(form);
            let mut solver = StaticSolver::new(Problem::new(m, material)).unwrap();
            let f = solver.internal_force(&u).unwrap();
            let fmax = f.iter().fold(0.0f64, |a, b| a.max(b.abs()));
            assert!(fmax < 1e-9, "{kind:?} {law:?} {form:?}: |f| = {fmax:e} under a rigid rotation");
        }
        // The linear law is not rotation invariant: the same test must see forces.
        let m = distorted(kind, 2);
        let u = rotated(&m);
        let mut solver = StaticSolver::new(Problem::new(m, Material::new(Law::Linear, 5000.0, 0.45))).unwrap();
        let f = solver.internal_force(&u).unwrap();
        assert!(f.iter().fold(0.0f64, |a, b| a.max(b.abs())) > 1.0);
    }
}

/// Cantilever along x, clamped at x = 0, with a downward traction on the free end.
fn cantilever(kind: CellKind, n: [usize; 3], law: Law, load: f64) -> (Vec<f64>, Mesh) {
    let (l, h) = (4.0, 1.0);
    let m = mesh::box_mesh(kind, [0.0; 3], [l, h, h], n).unwrap();
    let clamp = mesh::select::nodes_in_box(&m.nodes, [-1e-9; 3], [1e-9, h + 1e-9, h + 1e-9]);
    let tip = mesh::select::nodes_in_box(&m.nodes, [l - 1e-9, -1e-9, -1e-9], [l + 1e-9, h + 1e-9, h + 1e-9]);
    let mut problem = Problem::new(m.clone(), Material::new(law, 300.0, 0.0));
    problem.fix(&clamp);
    let area = problem.add_traction(&tip, [0.0, 0.0, -load]);
    assert!((area - h * h).abs() < 1e-9, "loaded area {area}");
    let mut solver = StaticSolver::new(problem).unwrap();
    let sol = solver.solve(&SolverOptions { load_steps: 2, ..Default::default() }).unwrap();
    (sol.u, m)
}

fn tip_deflection(u: &[f64], m: &Mesh) -> f64 {
    let tip = mesh::select::nodes_in_box(&m.nodes, [3.999, -1.0, -1.0], [4.001, 2.0, 2.0]);
    -tip.iter().map(|&n| u[3 * n + 2]).sum::<f64>() / tip.len() as f64
}

#[test]
fn h8_cantilever_converges_to_euler_bernoulli() {
    // δ = P L³ / (3 E I) with P = q·h², I = h⁴/12 (plus Timoshenko shear ≈ 0.6 % at L/h = 4·... here ~3.75 %).
    let (l, h, e, q) = (4.0f64, 1.0f64, 300.0, 0.01);
    let p = q * h * h;
    let bending = p * l.powi(3) / (3.0 * e * h.powi(4) / 12.0);
    let shear = p * l / (5.0 / 6.0 * e / 2.0 * h * h);
    let exact = bending + shear;
    let errors: Vec<f64> = [[4, 1, 1], [8, 2, 2], [16, 4, 4], [32, 8, 8]]
        .iter()
        .map(|&n| {
            let (u, m) = cantilever(CellKind::Hex8, n, Law::Linear, q);
            (tip_deflection(&u, &m) - exact).abs() / exact
        })
        .collect();
    for w in errors.windows(2) {
        assert!(w[1] < w[0], "error must decrease under refinement: {errors:?}");
    }
    eprintln!("cantilever relative errors: {errors:?}");
    assert!(errors[3] < 0.03, "finest mesh off the beam theory by {:.2} %", 100.0 * errors[3]);
    assert!(errors[0] > 2.0 * errors[3], "refinement must matter: {errors:?}");
}

/// Large deflection: a slender SVK cantilever (L/h = 10, ν = 0) under a dead tip load with PL²/EI = 1 bends
/// as the elastica does, towards Mattiasson's (1981) elliptic-integral tip displacements w/L = 0.30172 down and
/// u/L = 0.05643 towards the clamp, as the H8 mesh is refined; linear theory would give w/L = 1/3 and no
/// shortening.
#[test]
fn svk_cantilever_approaches_the_elastica() {
    let (l, h, e) = (10.0f64, 1.0f64, 300.0);
    let p = e * h.powi(4) / 12.0 / (l * l);
    let tip_displacement = |n: [usize; 3]| {
        let m = box_hex([0.0; 3], [l, h, h], n).unwrap();
        let clamp = mesh::select::nodes_in_box(&m.nodes, [-1e-9; 3], [1e-9, h + 1e-9, h + 1e-9]);
        let tip = mesh::select::nodes_in_box(&m.nodes, [l - 1e-9, -1e-9, -1e-9], [l + 1e-9, h + 1e-9, h + 1e-9]);
        let mut problem = Problem::new(m, Material::new(Law::Svk, e, 0.0));
        problem.fix(&clamp);
        problem.add_traction(&tip, [0.0, 0.0, -p / (h * h)]);
        let u = StaticSolver::new(problem)
            .unwrap()
            .solve(&SolverOptions { load_steps: 4, ..Default::default() })
            .unwrap()
            .u;
        let mean = |d: usize| tip.iter().map(|&k| u[3 * k + d]).sum::<f64>() / tip.len() as f64;
        (-mean(2) / l, -mean(0) / l)
    };
    let (w_exact, u_exact) = (0.30172, 0.05643);
    let meshes = [[10, 1, 1], [20, 2, 2], [40, 4, 4], [80, 8, 8]];
    let errors: Vec<(f64, f64)> = meshes
        .iter()
        .map(|&n| {
            let (w, u) = tip_displacement(n);
            ((w - w_exact).abs() / w_exact, (u - u_exact).abs() / u_exact)
        })
        .collect();
    eprintln!("elastica relative errors (w, u): {errors:?}");
    for pair in errors.windows(2) {
        assert!(pair[1].0 < pair[0].0 && pair[1].1 < pair[0].1, "refinement must come closer: {errors:?}");
    }
    let (w, u) = errors[errors.len() - 1];
    // Measured: 0.07 % and 0.08 % on the 80 × 8 × 8 mesh (29 % and 51 % on the coarsest).
    assert!(w < 0.005 && u < 0.005, "finest mesh off the elastica: {errors:?}");
}

/// A quadratic displacement field with the constant body force that balances it is an exact
/// solution of linear elasticity: T10 (straight edges) must reproduce it at every node to the
/// solver's tolerance, T4 cannot.
#[test]
fn t10_reproduces_a_quadratic_field_that_t4_cannot() {
    let mut t4 = box_tet([0.0; 3], [1.0, 0.8, 0.6], [3; 3]).unwrap();
    perturb_interior(&mut t4, 0.04);
    // u_i = c/2 xᵀ H_i x + c g_i·x: Hessians H_i and a gradient at the origin.
    let hessians = [
        Matrix3::new(1.0, 0.3, -0.2, 0.3, -0.5, 0.4, -0.2, 0.4, 0.8),
        Matrix3::new(-0.6, 0.1, 0.5, 0.1, 0.9, -0.3, 0.5, -0.3, 0.2),
        Matrix3::new(0.4, -0.7, 0.1, -0.7, 0.3, 0.6, 0.1, 0.6, -0.9),
    ];
    let c = 0.01;
    let exact = |p: &[f64; 3]| -> Vector3<f64> {
        let x = Vector3::from(*p);
        Vector3::from_fn(|i, _| c * (0.5 * x.dot(&(hessians[i] * x)) + 0.1 * (i as f64 + 1.0) * x[(i + 1) % 3]))
    };
    let material = Material::new(Law::Linear, 5000.0, 0.3);
    let (lambda, mu) = material.lame();
    // b = −((λ + μ) ∇(div u) + μ Δu), with ∂_j div u = c Σ_i H_i[i][j] and Δu_i = c tr H_i.
    let body = Vector3::from_fn(|j, _| {
        let grad_div: f64 = (0..3).map(|i| hessians[i][(i, j)]).sum();
        -c * ((lambda + mu) * grad_div + mu * hessians[j].trace())
    });
    let error = |m: &Mesh| {
        let mut problem = Problem::new(m.clone(), material);
        for n in boundary_nodes(m) {
            let u = exact(&m.nodes[n]);
            problem.prescribe(&[n], [u.x, u.y, u.z]);
        }
        let g = body / material.density;
        problem.add_gravity([g.x, g.y, g.z]).unwrap();
        let sol = StaticSolver::new(problem)
            .unwrap()
            .solve(&SolverOptions { rtol: 1e-13, utol: 1e-13, ..Default::default() })
            .unwrap();
        m.nodes
            .iter()
            .enumerate()
            .map(|(i, p)| (Vector3::from_column_slice(&sol.u[3 * i..3 * i + 3]) - exact(p)).norm())
            .fold(0.0, f64::max)
    };
    let scale = t4.nodes.iter().map(|p| exact(p).norm()).fold(0.0, f64::max);
    let (e4, e10) = (error(&t4), error(&t4.quadratic().unwrap()));
    assert!(e10 < 1e-9 * scale, "T10 error {e10:e} (field up to {scale:e})");
    assert!(e4 > 1e-4 * scale, "T4 reproduces a quadratic field? error {e4:e} (field up to {scale:e})");
}

/// A quadratic face carries a uniform traction on its mid-edge nodes only (∫ N dA = 0 at the
/// corners of a flat quadratic triangle): the loaded area and the resultant stay exact.
#[test]
fn quadratic_faces_carry_the_traction_resultant() {
    let m = mesh::box_mesh(CellKind::Tet10, [0.0; 3], [1.0, 1.0, 0.5], [4, 2, 1]).unwrap();
    let top = mesh::select::nodes_in_box(&m.nodes, [-1e-9, -1e-9, 0.5 - 1e-9], [1.0 + 1e-9, 1.0 + 1e-9, 0.5 + 1e-9]);
    let mut problem = Problem::new(m, Material::new(Law::Linear, 1.0, 0.3));
    assert!((problem.add_traction(&top, [0.0, 0.0, -2.0]) - 1.0).abs() < 1e-12);
    let fz: f64 = problem.f_ext.chunks(3).map(|f| f[2]).sum();
    assert!((fz + 2.0).abs() < 1e-12, "resultant {fz}");
    let corners = 15; // the 5 × 3 vertices of the top face
    let loaded = top.iter().filter(|&&n| problem.f_ext[3 * n + 2].abs() > 1e-12).count();
    assert_eq!(loaded, top.len() - corners, "only mid-edge nodes are loaded");
    assert!(top.iter().all(|&n| problem.f_ext[3 * n + 2] <= 1e-12));
    // Gravity: the consistent loads sum to the weight (corner shares are negative on T10).
    let mut heavy = problem.clone();
    heavy.f_ext.fill(0.0);
    heavy.add_gravity([0.0, 0.0, -10.0]).unwrap();
    let weight: f64 = heavy.f_ext.chunks(3).map(|f| f[2]).sum();
    assert!((weight + 1000.0 * 0.5 * 10.0).abs() < 1e-9, "weight {weight}");
}

#[test]
fn nonlinear_laws_agree_with_linear_for_small_loads() {
    for kind in KINDS {
        let n = [8, 2, 2];
        let (ul, m) = cantilever(kind, n, Law::Linear, 1e-4);
        let dl = tip_deflection(&ul, &m);
        for law in [Law::Corotational, Law::Svk, Law::NeoHookean] {
            let (u, m) = cantilever(kind, n, law, 1e-4);
            let d = tip_deflection(&u, &m);
            assert!((d - dl).abs() < 2e-3 * dl, "{kind:?} {law:?}: {d} vs linear {dl}");
        }
        // At a large load the models must differ (geometric nonlinearity).
        let (ul, m) = cantilever(kind, n, Law::Linear, 2.0);
        let (us, _) = cantilever(kind, n, Law::Svk, 2.0);
        let (dl, ds) = (tip_deflection(&ul, &m), tip_deflection(&us, &m));
        assert!((dl - ds).abs() > 0.05 * dl, "large load: svk {ds} vs linear {dl}");
    }
}

#[test]
fn gravity_and_springs_balance_exactly() {
    // A block hanging on springs only: total spring force equals total weight.
    let m = box_tet([0.0; 3], [0.1, 0.1, 0.1], [3, 3, 3]).unwrap();
    let all: Vec<usize> = (0..m.num_nodes()).collect();
    let mut problem = Problem::new(m, Material::new(Law::Svk, 5000.0, 0.45));
    problem.add_springs(&all, 10.0);
    problem.add_gravity([0.0, 0.0, -9.81]).unwrap();
    let weight = 1000.0 * 0.001 * 9.81;
    let fz: f64 = problem.f_ext.chunks(3).map(|f| f[2]).sum();
    assert!((fz + weight).abs() < 1e-12 * weight);
    let mut solver = StaticSolver::new(problem).unwrap();
    let sol = solver.solve(&SolverOptions::default()).unwrap();
    let spring_force: f64 = sol.u.chunks(3).map(|u| 10.0 * u[2]).sum();
    assert!((spring_force + weight).abs() < 1e-6 * weight, "springs carry {spring_force}, weight {weight}");
}

/// The reaction forces (clamp, node springs and a point spring) of a cantilever under a tip traction and its weight
/// balance the loads; under a hyperelastic law their moments balance too, about any point of
/// the deformed body (the clamp pushes up and turns back the tip's moment).
#[test]
fn reaction_forces_balance_the_loads_and_their_moments() {
    let (l, h) = (4.0, 1.0);
    for kind in KINDS {
        for law in LAWS {
            let m = mesh::box_mesh(kind, [0.0; 3], [l, h, h], [6, 2, 2]).unwrap();
            let clamp = mesh::select::nodes_in_box(&m.nodes, [-1e-9; 3], [1e-9, h + 1e-9, h + 1e-9]);
            let tip = mesh::select::nodes_in_box(&m.nodes, [l - 1e-9, -1e-9, -1e-9], [l + 1e-9, h + 1e-9, h + 1e-9]);
            let middle = mesh::select::nodes_in_box(&m.nodes, [1.9, -1e-9, -1e-9], [2.1, h + 1e-9, 1e-9]);
            let mut problem = Problem::new(m.clone(), Material { density: 0.2, ..Material::new(law, 3000.0, 0.3) });
            problem.fix(&clamp);
            problem.add_springs(&middle[..middle.len() / 2], 40.0);
            // A point spring between two nodes (an attachment's foundation), pulled up a little.
            let pair = &middle[middle.len() / 2..];
            problem.point_springs.push(PointSpring {
                nodes: vec![(pair[0], 0.5), (pair[1], 0.5)],
                target: [0.0, 0.0, 0.01],
                stiffness: 30.0,
                normal: [0.0, 0.0, 1.0],
                normal_stiffness: 20.0,
            });
            problem.add_traction(&tip, [0.0, 3.0, -4.0]);
            problem.add_gravity([0.0, 0.0, -9.81]).unwrap();
            let load: Vec<f64> = (0..3).map(|d| problem.f_ext.iter().skip(d).step_by(3).sum()).collect();
            let mut solver = StaticSolver::new(problem).unwrap();
            let sol = solver.solve(&SolverOptions { load_steps: 2, rtol: 1e-10, ..Default::default() }).unwrap();
            let r = solver.reaction_forces(&sol.u).unwrap();
            let held = |n: usize| clamp.contains(&n) || middle.contains(&n);
            assert!((0..m.num_nodes()).filter(|&n| !held(n)).all(|n| r[3 * n..3 * n + 3] == [0.0; 3]));
            let total: Vec<f64> = (0..3).map(|d| r.iter().skip(d).step_by(3).sum()).collect();
            let scale = mesh::norm([load[0], load[1], load[2]]);
            for d in 0..3 {
                assert!((total[d] + load[d]).abs() < 1e-6 * scale, "{kind:?} {law:?}: {total:?} vs loads {load:?}");
            }
            assert!(total[2] > 0.0, "the supports push up: {total:?}");
            if matches!(law, Law::Svk | Law::NeoHookean) {
                let f_ext = &solver.problem().f_ext;
                let mut moment = Vector3::zeros();
                for (n, p) in m.nodes.iter().enumerate() {
                    let x = Vector3::new(p[0] + sol.u[3 * n], p[1] + sol.u[3 * n + 1], p[2] + sol.u[3 * n + 2]);
                    moment += x.cross(&Vector3::from_fn(|d, _| r[3 * n + d] + f_ext[3 * n + d]));
                }
                assert!(moment.norm() < 1e-6 * scale * l, "{kind:?} {law:?}: moment {moment:?}");
            }
        }
    }
}

#[test]
fn point_springs_balance_gravity_and_pull_their_point() {
    // The block hanging on springs at points of its cells (each point between two nodes that
    // share no element too: that coupling is left out of the tangent) carries its weight.
    let m = box_tet([0.0; 3], [0.1, 0.1, 0.1], [3, 3, 3]).unwrap();
    let n = m.num_nodes();
    let mut problem = Problem::new(m, Material::new(Law::Svk, 5000.0, 0.45));
    problem.add_gravity([0.0, 0.0, -9.81]).unwrap();
    let spring = |nodes: Vec<(usize, f64)>, target: [f64; 3]| PointSpring {
        nodes,
        target,
        stiffness: 10.0,
        normal: [0.0, 0.0, 1.0],
        normal_stiffness: 20.0,
    };
    problem.point_springs = (0..n).map(|k| spring(vec![(k, 0.75), ((k * 7 + 3) % n, 0.25)], [0.0; 3])).collect();
    let weight = 1000.0 * 0.001 * 9.81;
    let mut solver = StaticSolver::new(problem.clone()).unwrap();
    let sol = solver.solve(&SolverOptions::default()).unwrap();
    let carried: f64 = problem
        .point_springs
        .iter()
        .map(|s| 30.0 * s.nodes.iter().map(|&(k, w)| w * sol.u[3 * k + 2]).sum::<f64>())
        .sum();
    assert!((carried + weight).abs() < 1e-6 * weight, "point springs carry {carried}, weight {weight}");
    // A stiff spring on a point of a cell takes the point to its target.
    let cell = problem.mesh.cells.cell(0).to_vec();
    let point = vec![(cell[0], 0.1), (cell[1], 0.2), (cell[2], 0.3), (cell[3], 0.4)];
    let target = [0.004, -0.002, 0.003];
    problem.f_ext.iter_mut().for_each(|f| *f = 0.0);
    problem.point_springs = vec![PointSpring { stiffness: 1e6, ..spring(point.clone(), target) }];
    let top: Vec<usize> = (0..n).filter(|&k| problem.mesh.nodes[k][2] > 0.0999).collect();
    problem.fix(&top);
    let sol = StaticSolver::new(problem).unwrap().solve(&SolverOptions::default()).unwrap();
    for (d, t) in target.iter().enumerate() {
        let x: f64 = point.iter().map(|&(k, w)| w * sol.u[3 * k + d]).sum();
        assert!((x - t).abs() < 1e-3 * t.abs(), "component {d}: {x} against {t}");
    }
}

#[test]
fn warm_start_from_solution_needs_no_iteration() {
    let (u, m) = cantilever(CellKind::Hex8, [8, 2, 2], Law::Svk, 0.05);
    let clamp = mesh::select::nodes_in_box(&m.nodes, [-1e-9; 3], [1e-9, 1.1, 1.1]);
    let tip = mesh::select::nodes_in_box(&m.nodes, [3.999, -1.0, -1.0], [4.001, 2.0, 2.0]);
    let mut problem = Problem::new(m, Material::new(Law::Svk, 300.0, 0.0));
    problem.fix(&clamp);
    problem.add_traction(&tip, [0.0, 0.0, -0.05]);
    let mut solver = StaticSolver::new(problem).unwrap();
    let sol = solver.solve_from(Some(&u), &SolverOptions::default()).unwrap();
    assert!(sol.iterations <= 1, "warm start took {} iterations", sol.iterations);
}

/// Springs that pull the top of a block by 1e-19 m (what a registration's cloud of the organ at
/// rest asks once given in mm and read back in m): the co-rotational law computes its forces from
/// positions, where so small a motion is lost to rounding, so the relative residual cannot come
/// down; below the force floor it counts as no load and the solve converges, with no motion. A
/// small load still above rounding (1e-3 Pa, under the floor) is solved to the tolerance: the
/// co-rotational cantilever bends as the linear one does.
#[test]
fn a_load_at_the_level_of_rounding_is_no_load() {
    let m = box_tet([0.0; 3], [0.1, 0.1, 0.1], [3, 3, 3]).unwrap();
    let mut problem = Problem::new(m, Material::new(Law::Corotational, 5000.0, 0.48));
    let bottom: Vec<usize> = (0..problem.mesh.num_nodes()).filter(|&k| problem.mesh.nodes[k][2] < 1e-9).collect();
    problem.fix(&bottom);
    let top = (0..problem.mesh.num_nodes()).filter(|&k| problem.mesh.nodes[k][2] > 0.0999);
    problem.point_springs = top
        .map(|k| PointSpring {
            nodes: vec![(k, 1.0)],
            target: [1e-19, -2e-19, 3e-19],
            stiffness: 10.0,
            normal: [0.0, 0.0, 1.0],
            normal_stiffness: 0.0,
        })
        .collect();
    let sol = StaticSolver::new(problem).unwrap().solve(&SolverOptions::default()).unwrap();
    let largest = sol.u.iter().fold(0.0f64, |a, b| a.max(b.abs()));
    assert!(largest < 1e-15, "moved by {largest:e} m");
    let (linear, m) = cantilever(CellKind::Hex8, [8, 2, 2], Law::Linear, 1e-3);
    let (corotational, _) = cantilever(CellKind::Hex8, [8, 2, 2], Law::Corotational, 1e-3);
    let ratio = tip_deflection(&corotational, &m) / tip_deflection(&linear, &m);
    assert!((ratio - 1.0).abs() < 1e-4, "co-rotational / linear tip deflection {ratio} under 1e-3 Pa");
}

/// A body that nothing holds (no fixed node, no spring), or that is held only along one line,
/// has a singular stiffness: a solve refuses it before any iteration, saying why; three fixed
/// nodes not on one line hold it.
#[test]
fn a_body_held_against_no_rigid_motion_is_refused() {
    let m = box_tet([0.0; 3], [0.04, 0.02, 0.02], [4, 2, 2]).unwrap();
    let material = Material::new(Law::NeoHookean, 5000.0, 0.45);
    let mut floating = Problem::new(m.clone(), material);
    floating.f_ext[2] = -0.01;
    let solve = |problem: Problem| StaticSolver::new(problem).unwrap().solve(&SolverOptions::default());
    let err = solve(floating.clone()).expect_err("a floating body is refused");
    assert!(err.to_string().contains("nothing holds the body"), "{err}");

    // Two corner nodes: the edge between them is an axis it can turn about.
    let corner = |p: [f64; 3]| m.nodes.iter().position(|q| mesh::distance(*q, p) < 1e-12).unwrap();
    let (a, b, c) = (corner([0.0; 3]), corner([0.04, 0.0, 0.0]), corner([0.0, 0.02, 0.0]));
    let mut on_a_line = floating.clone();
    on_a_line.fix(&[a, b]);
    let err = solve(on_a_line.clone()).expect_err("a body held along a line is refused");
    assert!(err.to_string().contains("only along one line"), "{err}");

    // A third corner off that edge, or a spring on it, holds it.
    let mut held = on_a_line.clone();
    held.fix(&[c]);
    assert!(solve(held).is_ok());
    let mut tied = on_a_line;
    tied.springs[c] = 10.0;
    assert!(solve(tied).is_ok());

    // A second block beside the first, touching it nowhere, with nothing to hold it: named apart.
    let mesh::Cells::Tet4(tets) = &m.cells else { panic!("tetrahedra") };
    let n = m.num_nodes();
    let nodes: Vec<[f64; 3]> = m
        .nodes
        .iter()
        .chain(m.nodes.iter().map(|p| [p[0], p[1], p[2] + 0.03]).collect::<Vec<_>>().iter())
        .copied()
        .collect();
    let cells: Vec<[usize; 4]> = tets.iter().copied().chain(tets.iter().map(|t| t.map(|k| k + n))).collect();
    let mut two = Problem::new(mesh::Mesh::new(nodes, mesh::Cells::Tet4(cells)).unwrap(), material);
    two.fix(&[a, b, c]);
    let err = solve(two).expect_err("a loose second body is refused").to_string();
    assert!(err.contains("in 1 piece(s) of the mesh lie apart from the rest, touching it nowhere"), "{err}");
}

#[test]
fn failures_are_reported_not_looped() {
    // Too few iterations allowed for a large load, force control alone: a NotConverged error, not
    // a hang.
    let m = box_hex([0.0; 3], [4.0, 1.0, 1.0], [8, 2, 2]).unwrap();
    let clamp = mesh::select::nodes_in_box(&m.nodes, [-1e-9; 3], [1e-9, 1.1, 1.1]);
    let tip = mesh::select::nodes_in_box(&m.nodes, [3.999, -1.0, -1.0], [4.001, 2.0, 2.0]);
    let mut problem = Problem::new(m.clone(), Material::new(Law::Svk, 300.0, 0.3));
    problem.fix(&clamp);
    problem.add_traction(&tip, [0.0, 0.0, -5.0]);
    let mut solver = StaticSolver::new(problem).unwrap();
    let options = SolverOptions {
        max_iterations: 2,
        max_step_cuts: 1,
        continuation: fem::Continuation::ForceOnly,
        ..Default::default()
    };
    let err = solver.solve(&options).unwrap_err();
    assert!(matches!(err, fem::FemError::NotConverged { .. }), "{err}");

    // Crushing a block to beyond zero thickness: an inverted-element error.
    let mut problem = Problem::new(m.clone(), Material::new(Law::NeoHookean, 300.0, 0.3));
    problem.fix(&clamp);
    problem.prescribe(&tip, [-6.0, 0.0, 0.0]);
    let mut solver = StaticSolver::new(problem).unwrap();
    let err = solver.solve(&SolverOptions { max_step_cuts: 2, ..Default::default() }).unwrap_err();
    assert!(matches!(err, fem::FemError::InvertedElement { .. } | fem::FemError::NotConverged { .. }), "{err}");

    // NaN in the loads.
    let mut problem = Problem::new(m, Material::new(Law::Svk, 300.0, 0.3));
    problem.fix(&clamp);
    problem.f_ext[5] = f64::NAN;
    let err = StaticSolver::new(problem).unwrap_err();
    assert!(matches!(err, fem::FemError::NonFinite(_)), "{err}");
}

/// An SVK beam bent by 9 cm (T10, ν = 0.49) whose first full-load attempt meets an indefinite
/// tangent far from equilibrium, then asked for a residual below round-off: the failure is a
/// Newton one, not SVK's compressive limit point (no element is compressed anywhere near it).
#[test]
fn a_tolerance_below_round_off_is_not_diagnosed_as_a_limit_point() {
    let problem = fem::verification::bent_beam(CellKind::Tet4, 2, Law::Svk, 0.49, 0.025).unwrap();
    let mut solver = StaticSolver::new(problem).unwrap();
    let reachable = solver.solve(&SolverOptions { rtol: 1e-9, utol: 0.0, ..Default::default() }).unwrap();
    assert!(reachable.u.iter().fold(0.0f64, |a, b| a.max(b.abs())) > 0.08);
    let err = solver.solve(&SolverOptions { rtol: 1e-14, utol: 0.0, ..Default::default() }).unwrap_err();
    assert!(matches!(err, fem::FemError::NotConverged { .. }), "{err}");
}

/// A total force is spread over a node set by tributary surface area, not in equal shares:
/// on the top face of a 1 × 1 box with 4 × 2 cells, a corner node carries 1/32 of it, an
/// node on an edge 1/16, an inner node 1/8; an interior node set falls back to equal shares.
#[test]
fn total_force_is_shared_by_tributary_area() {
    let m = box_hex([0.0; 3], [1.0, 1.0, 0.5], [4, 2, 1]).unwrap();
    let top = mesh::select::nodes_in_box(&m.nodes, [-1e-9, -1e-9, 0.5 - 1e-9], [1.0 + 1e-9, 1.0 + 1e-9, 0.5 + 1e-9]);
    assert_eq!(top.len(), 15);
    let shares = fem::force_shares(&m, &top);
    assert!((shares.iter().map(|(_, s)| s).sum::<f64>() - 1.0).abs() < 1e-12);
    for &(n, s) in &shares {
        let [x, y, _] = m.nodes[n];
        let on_edge = |c: f64| c.abs() < 1e-9 || (c - 1.0).abs() < 1e-9;
        let expected = match (on_edge(x), on_edge(y)) {
            (true, true) => 1.0 / 32.0,
            (true, false) | (false, true) => 1.0 / 16.0,
            (false, false) => 1.0 / 8.0,
        };
        assert!((s - expected).abs() < 1e-12, "node at ({x}, {y}): share {s}, expected {expected}");
    }
    // The same as the traction of that resultant on the face.
    let mut by_force = Problem::new(m.clone(), Material::new(Law::Linear, 1.0, 0.3));
    by_force.add_force(&top, [0.0, 0.0, -2.0]);
    let mut by_traction = by_force.clone();
    by_traction.f_ext.fill(0.0);
    assert!((by_traction.add_traction(&top, [0.0, 0.0, -2.0]) - 1.0).abs() < 1e-12);
    assert!(by_force.f_ext.iter().zip(&by_traction.f_ext).all(|(a, b)| (a - b).abs() < 1e-12));
    // Interior nodes only (a hexahedral box of 2 × 2 × 2 cells has one): equal shares.
    let cube = box_hex([0.0; 3], [1.0; 3], [2, 2, 2]).unwrap();
    let centre = mesh::select::nodes_in_box(&cube.nodes, [0.49; 3], [0.51; 3]);
    assert_eq!(fem::force_shares(&cube, &centre), vec![(centre[0], 1.0)]);
}

/// A block crushed by a force past SVK's compressive limit stops there, naming the most
/// compressed element at its last equilibrium, short of the stress's peak: the same element
/// whether the force asked for was twice the limit or three times, where the iterate that failed
/// strays past the peak, differently.
#[test]
fn an_svk_limit_point_is_told_of_the_last_equilibrium() {
    let m = box_hex([0.0; 3], [0.1, 0.1, 0.1], [2, 2, 2]).unwrap();
    let bottom = mesh::select::nodes_in_box(&m.nodes, [-1.0, -1.0, -1e-9], [1.0, 1.0, 1e-9]);
    let top = mesh::select::nodes_in_box(&m.nodes, [-1.0, -1.0, 0.0999], [1.0, 1.0, 1.0]);
    let limit = |load: f64| {
        let mut problem = Problem::new(m.clone(), Material::new(Law::Svk, 5000.0, 0.3));
        problem.fix(&bottom);
        problem.add_traction(&top, [0.0, 0.0, -load]);
        match StaticSolver::new(problem).unwrap().solve(&SolverOptions::default()) {
            Err(fem::FemError::LimitPoint { element, stretch, load_factor }) => (element, stretch, load * load_factor),
            other => panic!("{load} Pa: {:?}", other.map(|s| s.iterations)),
        }
    };
    // (element, stretch, load reached in Pa): the last equilibria lie a load step's cut apart
    // (781 and 844 Pa), each short of the peak of SVK's uniaxial stress (stretch 0.577).
    let (twice, thrice) = (limit(2000.0), limit(3000.0));
    assert_eq!(twice.0, thrice.0, "the same element: {twice:?} {thrice:?}");
    assert!((twice.2 - thrice.2).abs() < 0.1 * twice.2, "the limit load: {twice:?} {thrice:?}");
    for (_, stretch, _) in [twice, thrice] {
        assert!(stretch > 0.65 && stretch < 0.8, "the stretch at equilibrium: {twice:?} {thrice:?}");
    }
}
