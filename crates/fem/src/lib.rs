//! Finite elements for soft-tissue mechanics: linear, co-rotational,
//! Saint-Venant-Kirchhoff and Neo-Hookean materials on T4, T10 and H8 meshes,
//! standard or locking-free (F-bar) for nearly incompressible tissue,
//! Dirichlet conditions, springs, nodal forces, tractions and gravity, and a
//! static quasi-Newton solver (L-BFGS on a kept sparse Cholesky factorisation) with an
//! arc-length continuation where force control finds no equilibrium.
//!
//! Units are SI: m, Pa, N, kg/m³. Displacement vectors hold 3 values per node
//! (x, y, z of node 0, then node 1, ...).
//!
//! A bar in uniaxial tension, solved and checked against its exact solution:
//!
//! ```
//! use augsim_fem::{Law, Material, Problem, SolverOptions, StaticSolver};
//! use mesh::select::nodes_in_box;
//!
//! // 2 × 1 × 1 m, 4 × 2 × 2 hexahedra, E = 1 kPa, ν = 0: fixed at x = 0, pulled by 10 Pa at x = 2.
//! let mesh = mesh::box_hex([0.0; 3], [2.0, 1.0, 1.0], [4, 2, 2])?;
//! let mut problem = Problem::new(mesh, Material::new(Law::Linear, 1000.0, 0.0));
//! let fixed = nodes_in_box(&problem.mesh.nodes, [-0.1; 3], [0.1, 1.1, 1.1]);
//! let end = nodes_in_box(&problem.mesh.nodes, [1.9, -0.1, -0.1], [2.1, 1.1, 1.1]);
//! problem.fix(&fixed);
//! problem.add_traction(&end, [10.0, 0.0, 0.0]);
//! let solution = StaticSolver::new(problem)?.solve(&SolverOptions::default())?;
//! // u_x = σ L / E = 0.02 m at the loaded end: the field is linear, so the elements hold it
//! // exactly, to the solver's tolerance.
//! for &n in &end {
//!     assert!((solution.u[3 * n] - 0.02).abs() < 1e-5 * 0.02, "{}", solution.u[3 * n]);
//! }
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

pub mod assembly;
pub mod element;
pub mod fbar;
pub mod geometric;
pub mod interrupt;
mod lanes;
pub mod linsolve;
pub mod material;
pub mod patch;
pub mod post;
pub mod problem;
pub mod solver;
pub mod verification;

pub use element::ElementGeometry;
pub use geometric::Attachment;
pub use material::{Formulation, Law, Material};
pub use problem::{force_shares, force_strays, nodal_masses, PointSpring, Problem};
pub use solver::{Continuation, Solution, SolveProgress, SolverOptions, StaticSolver, Timings};

/// `n` zeros, written now: a buffer made so has its pages touched when it is built rather than
/// at its first use (`vec![0.0; n]` may take untouched zero pages from the operating system).
pub(crate) fn written_zeros<T: Copy + Default>(n: usize) -> Vec<T> {
    let mut v = Vec::with_capacity(n);
    v.resize(n, T::default());
    v
}

/// Errors of a finite-element computation.
#[derive(Debug, thiserror::Error)]
pub enum FemError {
    /// An element whose deformation gradient (or reference Jacobian) has det ≤ 0.
    #[error("element {element} is inverted (det F = {det:.3e})")]
    InvertedElement {
        /// The element: its number in the mesh's file once out of the solver ([`mesh::Mesh::file_cell`]).
        element: usize,
        /// The offending determinant.
        det: f64,
    },
    /// The static solver's quasi-Newton iterations did not reach the tolerance.
    #[error(
        "the static solver did not converge at load factor {load_factor:.4} after {iterations} iterations \
         (relative residual {residual:.3e})"
    )]
    NotConverged {
        /// The load factor being solved for.
        load_factor: f64,
        /// Iterations spent.
        iterations: usize,
        /// Last relative residual.
        residual: f64,
    },
    /// Saint-Venant-Kirchhoff passed its compressive limit point: no static
    /// equilibrium exists beyond it under this load.
    #[error(
        "Saint-Venant-Kirchhoff passed its compressive limit point beyond load factor {load_factor:.3}, where element \
         {element} is compressed to a principal stretch of {stretch:.3} (SVK's uniaxial stress peaks at 1/sqrt(3) = \
         {limit:.3} and falls beyond, so no equilibrium exists under the full load){buckling}; use law = \
         \"neo_hookean\" for large compression",
        limit = material::SVK_LIMIT_STRETCH,
        buckling = if *stretch > material::SVK_BUCKLING_STRETCH {
            ", or the body buckled (no element is compressed by a fifth: a slender part under compression buckles \
             under any law; neo_hookean, which has no such limit, tells the two apart)"
        } else {
            ""
        }
    )]
    LimitPoint {
        /// The most compressed element at the last equilibrium, or in the failing iterate when no
        /// load step converged (numbered as for [`FemError::InvertedElement`]).
        element: usize,
        /// Its smallest principal stretch there.
        stretch: f64,
        /// The last load factor reached.
        load_factor: f64,
    },
    /// A law whose energy stays finite for a flat element (SVK, co-rotational) crushed one flat
    /// with the body still stiff: beyond, no equilibrium was found that keeps the element the
    /// right way out.
    #[error("{law} crushed element {element} flat by load factor {load_factor:.3} (its smallest principal stretch {stretch:.1e}) while the body stayed stiff; beyond it no equilibrium was found that keeps the element the right way out. The {law} energy lets an element pass through flat and turn inside out, which augsim refuses (codes that do not check, CalculiX among them, go on with inverted elements); use law = \"neo_hookean\", which resists crushing, or a finer mesh there")]
    CrushedFlat {
        /// The law's name ([`crate::Law::display_name`]).
        law: &'static str,
        /// The element crushed flat at the last equilibrium (numbered as for
        /// [`FemError::InvertedElement`]).
        element: usize,
        /// Its smallest principal stretch there.
        stretch: f64,
        /// The last load factor reached.
        load_factor: f64,
    },
    /// The load path turned back: the smallest load step past the last equilibrium found none,
    /// even with a long descent.
    #[error("no equilibrium found beyond load factor {load_factor:.3}{}, and {iterations} further iterations found none; lower the load, hold the body more firmly, or push with a displacement", stiffness_note(*.softening, *.indefinite))]
    NoEquilibrium {
        /// The last load factor reached.
        load_factor: f64,
        /// The stiffness of the last load step against that at rest, in per cent (NaN where
        /// unknown).
        softening: f64,
        /// The tangent stiffness was found indefinite there: the body lost its stability.
        indefinite: bool,
        /// Iterations the last attempt took before it failed.
        iterations: usize,
    },
    /// A NaN or infinity appeared.
    #[error("non-finite value in {0}")]
    NonFinite(String),
    /// The sparse factorisation failed.
    #[error("factorisation failed: {0}")]
    Factorization(String),
    /// Inconsistent input.
    #[error("invalid problem: {0}")]
    Invalid(String),
    /// A mesh error.
    #[error(transparent)]
    Mesh(#[from] mesh::MeshError),
    /// The computation was asked to stop ([`interrupt::request`]).
    #[error("interrupted")]
    Interrupted,
    /// The solve passed its deadline ([`SolverOptions::deadline`]) before it converged.
    #[error("the solve passed its deadline before it converged")]
    OutOfTime,
}

impl FemError {
    /// The error with its element named by its number in `mesh`'s file ([`mesh::Mesh::file_cell`]),
    /// as the user knows it, rather than by its index.
    pub(crate) fn in_file_numbers(self, mesh: &mesh::Mesh) -> Self {
        match self {
            FemError::InvertedElement { element, det } => {
                FemError::InvertedElement { element: mesh.file_cell(element), det }
            }
            FemError::LimitPoint { element, stretch, load_factor } => {
                FemError::LimitPoint { element: mesh.file_cell(element), stretch, load_factor }
            }
            FemError::CrushedFlat { law, element, stretch, load_factor } => {
                FemError::CrushedFlat { law, element: mesh.file_cell(element), stretch, load_factor }
            }
            other => other,
        }
    }
}

/// The stiffness of a load path's last step, in per cent of that at rest, under which a failure to
/// go on is told as a limit point (the AMOS liver pushed by 1 N reaches 2 % there).
const LIMIT_POINT_STIFFNESS: f64 = 25.0;

/// What [`FemError::NoEquilibrium`] says of the load path: a limit point where its last steps had
/// softened to under [`LIMIT_POINT_STIFFNESS`] per cent of the stiffness at rest; where they had
/// not, a loss of stability if the tangent turned `indefinite` there, no sign of a limit point
/// otherwise; nothing of the stiffness where it is unknown.
fn stiffness_note(softening: f64, indefinite: bool) -> String {
    let lost = ": the tangent stiffness turned indefinite there, the body losing its stability (a bifurcation: \
                past it the body buckles, snaps or gives way under this load)";
    if softening <= 0.0 {
        format!(
            ": the load path had turned there (its stiffness {softening:.1} % of that at rest: a limit point, past \
             which the body snaps or gives way under this load)"
        )
    } else if softening < LIMIT_POINT_STIFFNESS {
        format!(
            ": the response there was {softening:.1} % as stiff as at rest (a limit point of the load path: past it the \
             body snaps or gives way under this load)"
        )
    } else if indefinite && softening.is_finite() {
        format!("{lost}, its response along the load still {softening:.1} % as stiff as at rest")
    } else if indefinite {
        lost.to_string()
    } else if softening.is_finite() {
        format!(
            ": the response there was still {softening:.1} % as stiff as at rest (no sign of a limit point: more \
             iterations, [solver] max_iterations, or more load_steps may find it)"
        )
    } else {
        String::new()
    }
}
