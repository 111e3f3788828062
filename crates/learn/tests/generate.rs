//! FEM dataset generation: grid encoding, determinism, resume and split/merge.

use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::Path;

use augsim_learn::data::generate::part_range;
use augsim_learn::data::generate::{DatasetConfig, Generator, Input, Load};
use augsim_learn::{merge_datasets, Dataset, DatasetPart};
use fem::{Law, Material, SolverOptions};
use mesh::NodeSelection;

fn bottom(x0: f64, x1: f64) -> NodeSelection {
    NodeSelection::Box { min: [x0 - 1e-6, -1e-6, -1e-6], max: [x1 + 1e-6, 1.0 + 1e-6, 1e-6] }
}

fn top() -> NodeSelection {
    NodeSelection::Box { min: [-1e-6, -1e-6, 1.0 - 1e-6], max: [4.0 + 1e-6, 1.0 + 1e-6, 1.0 + 1e-6] }
}

/// A small beam with a hidden fixed cuboid drawn from two alternatives.
fn beam_generator(samples: usize) -> Generator {
    beam_generator_with_shards(samples, 2)
}

fn beam_generator_with_shards(samples: usize, shard_size: usize) -> Generator {
    let mesh = mesh::box_hex([0.0; 3], [4.0, 1.0, 1.0], [8, 2, 2]).unwrap();
    let config = DatasetConfig {
        samples,
        seed: 7,
        shard_size,
        grid: None,
        fixed: vec![bottom(0.0, 1.0), bottom(2.0, 3.0)],
        attachment: vec![],
        load: Load::PatchForce { centres: Some(top()), radius: 0.6, magnitude: [0.05, 0.2], cone: None },
        gravity: None,
        input: Input::Displacement { nodes: top(), sparse: Some([3, 8]), normal: false },
    };
    Generator::new(mesh, Material::new(Law::Svk, 300.0, 0.4), SolverOptions::default(), config).unwrap()
}

fn files(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut out = Vec::new();
    for entry in walk(dir) {
        out.push((entry.strip_prefix(dir).unwrap().display().to_string(), std::fs::read(&entry).unwrap()));
    }
    out.sort();
    out
}

fn walk(dir: &Path) -> Vec<std::path::PathBuf> {
    let mut v = Vec::new();
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            v.extend(walk(&p));
        } else {
            v.push(p);
        }
    }
    v
}

#[test]
fn lattice_encoding_is_exact_and_forces_are_conserved() {
    let g = beam_generator(1);
    let grid = g.grid();
    assert_eq!([grid.nx, grid.ny, grid.nz], [9, 3, 3]);
    let mesh = mesh::box_hex([0.0; 3], [4.0, 1.0, 1.0], [8, 2, 2]).unwrap();
    let field: Vec<f64> = mesh.nodes.iter().flat_map(|p| [p[0] * 0.1, p[1] - p[2], 0.3 * p[2]]).collect();
    let enc = g.encode(&field, false).unwrap();
    let n = grid.nodes();
    for p in &mesh.nodes {
        let (i, j, k) = ((p[0] / 0.5).round() as usize, (p[1] / 0.5).round() as usize, (p[2] / 0.5).round() as usize);
        let node = grid.node_index(i, j, k);
        assert_eq!(enc[node], (p[0] * 0.1) as f32);
        assert_eq!(enc[n + node], (p[1] - p[2]) as f32);
        assert_eq!(enc[2 * n + node], (0.3 * p[2]) as f32);
    }
    assert!(g.mask().iter().all(|&m| m == 1));
}

#[test]
fn embedded_encoding_reproduces_linear_fields_and_total_force() {
    // A T4 box whose nodes coincide with the grid: linear fields are exact.
    let mesh = mesh::box_tet([0.0; 3], [0.2, 0.1, 0.1], [4, 2, 2]).unwrap();
    let all = NodeSelection::Box { min: [-1.0; 3], max: [1.0; 3] };
    let config = DatasetConfig {
        samples: 1,
        seed: 0,
        shard_size: 1,
        grid: Some([9, 5, 5]),
        fixed: vec![NodeSelection::Box { min: [-1e-6; 3], max: [1e-6, 1.0, 1.0] }],
        attachment: vec![],
        load: Load::PointForces { nodes: all, count: 3, magnitude: [0.1, 0.2] },
        gravity: None,
        input: Input::Force,
    };
    let g = Generator::new(mesh.clone(), Material::new(Law::Linear, 5000.0, 0.45), SolverOptions::default(), config)
        .unwrap();
    let lin = |p: &[f64; 3]| [0.01 + 0.2 * p[0] - 0.1 * p[1], 0.3 * p[2], -0.05 * p[0] + 0.4 * p[1]];
    let field: Vec<f64> = mesh.nodes.iter().flat_map(lin).collect();
    let enc = g.encode(&field, false).unwrap();
    let grid = g.grid();
    let n = grid.nodes();
    let mut inside = 0;
    for i in 0..9 {
        for j in 0..5 {
            for k in 0..5 {
                let node = grid.node_index(i, j, k);
                if g.mask()[node] == 0 {
                    continue;
                }
                inside += 1;
                let expect = lin(&[0.025 * i as f64, 0.025 * j as f64, 0.025 * k as f64]);
                for c in 0..3 {
                    assert!((enc[c * n + node] as f64 - expect[c]).abs() < 1e-6, "node ({i},{j},{k}) channel {c}");
                }
            }
        }
    }
    assert_eq!(inside, 9 * 5 * 5, "every grid node lies in the box");
    // Spreading nodal forces to the grid keeps the total force.
    let forces: Vec<f64> = (0..3 * mesh.num_nodes()).map(|i| ((i * 37) % 11) as f64 - 5.0).collect();
    let enc = g.encode(&forces, true).unwrap();
    for c in 0..3 {
        let total: f64 = forces.iter().skip(c).step_by(3).sum();
        let grid_total: f64 = enc[c * n..(c + 1) * n].iter().map(|&v| v as f64).sum();
        assert!((total - grid_total).abs() < 1e-4, "channel {c}: {total} vs {grid_total}");
    }
}

#[test]
fn samples_show_a_sparse_sub_domain_and_a_full_target() {
    let g = beam_generator(6);
    let tmp = tempfile::tempdir().unwrap();
    let manifest = g.run(tmp.path(), "beam", None, &augsim_learn::Silent).unwrap();
    assert_eq!(manifest.num_samples + manifest.failed.len(), 6);
    assert!(manifest.num_samples >= 5, "failures: {:?}", manifest.failed);
    // The samples carry a visible sparse sub-domain of the top face and a full target.
    let all = Dataset::open(tmp.path()).unwrap().load_all().unwrap();
    let n = all.grid.nodes();
    for i in 0..all.len() {
        let visible = (0..n).filter(|&k| (0..3).any(|c| all.input(i)[c * n + k] != 0.0)).count();
        assert!((3..=8).contains(&visible), "sample {i}: {visible} visible nodes");
        assert!(all.target(i).iter().any(|&v| v.abs() > 1e-4));
    }
}

/// Runs `g` in a rayon pool of `threads` threads.
fn run_in_pool(threads: usize, g: &Generator, dir: &Path, progress: &dyn augsim_learn::Progress) {
    let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
    pool.install(|| g.run(dir, "beam", None, progress)).unwrap();
}

#[test]
fn generation_is_bit_identical_for_any_thread_count_and_after_a_kill() {
    // Enough samples per fixed set that solvers solve several samples in a row (and keep their
    // factorisation between them). Shards of 5 samples, so that the kill leaves the dataset at an
    // index inside a block of samples solved in a row.
    let g = beam_generator_with_shards(40, 5);
    let tmp = tempfile::tempdir().unwrap();
    let dir = |name: &str| tmp.path().join(name);
    run_in_pool(1, &g, &dir("one"), &augsim_learn::Silent);
    let reference = files(&dir("one"));
    assert!(Dataset::open(&dir("one")).unwrap().len() >= 35);
    for threads in [2, 3] {
        let out = dir(&format!("threads{threads}"));
        run_in_pool(threads, &g, &out, &augsim_learn::Silent);
        assert!(files(&out) == reference, "{threads} threads must give the bytes of 1 thread");
    }
    // Killed in its second batch (of one block of 32 draws with 1 thread), resumed with 3.
    let resumed = dir("resumed");
    let killed = catch_unwind(AssertUnwindSafe(|| {
        run_in_pool(1, &g, &resumed, &|done: u64, _: u64, _: &str| {
            if done > 32 {
                panic!("simulated kill");
            }
        })
    }));
    assert!(killed.is_err());
    let partial = Dataset::open(&resumed).unwrap().manifest().next_index;
    assert!(partial > 0 && partial < 40, "resume at index {partial}");
    run_in_pool(3, &g, &resumed, &augsim_learn::Silent);
    assert!(files(&resumed) == reference, "a resumed generation must give the bytes of an uninterrupted one");
}

#[test]
fn parts_are_runs_of_whole_blocks_that_cover_every_draw_once() {
    for (samples, count) in [(70, 5), (70, 2), (64, 8), (20, 3), (1, 4), (5_200, 7)] {
        let ranges: Vec<_> =
            (0..count).map(|index| part_range(samples, Some(&DatasetPart { index, count })).unwrap()).collect();
        // Consecutive, from 0 to the last draw.
        assert_eq!(ranges[0].start, 0);
        assert_eq!(ranges[count - 1].end, samples);
        assert!(ranges.windows(2).all(|w| w[0].end == w[1].start), "{samples} in {count}: {ranges:?}");
        // Each part starts on a block (of 32) and holds whole blocks but for the dataset's last.
        assert!(ranges.iter().all(|r| r.start % 32 == 0 && (r.end % 32 == 0 || r.end == samples)), "{ranges:?}");
        // The blocks shared out evenly: part sizes in blocks differ by one at most.
        let blocks: Vec<usize> = ranges.iter().map(|r| r.len().div_ceil(32)).collect();
        let (least, most) = (blocks.iter().min().unwrap(), blocks.iter().max().unwrap());
        assert!(most - least <= 1, "{samples} in {count}: {blocks:?}");
    }
    assert!(part_range(10, Some(&DatasetPart { index: 2, count: 2 })).is_err());
    assert!(part_range(10, Some(&DatasetPart { index: 0, count: 0 })).is_err());
}

#[test]
fn split_generation_merges_into_the_full_dataset() {
    // 70 draws are 3 blocks of 32 (the last one short) in 5 parts: parts 1, 3 and 4 hold a block
    // each, parts 0 and 2 none; the empty parts are complete datasets and merge as well.
    let g = beam_generator_with_shards(70, 5);
    let tmp = tempfile::tempdir().unwrap();
    let full = tmp.path().join("full");
    run_in_pool(1, &g, &full, &augsim_learn::Silent);
    let parts: Vec<_> = (0..5)
        .map(|i| {
            let dir = tmp.path().join(format!("part{i}"));
            g.run(&dir, "beam", Some(DatasetPart { index: i, count: 5 }), &augsim_learn::Silent).unwrap();
            dir
        })
        .collect();
    let sizes: Vec<usize> = parts.iter().map(|p| Dataset::open(p).unwrap().len()).collect();
    assert_eq!(sizes, [0, 32, 0, 32, 6]);
    let merged = tmp.path().join("merged");
    merge_datasets(&parts, &merged, None).unwrap();
    let a = Dataset::open(&full).unwrap().load_all().unwrap();
    let b = Dataset::open(&merged).unwrap().load_all().unwrap();
    assert_eq!(a, b);
}

#[test]
fn bad_configurations_are_rejected_with_a_reason() {
    let mesh = mesh::box_hex([0.0; 3], [4.0, 1.0, 1.0], [8, 2, 2]).unwrap();
    let base = DatasetConfig {
        samples: 2,
        seed: 0,
        shard_size: 1,
        grid: None,
        fixed: vec![bottom(0.0, 1.0)],
        attachment: vec![],
        load: Load::PointForces { nodes: top(), count: 100, magnitude: [0.0, 1.0] },
        gravity: None,
        input: Input::Force,
    };
    let m = Material::new(Law::Svk, 300.0, 0.4);
    let err = Generator::new(mesh.clone(), m, SolverOptions::default(), base.clone()).err().unwrap().to_string();
    assert!(err.contains("cannot load 100 distinct nodes"), "{err}");
    let err =
        Generator::new(mesh.clone(), m, SolverOptions::default(), DatasetConfig { fixed: vec![], ..base.clone() })
            .err()
            .unwrap()
            .to_string();
    assert!(err.contains("fixed"), "{err}");
    let tool = Load::Tool { centres: Some(top()), radius: 0.6, depth: [0.2, 0.1] };
    let err = Generator::new(mesh.clone(), m, SolverOptions::default(), DatasetConfig { load: tool, ..base.clone() })
        .err()
        .unwrap()
        .to_string();
    assert!(err.contains("depth range"), "{err}");
    let cone = Load::PatchForce { centres: Some(top()), radius: 0.6, magnitude: [0.1, 0.2], cone: Some(200.0) };
    let err = Generator::new(mesh.clone(), m, SolverOptions::default(), DatasetConfig { load: cone, ..base.clone() })
        .err()
        .unwrap()
        .to_string();
    assert!(err.contains("cone half-angle"), "{err}");
    let nested = DatasetConfig { load: Load::Any(vec![Load::Any(vec![])]), ..base.clone() };
    let err = Generator::new(mesh.clone(), m, SolverOptions::default(), nested).err().unwrap().to_string();
    assert!(err.contains("not other `any`"), "{err}");
    let err = Generator::new(
        mesh,
        m,
        SolverOptions::default(),
        DatasetConfig {
            gravity: Some([-1.0, 9.81]),
            load: Load::PointForces { nodes: top(), count: 1, magnitude: [0.0, 1.0] },
            ..base
        },
    )
    .err()
    .unwrap()
    .to_string();
    assert!(err.contains("gravity range"), "{err}");
}

/// The generated samples of a beam fixed at one end, loaded by `load` and `gravity`, with the
/// full displacement of its top face as input.
fn beam_samples(law: Law, load: Load, gravity: Option<[f64; 2]>, samples: usize) -> augsim_learn::Samples {
    beam_dataset(law, load, gravity, Input::Displacement { nodes: top(), sparse: None, normal: false }, samples)
}

/// The generated samples of a beam fixed at one end, loaded by `load` and `gravity`, with `input`.
fn beam_dataset(
    law: Law,
    load: Load,
    gravity: Option<[f64; 2]>,
    input: Input,
    samples: usize,
) -> augsim_learn::Samples {
    let mesh = mesh::box_hex([0.0; 3], [4.0, 1.0, 1.0], [8, 2, 2]).unwrap();
    let config = DatasetConfig {
        samples,
        seed: 3,
        shard_size: samples,
        grid: None,
        fixed: vec![bottom(0.0, 1.0)],
        attachment: vec![],
        load,
        gravity,
        input,
    };
    let mut material = Material::new(law, 300.0, 0.3);
    material.density = 10.0;
    let g = Generator::new(mesh, material, SolverOptions::default(), config).unwrap();
    let tmp = tempfile::tempdir().unwrap();
    let manifest = g.run(tmp.path(), "beam", None, &augsim_learn::Silent).unwrap();
    assert!(manifest.failed.is_empty(), "{:?}", manifest.failed);
    Dataset::open(tmp.path()).unwrap().load_all().unwrap()
}

#[test]
fn a_tool_moves_the_nodes_under_it_by_its_depth() {
    let tool = Load::Tool { centres: Some(top()), radius: 0.6, depth: [0.05, 0.1] };
    let data = beam_samples(Law::NeoHookean, tool, None, 4);
    let n = data.grid.nodes();
    let mut depths = Vec::new();
    for i in 0..data.len() {
        let u = data.target(i);
        let on_top: Vec<usize> = (0..n).filter(|&k| (0..3).any(|c| data.input(i)[c * n + k] != 0.0)).collect();
        let moved = |k: usize| [u[k], u[n + k], u[2 * n + k]];
        let tool = tool_nodes(&data, i);
        assert!(!tool.is_empty(), "sample {i}: no node under the tool");
        let d = moved(tool[0]);
        assert!(tool.iter().all(|&k| moved(k) == d), "sample {i}: one displacement for the whole tool");
        let depth = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt() as f64;
        assert!((0.05 - 1e-6..=0.1 + 1e-6).contains(&depth), "sample {i}: depth {depth}");
        assert!(d[2] < 0.0, "sample {i}: the tool presses into the beam: {d:?}");
        // The rest of the beam follows.
        assert!(on_top.iter().any(|&k| !tool.contains(&k) && u[2 * n + k] < -0.01), "sample {i}");
        depths.push(depth);
    }
    assert!(depths.iter().any(|&d| d != depths[0]), "random depths: {depths:?}");
}

/// Sample `i`'s tool nodes: the nodes of the top face that share one displacement.
fn tool_nodes(data: &augsim_learn::Samples, i: usize) -> Vec<usize> {
    let n = data.grid.nodes();
    let u = data.target(i);
    let on_top: Vec<usize> = (0..n).filter(|&k| (0..3).any(|c| data.input(i)[c * n + k] != 0.0)).collect();
    let moved = |k: usize| [u[k], u[n + k], u[2 * n + k]];
    on_top.iter().copied().filter(|&k| on_top.iter().filter(|&&j| moved(j) == moved(k)).count() >= 2).collect()
}

#[test]
fn each_sample_draws_one_of_the_alternative_loads() {
    let tool = Load::Tool { centres: Some(top()), radius: 0.6, depth: [0.05, 0.1] };
    let push = Load::PatchForce { centres: Some(top()), radius: 0.6, magnitude: [0.05, 0.2], cone: None };
    let data = beam_samples(Law::NeoHookean, Load::Any(vec![tool, push]), None, 12);
    let pressed = (0..data.len()).filter(|&i| !tool_nodes(&data, i).is_empty()).count();
    assert!(pressed > 0 && pressed < data.len(), "{pressed} of {} samples pressed by the tool", data.len());
}

/// The total force of each sample of a beam pushed on its top face within a cone of
/// `half_angle` degrees around the inward normal, read back from the force input. The patch
/// centres are top nodes off the face's edges, where the normal is +z.
fn patch_force_totals(half_angle: f64, samples: usize) -> Vec<[f64; 3]> {
    let inside = NodeSelection::Box { min: [0.4, 0.4, 1.0 - 1e-6], max: [3.6, 0.6, 1.0 + 1e-6] };
    let load = Load::PatchForce { centres: Some(inside), radius: 0.6, magnitude: [0.05, 0.2], cone: Some(half_angle) };
    let data = beam_dataset(Law::Linear, load, None, Input::Force, samples);
    let n = data.grid.nodes();
    (0..data.len())
        .map(|i| std::array::from_fn(|c| data.input(i)[c * n..(c + 1) * n].iter().map(|&f| f64::from(f)).sum()))
        .collect()
}

#[test]
fn a_patch_force_cone_tilts_the_push_within_its_half_angle() {
    let angle = |f: &[f64; 3]| {
        let norm = (f[0] * f[0] + f[1] * f[1] + f[2] * f[2]).sqrt();
        assert!((0.05 - 1e-6..=0.2 + 1e-6).contains(&norm), "magnitude {norm}");
        (-f[2] / norm).clamp(-1.0, 1.0).acos().to_degrees()
    };
    let tilted: Vec<f64> = patch_force_totals(40.0, 12).iter().map(angle).collect();
    assert!(tilted.iter().all(|&a| a <= 40.0 + 1e-3), "{tilted:?}");
    assert!(tilted.iter().any(|&a| a > 15.0), "tilted pushes: {tilted:?}");
    // Beyond 90°, pulls: a force with an outward component.
    let any: Vec<f64> = patch_force_totals(180.0, 12).iter().map(angle).collect();
    assert!(any.iter().any(|&a| a > 90.0) && any.iter().any(|&a| a < 90.0), "{any:?}");
}

#[test]
fn gravity_adds_a_body_force_of_the_drawn_acceleration() {
    // No other load; a linear law, so that the displacement is proportional to the acceleration
    // drawn (the same direction for the same seed and index).
    let none = || Load::PointForces { nodes: top(), count: 1, magnitude: [0.0, 0.0] };
    let one = beam_samples(Law::Linear, none(), Some([1.0, 1.0]), 3);
    let two = beam_samples(Law::Linear, none(), Some([2.0, 2.0]), 3);
    let directions: Vec<Vec<f32>> = (0..3)
        .map(|i| {
            let u = one.target(i);
            let scale = u.iter().map(|v| v.abs()).fold(0.0f32, f32::max);
            assert!(scale > 1e-4, "sample {i}: gravity must move the beam");
            for (a, b) in u.iter().zip(two.target(i)) {
                assert!((2.0 * a - b).abs() <= 1e-5 * scale, "sample {i}: {b} against twice {a}");
            }
            u.iter().map(|v| v / scale).collect()
        })
        .collect();
    assert!(directions[0] != directions[1] && directions[1] != directions[2], "random directions");
}

/// With `order = 2` the samples are solved on quadratic tetrahedra: the generator's mesh is the T10 mesh of
/// the given T4 mesh, its embedding reproduces quadratic fields at the grid nodes, and patch forces (spread
/// as the traction of their resultant) are carried without a failed sample.
#[test]
fn quadratic_tetrahedra_are_solved_and_encoded_as_such() {
    let t4 = mesh::box_tet([0.0; 3], [0.2, 0.1, 0.1], [4, 2, 2]).unwrap();
    let top = NodeSelection::Box { min: [-1.0, -1.0, 0.1 - 1e-6], max: [1.0, 1.0, 1.0] };
    let config = DatasetConfig {
        samples: 2,
        seed: 3,
        shard_size: 2,
        grid: Some([9, 5, 5]),
        fixed: vec![NodeSelection::Box { min: [-1e-6; 3], max: [1e-6, 1.0, 1.0] }],
        attachment: vec![],
        load: Load::PatchForce { centres: Some(top.clone()), radius: 0.05, magnitude: [0.05, 0.1], cone: None },
        gravity: None,
        input: Input::Displacement { nodes: top, sparse: None, normal: false },
    };
    let material = Material::new(Law::NeoHookean, 5000.0, 0.45).with_order(2);
    let g = Generator::new(t4.clone(), material, SolverOptions::default(), config).unwrap();
    let t10 = t4.quadratic().unwrap();
    assert_eq!(g.mesh(), &t10);
    let quad = |p: &[f64; 3]| [p[0] * p[1] - 2.0 * p[2] * p[2], 0.5 * p[0] * p[0] + p[1], p[1] * p[2]];
    let field: Vec<f64> = t10.nodes.iter().flat_map(quad).collect();
    let enc = g.encode(&field, false).unwrap();
    let (grid, n) = (g.grid(), g.grid().nodes());
    for (i, j, k) in [(1, 1, 1), (4, 2, 3), (7, 4, 2), (8, 0, 4)] {
        let node = grid.node_index(i, j, k);
        let expect = quad(&[0.025 * i as f64, 0.025 * j as f64, 0.025 * k as f64]);
        for c in 0..3 {
            assert!((enc[c * n + node] as f64 - expect[c]).abs() < 1e-7, "node ({i},{j},{k}) channel {c}");
        }
    }
    let dir = tempfile::tempdir().unwrap();
    let manifest = g.run(dir.path(), "t10", None, &augsim_learn::Silent).unwrap();
    assert_eq!((manifest.num_samples, manifest.failed.len()), (2, 0), "{:?}", manifest.failed);
}

/// On a mesh whose factorisation is large enough to run in parallel alone (a cube of 18³ cells of
/// T4, 20k dofs), a draw's bytes do not depend on the number of threads either: each draw
/// factorises on one thread.
#[test]
fn a_large_mesh_gives_the_same_bytes_on_any_number_of_threads() {
    let mesh = mesh::box_tet([0.0; 3], [1.0; 3], [18; 3]).unwrap();
    let geometry = fem::ElementGeometry::new(&mesh, fem::Formulation::Standard).unwrap();
    let constrained: Vec<bool> = (0..3 * mesh.nodes.len()).map(|dof| mesh.nodes[dof / 3][2] == 0.0).collect();
    let mut pattern = fem::assembly::Pattern::new(&geometry, constrained.len(), &constrained).unwrap();
    let work = fem::linsolve::SparseCholesky::new(&mut pattern).unwrap().factorization_work();
    assert!(work > fem::linsolve::ND_WORK, "factorised in parallel by default: {work:.2e} multiply-adds");
    let config = DatasetConfig {
        samples: 3,
        seed: 7,
        shard_size: 3,
        grid: None,
        fixed: vec![bottom(0.0, 1.0)],
        attachment: vec![],
        load: Load::PatchForce { centres: Some(top()), radius: 0.3, magnitude: [1.0, 5.0], cone: None },
        gravity: None,
        input: Input::Displacement { nodes: top(), sparse: None, normal: false },
    };
    let g = Generator::new(mesh, Material::new(Law::Linear, 300.0, 0.4), SolverOptions::default(), config).unwrap();
    let tmp = tempfile::tempdir().unwrap();
    let (one, three) = (tmp.path().join("one"), tmp.path().join("three"));
    run_in_pool(1, &g, &one, &augsim_learn::Silent);
    run_in_pool(3, &g, &three, &augsim_learn::Silent);
    assert_eq!(Dataset::open(&one).unwrap().len(), 3);
    assert!(files(&one) == files(&three), "3 threads must give the bytes of 1 thread");
}
