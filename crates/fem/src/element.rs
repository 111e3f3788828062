//! Element geometry (shape-function gradients and quadrature weights in the
//! reference configuration) and element kernels (internal force and tangent).

use std::ops::Range;

use mesh::{Cells, Mesh};
use nalgebra::Matrix3;

use crate::material::{Formulation, Material};
use crate::patch::{Patches, TET_PATCH_SIZE};
use crate::FemError;

/// The nodes of H8's reference cube in VTK order.
const HEX_REF: [[f64; 3]; 8] = [
    [-1., -1., -1.],
    [1., -1., -1.],
    [1., 1., -1.],
    [-1., 1., -1.],
    [-1., -1., 1.],
    [1., -1., 1.],
    [1., 1., 1.],
    [-1., 1., 1.],
];

/// Precomputed quadrature data of every element of a mesh.
#[derive(Clone, Debug)]
pub struct ElementGeometry {
    /// Nodes per element (4, 8 or 10).
    pub nodes_per_element: usize,
    /// Quadrature points per element (1 for T4, 8 for H8, 4 for T10).
    pub points_per_element: usize,
    /// Element connectivity, `nodes_per_element` entries per element.
    pub connectivity: Vec<usize>,
    /// ∂N_a/∂X at each quadrature point: index `(e * points + q) * nodes + a`.
    pub grads: Vec<[f64; 3]>,
    /// Shape function values at each quadrature point (same for all elements): `q * nodes + a`.
    pub shape: Vec<f64>,
    /// Quadrature weight × det J × cell fraction: index `e * points + q`.
    pub weights: Vec<f64>,
    /// The formulation: [`Formulation::Standard`] or [`Formulation::Fbar`].
    pub formulation: Formulation,
    /// The assembly units: one element each (standard, H8 and T10 F-bar) or groups of
    /// about [`TET_PATCH_SIZE`] tetrahedra sharing their volume ratio (T4 F-bar).
    pub patches: Patches,
}

impl ElementGeometry {
    /// Computes gradients, weights and patches for the formulation
    /// ([`Formulation::Auto`] is taken as standard: resolve it with
    /// [`Material::resolved_formulation`] first); fails on a degenerate or
    /// inverted element.
    pub fn new(mesh: &Mesh, formulation: Formulation) -> Result<Self, FemError> {
        let mut geometry = Self::standard(mesh)?;
        if formulation == Formulation::Fbar {
            geometry.formulation = Formulation::Fbar;
            if geometry.nodes_per_element == 4 {
                geometry.patches = Patches::tetrahedra(&geometry.connectivity, TET_PATCH_SIZE);
            }
        }
        Ok(geometry)
    }

    fn standard(mesh: &Mesh) -> Result<Self, FemError> {
        match &mesh.cells {
            Cells::Tet4(tets) => {
                let ne = tets.len();
                let fraction = |e: usize| mesh.cell_fraction.as_ref().map_or(1.0, |f| f[e]);
                let connectivity: Vec<usize> = tets.iter().flatten().copied().collect();
                let x = |k: usize| nalgebra::Vector3::from(mesh.nodes[k]);
                let mut grads = Vec::with_capacity(4 * ne);
                let mut weights = Vec::with_capacity(ne);
                for (e, t) in tets.iter().enumerate() {
                    let dm = Matrix3::from_columns(&[x(t[1]) - x(t[0]), x(t[2]) - x(t[0]), x(t[3]) - x(t[0])]);
                    let det = dm.determinant();
                    let inv =
                        dm.try_inverse().filter(|_| det > 0.0).ok_or(FemError::InvertedElement { element: e, det })?;
                    let g: [[f64; 3]; 3] = std::array::from_fn(|a| [inv[(a, 0)], inv[(a, 1)], inv[(a, 2)]]);
                    grads.push(std::array::from_fn(|d| -(g[0][d] + g[1][d] + g[2][d])));
                    grads.extend_from_slice(&g);
                    weights.push(det / 6.0 * fraction(e));
                }
                Ok(ElementGeometry {
                    nodes_per_element: 4,
                    points_per_element: 1,
                    patches: Patches::singletons(&connectivity, 4),
                    connectivity,
                    grads,
                    shape: vec![0.25; 4],
                    weights,
                    formulation: Formulation::Standard,
                })
            }
            Cells::Hex8(hexes) => {
                let gp = 1.0 / 3f64.sqrt();
                let points: Vec<[f64; 3]> = HEX_REF.iter().map(|r| r.map(|c| c * gp)).collect();
                let mut shape = Vec::with_capacity(64);
                let mut dref = Vec::with_capacity(64);
                for p in &points {
                    for r in &HEX_REF {
                        let f = |d: usize| 1.0 + r[d] * p[d];
                        shape.push(f(0) * f(1) * f(2) / 8.0);
                        dref.push([r[0] * f(1) * f(2) / 8.0, f(0) * r[1] * f(2) / 8.0, f(0) * f(1) * r[2] / 8.0]);
                    }
                }
                isoparametric(mesh, hexes, shape, &dref, &[1.0; 8])
            }
            Cells::Tet10(tets) => {
                // The 4-point Gauss rule (degree 2: the linear-elastic tangent exactly) at barycentric
                // coordinates (a, b, b, b) and permutations; reference coordinates ξ = (λ1, λ2, λ3).
                let (a, b) = (0.585_410_196_624_968_5, 0.138_196_601_125_010_5);
                let mut shape = Vec::with_capacity(40);
                let mut dref = Vec::with_capacity(40);
                for q in 0..4 {
                    let l: [f64; 4] = std::array::from_fn(|k| if k == q { a } else { b });
                    shape.extend(mesh::tet10_shape(l));
                    dref.extend(mesh::tet10_shape_derivatives(l).map(|d| [d[1] - d[0], d[2] - d[0], d[3] - d[0]]));
                }
                isoparametric(mesh, tets, shape, &dref, &[1.0 / 24.0; 4])
            }
        }
    }

    /// Number of elements.
    pub fn len(&self) -> usize {
        self.weights.len() / self.points_per_element
    }

    /// True when there is no element.
    pub fn is_empty(&self) -> bool {
        self.weights.is_empty()
    }

    /// Node indices of element `e`.
    pub fn element_nodes(&self, e: usize) -> &[usize] {
        &self.connectivity[e * self.nodes_per_element..(e + 1) * self.nodes_per_element]
    }

    /// Deformation gradient F = I + Σ_a u_a ⊗ ∇N_a at quadrature point `q` of element `e`.
    pub fn deformation_gradient(&self, e: usize, q: usize, u: &[f64]) -> Matrix3<f64> {
        let npe = self.nodes_per_element;
        let g = &self.grads[(e * self.points_per_element + q) * npe..][..npe];
        let mut f = Matrix3::identity();
        for (a, &n) in self.element_nodes(e).iter().enumerate() {
            for i in 0..3 {
                for j in 0..3 {
                    f[(i, j)] += u[3 * n + i] * g[a][j];
                }
            }
        }
        f
    }

    /// Internal forces of the elements `elements`, one after the other in `f` (3 per element
    /// node): the deformation gradients of all their quadrature points first, then every
    /// stress at once ([`Material::stresses`], which vectorises the co-rotational law).
    /// Fails when det F ≤ 0 at a quadrature point for a law that needs det F > 0, or when
    /// a force is not finite.
    pub fn forces(
        &self,
        elements: Range<usize>,
        material: &Material,
        u: &[f64],
        f: &mut [f64],
        scratch: &mut ForceScratch,
    ) -> Result<(), FemError> {
        let (npe, nq) = (self.nodes_per_element, self.points_per_element);
        let ForceScratch { gradients, stresses } = scratch;
        gradients.clear();
        gradients.reserve(elements.len() * nq);
        for e in elements.clone() {
            for q in 0..nq {
                gradients.push(self.checked_gradient(e, q, material, u)?);
            }
        }
        stresses.resize(gradients.len(), Matrix3::zeros());
        material.stresses(gradients, stresses);
        f.fill(0.0);
        for (i, e) in elements.enumerate() {
            let fe = &mut f[3 * npe * i..3 * npe * (i + 1)];
            for q in 0..nq {
                let at = e * nq + q;
                add_point_force(fe, self.weights[at], &stresses[i * nq + q], &self.grads[at * npe..][..npe]);
            }
            if fe.iter().any(|v| !v.is_finite()) {
                return Err(FemError::NonFinite(format!("internal force of element {e}")));
            }
        }
        Ok(())
    }

    /// The deformation gradient at point `q` of element `e`, checked against inversion.
    fn checked_gradient(&self, e: usize, q: usize, material: &Material, u: &[f64]) -> Result<Matrix3<f64>, FemError> {
        let fg = self.deformation_gradient(e, q, u);
        let det = fg.determinant();
        if !det.is_finite() || (material.law.needs_positive_jacobian() && det <= 0.0) {
            return Err(FemError::InvertedElement { element: e, det });
        }
        Ok(fg)
    }

    /// Internal force `f` (3n entries) and, when `k` is given, tangent stiffness (3n×3n,
    /// row-major, local dof `3a + i`) of element `e` at displacement `u`. Fails as
    /// [`ElementGeometry::forces`] does.
    pub fn force_tangent(
        &self,
        e: usize,
        material: &Material,
        u: &[f64],
        f: &mut [f64],
        k: Option<&mut [f64]>,
    ) -> Result<(), FemError> {
        let Some(k) = k else {
            return self.forces(e..e + 1, material, u, f, &mut ForceScratch::default());
        };
        let npe = self.nodes_per_element;
        let ndof = 3 * npe;
        f.fill(0.0);
        k.fill(0.0);
        for q in 0..self.points_per_element {
            let w = self.weights[e * self.points_per_element + q];
            let g = &self.grads[(e * self.points_per_element + q) * npe..][..npe];
            let fg = self.checked_gradient(e, q, material, u)?;
            let (p, a_tan) = material.stress_tangent(&fg);
            add_point_force(f, w, &p, g);
            // Q_a[i][k][L] = Σ_J g_aJ A_iJkL, then K_ab,ik = Σ_L Q_a[i][k][L] g_bL.
            for a in 0..npe {
                let mut qa = [[0.0; 9]; 3];
                for i in 0..3 {
                    for j in 0..3 {
                        let gj = g[a][j] * w;
                        let row = &a_tan[3 * i + j];
                        for kl in 0..9 {
                            qa[i][kl] += gj * row[kl];
                        }
                    }
                }
                for b in a..npe {
                    for i in 0..3 {
                        let out = &mut k[(3 * a + i) * ndof + 3 * b..][..3];
                        for kk in 0..3 {
                            out[kk] +=
                                qa[i][3 * kk] * g[b][0] + qa[i][3 * kk + 1] * g[b][1] + qa[i][3 * kk + 2] * g[b][2];
                        }
                    }
                }
            }
        }
        // The tangent is symmetric: only blocks b ≥ a were accumulated.
        mirror_upper_blocks(k, ndof);
        if f.iter().any(|v| !v.is_finite()) {
            return Err(FemError::NonFinite(format!("internal force of element {e}")));
        }
        Ok(())
    }
}

/// The geometry of isoparametric elements with `N` nodes: `shape` and `dref` hold N_a and
/// ∂N_a/∂ξ at each reference quadrature point (`q * N + a`), whose reference weights are
/// `ref_weights`. Fails on a point where the map from the reference element is not positive.
fn isoparametric<const N: usize>(
    mesh: &Mesh,
    cells: &[[usize; N]],
    shape: Vec<f64>,
    dref: &[[f64; 3]],
    ref_weights: &[f64],
) -> Result<ElementGeometry, FemError> {
    let nq = ref_weights.len();
    let fraction = |e: usize| mesh.cell_fraction.as_ref().map_or(1.0, |f| f[e]);
    let mut grads = Vec::with_capacity(N * nq * cells.len());
    let mut weights = Vec::with_capacity(nq * cells.len());
    for (e, cell) in cells.iter().enumerate() {
        for (q, w) in ref_weights.iter().enumerate() {
            let mut j = Matrix3::zeros();
            for (a, &n) in cell.iter().enumerate() {
                j += nalgebra::Vector3::from(mesh.nodes[n]) * nalgebra::RowVector3::from(dref[q * N + a]);
            }
            let det = j.determinant();
            let jinv = j.try_inverse().filter(|_| det > 0.0).ok_or(FemError::InvertedElement { element: e, det })?;
            for a in 0..N {
                let g = nalgebra::RowVector3::from(dref[q * N + a]) * jinv;
                grads.push([g[0], g[1], g[2]]);
            }
            weights.push(w * det * fraction(e));
        }
    }
    let connectivity: Vec<usize> = cells.iter().flatten().copied().collect();
    Ok(ElementGeometry {
        nodes_per_element: N,
        points_per_element: nq,
        patches: Patches::singletons(&connectivity, N),
        connectivity,
        grads,
        shape,
        weights,
        formulation: Formulation::Standard,
    })
}

/// Copies the node blocks above the diagonal of a symmetric row-major `ndof × ndof` tangent
/// (3 × 3 blocks, local dof `3a + i`) onto those below it.
pub(crate) fn mirror_upper_blocks(k: &mut [f64], ndof: usize) {
    for r in 0..ndof {
        for s in 3 * (r / 3 + 1)..ndof {
            k[s * ndof + r] = k[r * ndof + s];
        }
    }
}

/// Scratch space of [`ElementGeometry::forces`], reused across calls.
#[derive(Clone, Debug, Default)]
pub struct ForceScratch {
    gradients: Vec<Matrix3<f64>>,
    stresses: Vec<Matrix3<f64>>,
}

/// Adds a quadrature point's force, w · P ∇N_a per node a, to an element's force `f`.
fn add_point_force(f: &mut [f64], w: f64, p: &Matrix3<f64>, g: &[[f64; 3]]) {
    for (a, ga) in g.iter().enumerate() {
        for i in 0..3 {
            f[3 * a + i] += w * (p[(i, 0)] * ga[0] + p[(i, 1)] * ga[1] + p[(i, 2)] * ga[2]);
        }
    }
}
