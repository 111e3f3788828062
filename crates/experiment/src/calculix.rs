//! CalculiX (`ccx`, Dhondt), an established open-source FEM, as a verification peer: a static
//! [`Problem`] written as a CalculiX input deck, solved by `ccx`, its nodal displacements read back.
//!
//! The deck reproduces the problem exactly where CalculiX has the same model: the same nodes and
//! cells (C3D4, C3D10 and C3D8 use augsim's node orders and quadrature: 1, 4 and 2×2×2 points),
//! linear elasticity (`*ELASTIC`) or Saint-Venant-Kirchhoff (`*ELASTIC` under `NLGEOM`), the
//! nodal forces (`*CLOAD`: forces, tractions and gravity as augsim integrates them), the prescribed
//! displacements (`*BOUNDARY`) and the nodal springs (`SPRING1` elements), then a second step of
//! equilibrium iterations under the same load. augsim's Neo-Hookean law (energy
//! μ/2 (I₁ − 3) − μ ln J + λ/2 ln² J) becomes CalculiX's nearest model, `*HYPERELASTIC, NEO HOOKE`
//! with the same shear and bulk moduli (energy μ/2 (Ī₁ − 3) + K/2 (J − 1)²): the same law at small
//! strain, a volumetric energy of another shape at large strain, so that the two agree to within a
//! few per cent, not to the last digit, at finite strain (`tests/real_organs.rs`: 0.4 %). Laws,
//! formulations and terms CalculiX does not have (co-rotational, F-bar, point springs,
//! immersed-boundary cells) are refused rather than approximated.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;
use std::process::Command;
use std::time::Instant;

use anyhow::{bail, ensure, Context, Result};
use fem::{Formulation, Law, Problem};
use mesh::CellKind;

/// The environment variable naming the CalculiX executable (default `ccx`).
pub const CCX_ENV: &str = "AUGSIM_CCX";

/// The job name of the deck written by [`solve`] (`<dir>/peer.inp`, results `<dir>/peer.dat`).
const JOB: &str = "peer";

/// CalculiX's solution of a problem.
#[derive(Clone, Debug, PartialEq)]
pub struct PeerSolution {
    /// Nodal displacement (m, 3 per node), in augsim's node order.
    pub u: Vec<f64>,
    /// Reaction forces (N, 3 per node: CalculiX's RF, the force a node's constraint exerts on it).
    pub reaction: Vec<f64>,
    /// Wall time of the `ccx` run (s), reading the deck and writing the results included.
    pub seconds: f64,
}

/// The CalculiX element type of augsim's cells.
fn element_type(kind: CellKind) -> &'static str {
    match kind {
        CellKind::Tet4 => "C3D4",
        CellKind::Tet10 => "C3D10",
        CellKind::Hex8 => "C3D8",
    }
}

/// The problem as a CalculiX input deck (SI units; 13 significant digits, as CalculiX reads at
/// most 20 characters a number; node and element numbers are augsim's indices plus one). Fails
/// for what CalculiX cannot reproduce exactly (see the module).
pub fn input_deck(problem: &Problem) -> Result<String> {
    problem.validate()?;
    let material = &problem.material;
    let nonlinear = match material.law {
        Law::Linear => false,
        Law::Svk | Law::NeoHookean => true,
        law => bail!(
            "CalculiX has no {law:?} law like augsim's: compare linear, Saint-Venant-Kirchhoff or Neo-Hookean solves"
        ),
    };
    ensure!(
        material.resolved_formulation() == Formulation::Standard,
        "F-bar elements have no CalculiX counterpart: compare the standard formulation"
    );
    ensure!(problem.point_springs.is_empty(), "point springs have no CalculiX counterpart");
    let mesh = &problem.mesh;
    ensure!(mesh.cell_fraction.is_none(), "immersed-boundary cells (cell fractions) have no CalculiX counterpart");

    let mut deck = String::from("** augsim problem as a CalculiX deck\n*NODE, NSET=NALL\n");
    for (i, p) in mesh.nodes.iter().enumerate() {
        writeln!(deck, "{}, {:.12e}, {:.12e}, {:.12e}", i + 1, p[0], p[1], p[2])?;
    }
    writeln!(deck, "*ELEMENT, TYPE={}, ELSET=EALL", element_type(mesh.cells.kind()))?;
    for c in 0..mesh.cells.len() {
        let nodes: Vec<String> = mesh.cells.cell(c).iter().map(|n| (n + 1).to_string()).collect();
        // A deck line holds at most 16 entries: C3D10 (11) and C3D8 (9) fit on one.
        writeln!(deck, "{}, {}", c + 1, nodes.join(", "))?;
    }
    // Nodal springs, grouped by stiffness: one SPRING1 element per node and direction.
    let mut by_stiffness: BTreeMap<u64, Vec<usize>> = BTreeMap::new();
    for (n, &k) in problem.springs.iter().enumerate().filter(|(_, &k)| k > 0.0) {
        by_stiffness.entry(k.to_bits()).or_default().push(n);
    }
    let mut next_element = mesh.cells.len() + 1;
    for (group, (bits, nodes)) in by_stiffness.iter().enumerate() {
        for dof in 1..=3 {
            let set = format!("SPRING{group}D{dof}");
            writeln!(deck, "*ELEMENT, TYPE=SPRING1, ELSET={set}")?;
            for n in nodes {
                writeln!(deck, "{next_element}, {}", n + 1)?;
                next_element += 1;
            }
            writeln!(deck, "*SPRING, ELSET={set}\n{dof}\n{:.12e}", f64::from_bits(*bits))?;
        }
    }
    if material.law == Law::NeoHookean {
        // C10 = μ/2, D1 = 2/K.
        let (lambda, mu) = material.lame();
        let bulk = lambda + 2.0 * mu / 3.0;
        writeln!(deck, "*MATERIAL, NAME=TISSUE\n*HYPERELASTIC, NEO HOOKE\n{:.12e}, {:.12e}", mu / 2.0, 2.0 / bulk)?;
    } else {
        writeln!(deck, "*MATERIAL, NAME=TISSUE\n*ELASTIC\n{:.12e}, {:.12e}", material.young, material.poisson)?;
    }
    writeln!(deck, "*SOLID SECTION, ELSET=EALL, MATERIAL=TISSUE")?;
    // The load in increments CalculiX sizes itself (from 5 %), then a second step under the same
    // load: CalculiX accepts an increment on criteria of its own, which left 2 µm on a 9.5 cm
    // bend; the second step's equilibrium iterations take it to the printed digits (7 nm).
    let step = format!("*STEP{}, INC=10000\n*STATIC\n", if nonlinear { ", NLGEOM" } else { "" });
    deck.push_str(&step);
    deck.push_str("0.05, 1.0, 1e-6, 1.0\n");
    // Prescribed displacements and loads rise with the step, as augsim's load factor scales them.
    if !problem.dirichlet.is_empty() {
        deck.push_str("*BOUNDARY\n");
        for (&n, value) in &problem.dirichlet {
            for (d, v) in value.iter().enumerate() {
                writeln!(deck, "{}, {}, {}, {v:.12e}", n + 1, d + 1, d + 1)?;
            }
        }
    }
    let forces: Vec<(usize, usize, f64)> = (0..problem.f_ext.len())
        .filter(|&i| problem.f_ext[i] != 0.0)
        .map(|i| (i / 3, i % 3, problem.f_ext[i]))
        .collect();
    if !forces.is_empty() {
        deck.push_str("*CLOAD\n");
        for (n, d, f) in forces {
            writeln!(deck, "{}, {}, {f:.12e}", n + 1, d + 1)?;
        }
    }
    deck.push_str("*END STEP\n");
    deck.push_str(&step);
    deck.push_str("1.0, 1.0, 1e-6, 1.0\n*NODE PRINT, NSET=NALL\nU, RF\n*END STEP\n");
    Ok(deck)
}

/// The displacements of the last increment of a CalculiX `.dat` file (`*NODE PRINT` of `U` on
/// every node), for `num_nodes` nodes.
pub fn read_displacements(dat: &str, num_nodes: usize) -> Result<Vec<f64>> {
    read_nodal_block(dat, " displacements (vx,vy,vz)", "displacement", num_nodes)
}

/// The reaction forces of the last increment of a CalculiX `.dat` file (`*NODE PRINT` of `RF` on
/// every node: zero where nothing holds a node), for `num_nodes` nodes.
pub fn read_reaction_forces(dat: &str, num_nodes: usize) -> Result<Vec<f64>> {
    read_nodal_block(dat, " forces (fx,fy,fz)", "force", num_nodes)
}

/// The last block of a `.dat` file headed by `heading` (the `what` block), three values a node.
fn read_nodal_block(dat: &str, heading: &str, what: &str, num_nodes: usize) -> Result<Vec<f64>> {
    let start = dat.rfind(heading).with_context(|| format!("no {what} block in the CalculiX results"))?;
    let mut u = vec![f64::NAN; 3 * num_nodes];
    let mut seen = 0;
    for (no, line) in dat[start..].lines().enumerate().skip(1) {
        let fields: Vec<&str> = line.split_whitespace().collect();
        if fields.is_empty() {
            if seen > 0 {
                break;
            }
            continue;
        }
        ensure!(fields.len() == 4, "line {} of the {what} block: expected a node and 3 values, got '{line}'", no + 1);
        let node: usize = fields[0].parse().with_context(|| format!("node number '{}'", fields[0]))?;
        ensure!((1..=num_nodes).contains(&node), "node {node} out of 1..={num_nodes}");
        for d in 0..3 {
            u[3 * (node - 1) + d] = fields[d + 1].parse().with_context(|| format!("value '{}'", fields[d + 1]))?;
        }
        seen += 1;
    }
    ensure!(seen == num_nodes, "the {what} block has {seen} nodes, the problem {num_nodes}");
    Ok(u)
}

/// The CalculiX executable: [`CCX_ENV`] or `ccx`.
fn executable() -> String {
    std::env::var(CCX_ENV).unwrap_or_else(|_| "ccx".into())
}

/// The version CalculiX reports ("2.20"), or an error saying how to install it.
pub fn version() -> Result<String> {
    let ccx = executable();
    let output = Command::new(&ccx).arg("-v").output().with_context(|| {
        format!("cannot run CalculiX '{ccx}' (install it, e.g. apt-get install calculix-ccx, or set {CCX_ENV})")
    })?;
    let text = String::from_utf8_lossy(&output.stdout);
    let version = text.split_once("Version").map(|(_, v)| v.trim().to_string());
    version.filter(|v| !v.is_empty()).with_context(|| format!("'{ccx} -v' printed no version: is it CalculiX?"))
}

/// Solves `problem` with CalculiX in `dir` (written there: `peer.inp`, CalculiX's files, and its
/// output in `ccx.log`).
pub fn solve(problem: &Problem, dir: &Path) -> Result<PeerSolution> {
    let deck = input_deck(problem)?;
    mesh::io::create_folder(dir)?;
    mesh::io::write_atomic_bytes(&dir.join(format!("{JOB}.inp")), deck.as_bytes())?;
    let ccx = executable();
    let start = Instant::now();
    let output = Command::new(&ccx)
        .args(["-i", JOB])
        .current_dir(dir)
        .output()
        .with_context(|| format!("running CalculiX '{ccx}'"))?;
    let seconds = start.elapsed().as_secs_f64();
    let log = String::from_utf8_lossy(&output.stdout).into_owned() + &String::from_utf8_lossy(&output.stderr);
    mesh::io::write_atomic_bytes(&dir.join("ccx.log"), log.as_bytes())?;
    if let Some(error) = log.lines().find(|l| l.contains("*ERROR")) {
        bail!("CalculiX failed: {} (see {})", error.trim(), dir.join("ccx.log").display());
    }
    ensure!(output.status.success(), "CalculiX exited with {} (see {})", output.status, dir.join("ccx.log").display());
    let dat_path = dir.join(format!("{JOB}.dat"));
    let dat = std::fs::read_to_string(&dat_path).with_context(|| format!("reading {}", dat_path.display()))?;
    let u = read_displacements(&dat, problem.mesh.nodes.len())?;
    let reaction = read_reaction_forces(&dat, problem.mesh.nodes.len())?;
    Ok(PeerSolution { u, reaction, seconds })
}

#[cfg(test)]
mod tests {
    use super::*;
    use fem::{Material, PointSpring};
    use std::fs;

    fn cube(law: Law, poisson: f64) -> Problem {
        let m = mesh::box_mesh(CellKind::Tet4, [0.0; 3], [1.0; 3], [1, 1, 1]).unwrap();
        let mut p = Problem::new(m, Material::new(law, 1000.0, poisson));
        p.fix(&[0, 1, 2]);
        p.add_springs(&[3], 5.0);
        p.f_ext[3 * 7 + 2] = -1.0;
        p
    }

    /// The deck holds every node, cell, constraint, spring and load, with the keywords
    /// CalculiX expects; what CalculiX cannot reproduce is refused, naming it.
    #[test]
    fn the_deck_writes_the_problem_and_refuses_what_calculix_lacks() {
        let deck = input_deck(&cube(Law::Svk, 0.3)).unwrap();
        assert!(deck.contains("*ELEMENT, TYPE=C3D4, ELSET=EALL\n1, "), "{deck}");
        assert_eq!(deck.matches("*STEP, NLGEOM").count(), 2);
        assert!(deck.contains("*ELEMENT, TYPE=SPRING1, ELSET=SPRING0D3\n"), "{deck}");
        assert!(deck.contains("*SPRING, ELSET=SPRING0D1\n1\n5.000000000000e0\n"), "{deck}");
        assert!(deck.contains("*CLOAD\n8, 3, -1.000000000000e0\n"), "{deck}");
        assert!(deck.contains("*BOUNDARY\n1, 1, 1, 0.000000000000e0\n1, 2, 2, 0.000000000000e0\n"), "{deck}");
        let boundary = deck.split("*BOUNDARY\n").nth(1).unwrap().split("*CLOAD").next().unwrap();
        assert_eq!(boundary.lines().count(), 9, "three fixed nodes, three directions each");
        assert!(!input_deck(&cube(Law::Linear, 0.3)).unwrap().contains("NLGEOM"));
        // Neo-Hookean: CalculiX's own, with C10 = μ/2 and D1 = 2/K (E 1,000 Pa, ν 0.3: μ 384.6 Pa, K 833.3 Pa).
        let neo = input_deck(&cube(Law::NeoHookean, 0.3)).unwrap();
        assert!(neo.contains("*HYPERELASTIC, NEO HOOKE\n1.923076923077e2, 2.400000000000e-3\n"), "{neo}");
        let refused = |p: Problem| input_deck(&p).unwrap_err().to_string();
        assert!(refused(cube(Law::Corotational, 0.3)).contains("no Corotational law"));
        assert!(refused(cube(Law::Svk, 0.49)).contains("F-bar"));
        let mut with_point_spring = cube(Law::Svk, 0.3);
        with_point_spring.point_springs.push(PointSpring {
            nodes: vec![(4, 1.0)],
            target: [0.0; 3],
            stiffness: 1.0,
            normal: [0.0, 0.0, 1.0],
            normal_stiffness: 0.0,
        });
        assert!(refused(with_point_spring).contains("point springs"));
    }

    /// The deck's mesh reads back as the problem's (augsim's `.inp` reader): the same cells in the
    /// same node order, nodes to the deck's 13 digits, numbered from 1; the spring elements make
    /// regions of their nodes.
    #[test]
    fn the_deck_reads_back_as_the_same_mesh() {
        let dir = tempfile::tempdir().unwrap();
        for kind in [CellKind::Tet4, CellKind::Tet10, CellKind::Hex8] {
            let m = mesh::box_mesh(kind, [0.0; 3], [0.1, 0.07, 0.05], [2, 2, 1]).unwrap();
            let mut p = Problem::new(m, Material::new(Law::Linear, 3000.0, 0.3));
            p.fix(&[0, 1, 2]);
            p.add_springs(&[4, 5], 5.0);
            let path = dir.path().join("deck.inp");
            fs::write(&path, input_deck(&p).unwrap()).unwrap();
            let read = mesh::io::read_inp(&path).unwrap();
            assert_eq!(read.cells, p.mesh.cells, "{kind:?}");
            assert_eq!(read.file_nodes, Some((1..=p.mesh.num_nodes()).collect()));
            let far = read.nodes.iter().zip(&p.mesh.nodes).flat_map(|(a, b)| (0..3).map(move |d| (a[d] - b[d]).abs()));
            assert!(far.fold(0.0, f64::max) < 1e-13, "{kind:?}");
            assert_eq!(read.regions["SPRING0D1"], [4, 5]);
            assert_eq!(read.regions["NALL"].len(), p.mesh.num_nodes());
        }
    }

    /// The last displacement block is read; a missing block, a missing node or a malformed line
    /// is an error that says so.
    #[test]
    fn displacements_are_read_from_the_last_block() {
        let block = |t: f64| {
            format!(" displacements (vx,vy,vz) for set NALL and time  {t:.7E}\n\n         1  1.000000E-03 -2.000000E-03  0.000000E+00\n         2  0.000000E+00  0.000000E+00  4.500000E-02\n\n")
        };
        let dat = block(1.0).replace("1.000000E-03", "9.0E+00") + &block(2.0);
        assert_eq!(read_displacements(&dat, 2).unwrap(), vec![1e-3, -2e-3, 0.0, 0.0, 0.0, 4.5e-2]);
        assert!(read_displacements(" stresses\n", 2).unwrap_err().to_string().contains("no displacement block"));
        let forces = dat.replace(" displacements (vx,vy,vz)", " forces (fx,fy,fz)");
        assert_eq!(read_reaction_forces(&forces, 2).unwrap(), vec![1e-3, -2e-3, 0.0, 0.0, 0.0, 4.5e-2]);
        assert!(read_reaction_forces(&dat, 2).unwrap_err().to_string().contains("no force block"));
        assert!(read_displacements(&block(1.0), 3).unwrap_err().to_string().contains("has 2 nodes, the problem 3"));
        let bad = block(1.0).replace("-2.000000E-03 ", "");
        assert!(read_displacements(&bad, 2).unwrap_err().to_string().contains("expected a node and 3 values"));
    }
}
