//! augsim's static solver against CalculiX on two real livers, Neo-Hookean at ν = 0.49, held near
//! their back and pushed: augsim's standard T4 and T10 against CalculiX's C3D4 and C3D10 on the
//! same meshes, fixed nodes and nodal loads (`tests/data/real_organs/README.md`). CalculiX's
//! Neo-Hookean law has the same shear and bulk moduli as augsim's but another volumetric energy
//! (see [`calculix`]): the two agree to within a few per cent, not to the last digit.
//!
//! The stored CalculiX solutions are remade, with CalculiX on the PATH, by
//! `cargo test --release -p augsim-experiment --test real_organs -- --ignored`.

use std::path::{Path, PathBuf};

use augsim_experiment::calculix;
use fem::{Continuation, FemError, Formulation, Law, Material, Problem, SolverOptions, StaticSolver};
use mesh::select::{Ball, Near, NodeSelection};
use mesh::Mesh;

fn data(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/real_organs").join(name)
}

/// A liver, where it is held and where it is pushed.
struct Organ {
    /// The case's name, which its CalculiX files start with.
    name: &'static str,
    /// Its mesh's file stem.
    mesh: &'static str,
    held: NodeSelection,
    push: Ball,
    direction: [f64; 3],
}

fn organs() -> [Organ; 3] {
    let amos_held = |distance: f64| {
        NodeSelection::Near(Near {
            points: Vec::new(),
            file: Some(data("amos_liver_attach.csv")),
            distance,
            surface: true,
        })
    };
    // The distance at which the AMOS liver is held over the share of its surface `prepare` holds.
    let landmarks = mesh::io::points::read_points_csv(&data("amos_liver_attach.csv")).unwrap();
    let share = mesh::distance_holding_share(&whole("amos_liver"), &landmarks, app::prepare::HELD_SHARE).unwrap();
    [
        // A liver segmented from a public CT scan (AMOS), held within 25 mm of three landmarks on its
        // back, pushed on its front.
        Organ {
            name: "amos_liver",
            mesh: "amos_liver",
            held: amos_held(0.025),
            push: Ball { centre: [0.0, -0.09, 0.0], radius: 0.03 },
            direction: [0.0, 1.0, 0.0],
        },
        // SOFA's liver (CT-derived), 20 cm long, held along its top, the tip of its right lobe pushed sideways.
        Organ {
            name: "sofa_liver",
            mesh: "sofa_liver",
            held: NodeSelection::Intersection(vec![
                NodeSelection::Surface,
                NodeSelection::Box { min: [-0.03, 0.055, -1.0], max: [0.03, 1.0, 1.0] },
            ]),
            push: Ball { centre: [0.09, 0.04, 0.0], radius: 0.025 },
            direction: [0.0, 0.0, 1.0],
        },
        // The AMOS liver held as `prepare` holds an organ by default, over 12 % of its surface
        // around the same landmarks (35 mm), pushed as above by up to `prepare`'s largest push.
        Organ {
            name: "amos_liver_held12",
            mesh: "amos_liver",
            held: amos_held(share),
            push: Ball { centre: [0.0, -0.09, 0.0], radius: 0.03 },
            direction: [0.0, 1.0, 0.0],
        },
    ]
}

fn read_mesh(stem: &str) -> Mesh {
    mesh::io::read_mesh(data(&format!("{stem}.vtu"))).unwrap()
}

/// The organ's mesh as read, and without the pieces that hang on it by an edge or a vertex.
fn meshes(organ: &Organ) -> (Mesh, Mesh) {
    (read_mesh(organ.mesh), whole(organ.mesh))
}

/// The mesh without the pieces that hang on it by an edge or a vertex.
fn whole(stem: &str) -> Mesh {
    mesh::without_small_pieces(read_mesh(stem)).unwrap()
}

/// The organ pushed by `force` newtons, Neo-Hookean (E 5 kPa, ν 0.49), standard elements of `order`.
fn problem(organ: &Organ, mesh: Mesh, force: f64, order: u8) -> Problem {
    let material =
        Material::new(Law::NeoHookean, 5000.0, 0.49).with_order(order).with_formulation(Formulation::Standard);
    let mut p = Problem::new(mesh, material);
    let held = organ.held.select(&p.mesh).unwrap();
    p.fix(&held);
    let pushed = NodeSelection::Ball(organ.push).select(&p.mesh).unwrap();
    p.add_force(&pushed, organ.direction.map(|d| d * force));
    p
}

/// The cases: organ, force (N), element order.
const CASES: [(usize, f64, u8); 9] = [
    (0, 0.2, 1),
    (0, 1.0, 1),
    (0, 0.2, 2),
    (1, 0.5, 1),
    (1, 2.0, 1),
    (1, 0.5, 2),
    (2, 1.5, 1),
    (2, 3.0, 1),
    (2, 1.0, 2),
];

/// Each case's name, problem and stored CalculiX solution, each organ's mesh read once.
fn cases() -> Vec<(String, Problem, PathBuf)> {
    let organs = organs();
    let whole: Vec<Mesh> = organs.iter().map(|organ| meshes(organ).1).collect();
    CASES
        .iter()
        .map(|&(o, force, order)| {
            let organ = &organs[o];
            let name = format!("{} {force} N, order {order}", organ.name);
            (name, problem(organ, whole[o].clone(), force, order), reference(organ, force, order))
        })
        .collect()
}

fn reference(organ: &Organ, force: f64, order: u8) -> PathBuf {
    data(&format!("{}_{force}N_{}.dat", organ.name, if order == 1 { "c3d4" } else { "c3d10" }))
}

fn max_norm(u: &[f64]) -> f64 {
    u.chunks_exact(3).map(|c| (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt()).fold(0.0, f64::max)
}

/// A tetrahedron that hangs on the rest of the mesh by a vertex (as meshing left one in the AMOS
/// liver) can turn about it freely: the solve is refused, saying where, instead of failing with an
/// inverted element, by the element's number in the mesh file (the same mesh as a CalculiX deck,
/// numbered from 1, names it 2480); without it, the same problem solves.
#[test]
fn a_tetrahedron_hanging_by_a_vertex_is_refused_and_the_mesh_without_it_solves() {
    let organ = &organs()[0];
    let (read, whole) = meshes(organ);
    assert_eq!((read.num_nodes(), read.cells.len()), (830, 3058));
    assert_eq!((whole.num_nodes(), whole.cells.len()), (827, 3056), "two one-element pieces dropped");
    let error =
        StaticSolver::new(problem(organ, read.clone(), 0.2, 1)).unwrap().solve(&SolverOptions::default()).unwrap_err();
    let message = error.to_string();
    assert!(
        message.contains("hang on the rest by an edge or a vertex") && message.contains("element 2479"),
        "{message}"
    );
    let dir = tempfile::tempdir().unwrap();
    let deck = dir.path().join("liver.inp");
    std::fs::write(&deck, calculix::input_deck(&problem(organ, read.clone(), 0.2, 1)).unwrap()).unwrap();
    let from_deck = mesh::io::read_inp(&deck).unwrap();
    assert_eq!(from_deck.file_cells, Some((1..=read.cells.len()).collect()));
    let error = StaticSolver::new(problem(organ, from_deck, 0.2, 1)).unwrap().solve(&SolverOptions::default());
    let message = error.unwrap_err().to_string();
    assert!(message.contains("from element 2480,"), "{message}");
    let solution = StaticSolver::new(problem(organ, whole, 0.2, 1)).unwrap().solve(&SolverOptions::default()).unwrap();
    assert!(max_norm(&solution.u) > 1e-3);
}

/// augsim's solution of every case is within 1 % of CalculiX's: its largest displacement, and the
/// root-mean-square difference of the nodal displacements relative to it. The AMOS liver held as
/// `prepare` holds it moves by 5–15 cm under 1.5–3 N, the range of `prepare`'s pushes.
#[test]
fn real_livers_deform_as_calculix_computes() {
    for (name, p, reference) in cases() {
        let dat = std::fs::read_to_string(reference).unwrap();
        let peer = calculix::read_displacements(&dat, p.mesh.num_nodes()).unwrap();
        let ours = StaticSolver::new(p).unwrap().solve(&SolverOptions::default()).unwrap().u;
        let (a, b) = (max_norm(&ours), max_norm(&peer));
        let rms = (ours.iter().zip(&peer).map(|(x, y)| (x - y).powi(2)).sum::<f64>() / (ours.len() / 3) as f64).sqrt();
        let case = format!("{name}: augsim {:.2} mm, CalculiX {:.2} mm, rms {:.3} mm", 1e3 * a, 1e3 * b, 1e3 * rms);
        println!("{case}");
        assert!((a - b).abs() <= 0.01 * b && rms <= 0.01 * b, "{case}");
    }
}

/// The AMOS liver's quadratic mesh pushed by 1 N: force control follows it to load factor 0.918,
/// where its response has softened to a few per cent of its stiffness at rest and CalculiX stops
/// too ("increment size smaller than minimum"). Past that limit point the organ swings on to an
/// equilibrium more than 20 cm away, which the solver's patient attempt at a load step
/// reaches: the state it returns balances the load (to 1e-4 of it: the solver accepts a small
/// last increment at a relative residual of up to 1e-3). It gets there in 853 iterations and 172
/// factorisations; with the patient attempt made only as the last resort, after load steps had
/// crept towards the limit point, and a refactorisation every second iteration of a sequence that
/// does not converge, it took 1,056 and 363.
#[test]
fn past_its_limit_point_a_hanging_liver_swings_on_to_an_equilibrium() {
    let organ = &organs()[0];
    let p = problem(organ, meshes(organ).1, 1.0, 2);
    let load = p.f_ext.clone();
    let mut solver = StaticSolver::new(p).unwrap();
    let solution = solver.solve(&SolverOptions::default()).unwrap();
    assert!(max_norm(&solution.u) > 0.2, "moved {} m", max_norm(&solution.u));
    assert!(solution.snapped_from.is_some_and(|l| l > 0.5), "said to snap: {:?}", solution.snapped_from);
    let cost = format!("{} iterations, {} factorisations", solution.iterations, solution.factorizations);
    assert!(solution.iterations < 1000 && solution.factorizations < 250, "{cost}");
    let internal = solver.internal_force(&solution.u).unwrap();
    let free: Vec<usize> = (0..load.len()).filter(|&d| solver.free_index(d).is_some()).collect();
    let residual = free.iter().map(|&d| (internal[d] - load[d]).powi(2)).sum::<f64>().sqrt();
    let scale = free.iter().map(|&d| load[d].powi(2)).sum::<f64>().sqrt();
    assert!(residual <= 1e-4 * scale, "residual {residual} N against a load of {scale} N");
}

/// The AMOS liver's quadratic mesh pulled forward at five nodes by 0.17 N each (Neo-Hookean, ν
/// 0.49, held where `prepare` attached it): its path softens so far on the way that a load step
/// cut once still fails. A patient attempt over a whole load step from there (from load factor
/// 0.5 to 1) finds an equilibrium 283.6 mm away on another branch, where the path followed in 32
/// load steps reaches 272.4 mm (and by arc length, to 3e-7 of it). Made over the step that
/// failed, as force control makes it, it keeps to the path.
#[test]
fn force_control_keeps_to_the_path_where_it_softens() {
    let material = Material::new(Law::NeoHookean, 5000.0, 0.49).with_order(2).with_formulation(Formulation::Standard);
    let mut p = Problem::new(whole("amos_liver"), material);
    p.fix(&NodeSelection::Region("attached".into()).select(&p.mesh).unwrap());
    for node in [134, 198, 433, 491, 803] {
        p.add_force(&NodeSelection::List(vec![node]).select(&p.mesh).unwrap(), [0.0, 0.17, 0.0]);
    }
    let solve = |options: SolverOptions| StaticSolver::new(p.clone()).unwrap().solve(&options).unwrap().u;
    let at_once = solve(SolverOptions::default());
    let stepped =
        solve(SolverOptions { load_steps: 32, continuation: Continuation::ForceOnly, ..SolverOptions::default() });
    let largest = max_norm(&stepped);
    let difference = at_once.iter().zip(&stepped).fold(0.0f64, |m, (a, b)| m.max((a - b).abs())) / largest;
    assert!(
        largest > 0.25 && difference < 1e-4,
        "moved {largest} m; one load step {difference:e} of it off 32 steps' path"
    );
}

/// The AMOS liver pushed forward at five nodes by 0.2 N each, F-bar, as `augsim solve` solves it
/// (the one tetrahedron that hangs idle left out): its path softens to a few per cent of its
/// stiffness at rest, stiffens again, and meets a limit point at load factor 0.970 inside the last
/// of 7 load steps, whose stiffness falls only to 0.56 times the step's before it. A check by arc
/// length of that step finds the limit point, as 10 steps, which see the snap itself, do.
#[test]
fn a_short_snap_within_the_last_load_step_is_told() {
    let material = Material::new(Law::NeoHookean, 5000.0, 0.49).with_formulation(Formulation::Fbar);
    let pushed = |mesh: Mesh| {
        let mut p = Problem::new(mesh, material);
        p.fix(&NodeSelection::Region("attached".into()).select(&p.mesh).unwrap());
        for node in [134, 198, 433, 491, 803] {
            p.add_force(&NodeSelection::List(vec![node]).select(&p.mesh).unwrap(), [0.0, 0.2, 0.0]);
        }
        p
    };
    let whole = pushed(read_mesh("amos_liver"));
    let idle = whole.idle_hanging_pieces().concat();
    assert_eq!(idle.len(), 1);
    let p = pushed(whole.mesh.without_cells(&idle).unwrap());
    let solve = |load_steps: usize, confirm_snaps: bool| {
        let options = SolverOptions { load_steps, confirm_snaps, ..SolverOptions::default() };
        StaticSolver::new(p.clone()).unwrap().solve(&options).unwrap()
    };
    let checked = solve(1, true);
    assert_eq!(checked.load_steps, 7);
    assert!(max_norm(&checked.u) > 0.2, "moved {} m", max_norm(&checked.u));
    assert!(checked.snapped_from.is_some_and(|l| (0.95..0.99).contains(&l)), "{:?}", checked.snapped_from);
    let finer = solve(10, true).snapped_from.unwrap();
    assert!((finer - checked.snapped_from.unwrap()).abs() < 1e-3, "{finer}");
}

/// The AMOS liver, Saint-Venant–Kirchhoff at ν = 0.3, pushed by 0.5 N or by 1 N: both stop at
/// its compressive limit, about 0.48 N (CalculiX stops at 0.484 N too), naming the element most
/// compressed at the last equilibrium and its stretch there, the same for either push (CalculiX's
/// last converged state: 0.200), not the stretch of the iterate that failed past it.
#[test]
fn saint_venant_kirchhoff_s_limit_point_is_told_of_its_last_equilibrium() {
    let organ = &organs()[0];
    let limit = |force: f64| {
        let mut p = problem(organ, meshes(organ).1, force, 1);
        p.material = Material::new(Law::Svk, 5000.0, 0.3).with_formulation(Formulation::Standard);
        match StaticSolver::new(p).unwrap().solve(&SolverOptions::default()) {
            Err(FemError::LimitPoint { element, stretch, load_factor }) => (element, stretch, force * load_factor),
            other => panic!("{force} N: {:?}", other.map(|s| max_norm(&s.u))),
        }
    };
    let (half, one) = (limit(0.5), limit(1.0));
    assert_eq!(half.0, one.0, "{half:?} {one:?}");
    assert!((half.2 - one.2).abs() < 0.01 * one.2 && (0.47..0.49).contains(&one.2), "{half:?} {one:?}");
    assert!((half.1 - one.1).abs() < 0.02 && (0.15..0.25).contains(&one.1), "{half:?} {one:?}");
}

/// The load factor of the last increment CalculiX converged (its status file: one line per
/// attempt, `U` after an attempt that did not converge).
fn last_converged(sta: &str) -> f64 {
    sta.lines()
        .rev()
        .find_map(|line| {
            let fields: Vec<&str> = line.split_whitespace().collect();
            (fields.len() == 7 && !fields[2].ends_with('U')).then(|| fields[4].parse::<f64>().ok()).flatten()
        })
        .unwrap()
}

/// The AMOS liver's linear mesh has a limit point between 1.4 and 1.6 N, as CalculiX's C3D4 has:
/// - under 1.4 N both find the organ pushed by about 9 cm, within 5 % of each other (the
///   response is steep this near the limit point, so the two laws' volumetric energies, the same
///   at small strain, tell more than the 1 % of the other cases);
/// - under 1.6 N CalculiX stops at load factor 0.918 (1.47 N: "increment size smaller than
///   minimum"), and augsim's arc-length continuation, which follows stable equilibria only, stops
///   at the load where the path turns back, within 3 % of it;
/// - past it the organ snaps, turning about its held strip by more than 20 cm, which force
///   control's patient attempt finds and CalculiX does not.
#[test]
fn a_hanging_liver_meets_its_limit_point_where_calculix_stops() {
    let organ = &organs()[0];
    let whole = meshes(organ).1;
    let below = problem(organ, whole.clone(), 1.4, 1);
    let dat = std::fs::read_to_string(data("amos_liver_1.4N_c3d4.dat")).unwrap();
    let peer = calculix::read_displacements(&dat, below.mesh.num_nodes()).unwrap();
    let ours = StaticSolver::new(below).unwrap().solve(&SolverOptions::default()).unwrap().u;
    let (a, b) = (max_norm(&ours), max_norm(&peer));
    assert!(b > 0.08 && (a - b).abs() <= 0.05 * b, "under 1.4 N: augsim {a} m, CalculiX {b} m");

    let past = problem(organ, whole, 1.6, 1);
    let stop = 1.6 * last_converged(&std::fs::read_to_string(data("amos_liver_1.6N_c3d4.sta")).unwrap());
    let by_arc = SolverOptions { continuation: Continuation::ArcLength, ..SolverOptions::default() };
    match StaticSolver::new(past.clone()).unwrap().solve(&by_arc) {
        Err(FemError::NoEquilibrium { load_factor, .. }) => {
            let limit = 1.6 * load_factor;
            assert!((limit - stop).abs() <= 0.03 * stop, "limit load: augsim {limit} N, CalculiX stops at {stop} N");
        }
        other => panic!("the arc-length continuation went past the limit point: {:?}", other.map(|s| s.load_steps)),
    }
    let snapped = StaticSolver::new(past).unwrap().solve(&SolverOptions::default()).unwrap();
    assert!(max_norm(&snapped.u) > 0.2, "under 1.6 N the organ moved {} m", max_norm(&snapped.u));
}

/// Writes the CalculiX solutions the tests above compare with (needs `ccx`).
#[test]
#[ignore]
fn write_calculix_references() {
    for (name, p, reference) in cases() {
        let dir = tempfile::tempdir().unwrap();
        calculix::solve(&p, dir.path()).unwrap_or_else(|e| panic!("{name}: {e}"));
        std::fs::copy(dir.path().join("peer.dat"), reference).unwrap();
    }
    let organ = &organs()[0];
    for (force, kept) in [(1.4, "dat"), (1.6, "sta")] {
        let dir = tempfile::tempdir().unwrap();
        // Past the limit point CalculiX fails; its status file says where it stopped.
        let solved = calculix::solve(&problem(organ, meshes(organ).1, force, 1), dir.path());
        assert_eq!(solved.is_ok(), kept == "dat");
        std::fs::copy(dir.path().join(format!("peer.{kept}")), data(&format!("amos_liver_{force}N_c3d4.{kept}")))
            .unwrap();
    }
}

/// The AMOS liver's surface meshed anew at the sizes `prepare` and `mesh` use (3,000 and 5,000
/// tetrahedra), about them and as coarse as a live stream's (700, 800): one piece joined through
/// faces, with no edge of four triangles, at each. Where the liver is thinner than the lattice,
/// stuffing left parts hanging on the rest by an edge at most of these sizes, by a vertex at 700
/// and 800.
#[test]
fn a_real_liver_is_meshed_in_one_piece_at_every_size() {
    let boundary = mesh::boundary_surface(&whole("amos_liver")).compacted();
    // As `prepare` takes a segmentation's surface: repaired (this one has an edge of four triangles).
    let (surface, _) = mesh::rebuild::repair_or_rebuild(&boundary, &Default::default(), &Default::default()).unwrap();
    for tets in [700, 800, 1500, 2000, 2500, 3000, 3500, 4000, 5000] {
        let (mesh, quality) =
            mesh::tetmesh::mesh_surface_to_count(&surface, tets, mesh::BoundaryFit::default()).unwrap();
        let mut edges = std::collections::HashMap::<[usize; 2], usize>::new();
        for t in &mesh::boundary_surface(&mesh).triangles {
            for (a, b) in [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])] {
                *edges.entry([a.min(b), a.max(b)]).or_default() += 1;
            }
        }
        let pinched = edges.values().filter(|&&n| n > 2).count();
        assert_eq!((quality.pieces, pinched), (1, 0), "{tets} tetrahedra asked, {} made", mesh.cells.len());
    }
}
