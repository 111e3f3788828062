//! The F-bar patch kernel: internal force and consistent tangent of a patch of
//! elements whose quadrature points share one volume measure.
//!
//! Each quadrature point q of the patch (weight w_q, deformation gradient F_q)
//! is evaluated at F̄_q = Φ(F_q, m̄) where m̄ = Σ c_q m(F_q), c_q = w_q / V_P,
//! is the volume average over the patch of a volume measure m:
//! - finite strain: m = J = det F and Φ = (m̄/J)^⅓ F (F-bar);
//! - linear law: m = tr F − 3 = div u and Φ = F + ⅓(m̄ − m) I (B-bar),
//!   which keeps the linear law linear.
//!
//! The patch energy is Π = Σ_q w_q W(F̄_q). Writing M_q = ∂Φ/∂F and
//! φ_q = ∂Φ/∂m̄, its gradient with respect to F_q is
//! g_q = w_q M_qᵀ P̄_q + σ̄ c_q ∂m_q with σ̄ = Σ_p w_p P̄_p : φ_p, and its Hessian is
//! D_q δ_qr + a_q ⊗ b_r + b_q ⊗ a_r + γ b_q ⊗ b_r with
//! D_q = w_q (M_qᵀ A_q M_q + P̄_q : ∂²Φ/∂F²) + σ̄ c_q ∂²m_q,
//! a_q = w_q (M_qᵀ A_q φ_q + P̄_q : ∂²Φ/∂F∂m̄), b_q = c_q ∂m_q and
//! γ = Σ_p w_p (φ_pᵀ A_p φ_p + P̄_p : ∂²Φ/∂m̄²). Mapped to the patch's nodal
//! dofs, the tangent is Σ_q B_qᵀ D_q B_q + ā b̄ᵀ + b̄ āᵀ + γ b̄ b̄ᵀ with
//! ā = Σ_q B_qᵀ a_q and b̄ = Σ_q B_qᵀ b_q = ∂m̄/∂u.
//!
//! For both measures M = α (I − ⅓ x yᵀ) with (α, x, y) = ((m̄/J)^⅓, F, F⁻ᵀ) for
//! F-bar and (1, I, I) for B-bar, and φ = ϕ x with ϕ = α / (3 m̄) and ⅓.
//!
//! *Stabilised quadratic F-bar.* A T10 averages J over its own four points, and only the
//! average then meets the volumetric stiffness: a point's own J is held by the shear modulus
//! alone. Under compression by centimetres the tangent then loses positive definiteness
//! (a spurious mode: on the liver phantom one point at J = 0.19 in an element whose mean is
//! 0.93) and a quarter of the large-load draws of `liver_forces_large` found no solution; in
//! bending a T10 with J constant per element is also far too soft (58 % off on a 10 × 1 × 1
//! cantilever). So T10 adds a stabilising energy κ_s/2 Σ_q w_q d_q², d_q = g(m_q) − g(m̄)
//! (g = ln for finite strain, g(m) = m for B-bar), with κ_s Lamé's λ of the same material at
//! Poisson's ratio min(ν, [`FBAR_POISSON`]): the volumetric stiffness of a solid that does not
//! lock acts at every point, only the excess over it is relaxed (a split of the bulk modulus
//! between full and reduced integration, as in Hughes' selective integration). The energy
//! vanishes under any homogeneous deformation (patch test) and rigid motion; with
//! s_q = κ_s (w_q d_q g′_q − c_q g′(m̄) D), D = Σ_q w_q d_q, it adds s_q ∂m_q to g_q,
//! s_q ∂²m_q + κ_s w_q (g′_q² + d_q g″_q) ∂m_q ⊗ ∂m_q to D_q, −κ_s g′(m̄) w_q g′_q ∂m_q to a_q and
//! κ_s (g′(m̄)² V_P − g″(m̄) D) to γ.

use std::ops::Range;

use nalgebra::Matrix3;

use crate::element::{mirror_upper_blocks, ElementGeometry};
use crate::material::{cofactor, Law, Material, Tangent, FBAR_POISSON};
use crate::FemError;

type V9 = [f64; 9];

/// The identity, flattened.
const IDENTITY: V9 = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0];

fn flat(m: &Matrix3<f64>) -> V9 {
    std::array::from_fn(|r| m[(r / 3, r % 3)])
}

fn dot(a: &V9, b: &V9) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

fn mat_vec(a: &Tangent, x: &V9) -> V9 {
    std::array::from_fn(|r| dot(&a[r], x))
}

/// x^⅓ for x > 0 to within one unit in the last place, twice as fast as `f64::cbrt` (which
/// rounds correctly): an estimate from the exponent bits (within 6 %), two Halley steps
/// (cubic convergence) and one Newton step.
fn cube_root(x: f64) -> f64 {
    if !(x.is_normal() && x > 0.0) {
        return x.cbrt();
    }
    let mut y = f64::from_bits(x.to_bits() / 3 + (0x2a9f_7893_u64 << 32));
    for _ in 0..2 {
        let y3 = y * y * y;
        y *= (y3 + 2.0 * x) / (2.0 * y3 + x);
    }
    y - (y * y * y - x) / (3.0 * y * y)
}

/// Scratch space of a patch evaluation, reused across patches.
#[derive(Clone, Debug, Default)]
pub struct PatchScratch {
    points: Vec<PatchPoint>,
    /// A = ∂P/∂F at F̄ per point (tangent evaluations only).
    tangents: Vec<Tangent>,
    /// F̄ and P̄ per point (force evaluations only).
    gradients: Vec<Matrix3<f64>>,
    stresses: Vec<Matrix3<f64>>,
    /// Each patch's first point and kinematics (force evaluations only).
    kinematics: Vec<(usize, Kinematics)>,
}

/// Per-quadrature-point state of a patch evaluation.
#[derive(Clone, Debug)]
struct PatchPoint {
    slot: usize,
    grads: usize,
    w: f64,
    f: Matrix3<f64>,
    /// ∂m/∂F: cof F = J F⁻ᵀ for finite strain, I for the linear law.
    dm: V9,
    /// Volume measure m(F): J or tr F − 3.
    m: f64,
    /// d = g(m) − g(m̄), the deviation the stabilisation penalises (0 without it).
    deviation: f64,
    alpha: f64,
    stress: V9,
}

/// Kinematics shared by force, tangent and post-processing.
#[derive(Clone, Debug)]
struct Kinematics {
    linear: bool,
    /// Patch volume average of m.
    mean: f64,
    volume: f64,
    /// The stabilising modulus κ_s ([`stabilization_modulus`]; 0: none).
    kappa: f64,
    /// D = Σ_q w_q d_q (with κ_s only).
    deviation: f64,
}

/// Appends the patch's quadrature points to `points` and returns the patch's
/// kinematics (m̄, volume, and D with a stabilising modulus `kappa` > 0); fails on an
/// inverted element for the finite-strain laws.
fn gather(
    geo: &ElementGeometry,
    patch: usize,
    law: Law,
    kappa: f64,
    u: &[f64],
    points: &mut Vec<PatchPoint>,
) -> Result<Kinematics, FemError> {
    let linear = law == Law::Linear;
    let start = points.len();
    let (mut volume, mut sum) = (0.0, 0.0);
    let nq = geo.points_per_element;
    for (slot, &e) in geo.patches.elements(patch).iter().enumerate() {
        for q in 0..nq {
            let f = geo.deformation_gradient(e, q, u);
            // ∂J/∂F = cof F; ∂(tr F − 3)/∂F = I.
            let (m, dm) = if linear {
                (f.trace() - 3.0, IDENTITY)
            } else {
                let cof = cofactor(&f);
                (f.row(0).dot(&cof.row(0)), flat(&cof))
            };
            if !m.is_finite() || (!linear && m <= 0.0) {
                return Err(FemError::InvertedElement { element: e, det: m });
            }
            let w = geo.weights[e * nq + q];
            volume += w;
            sum += w * m;
            points.push(PatchPoint {
                slot,
                grads: (e * nq + q) * geo.nodes_per_element,
                w,
                f,
                dm,
                m,
                deviation: 0.0,
                alpha: 1.0,
                stress: [0.0; 9],
            });
        }
    }
    if !(volume > 0.0) {
        return Err(FemError::Invalid(format!("patch {patch} has no volume")));
    }
    let mut kin = Kinematics { linear, mean: sum / volume, volume, kappa, deviation: 0.0 };
    if kin.kappa > 0.0 {
        let g_mean = kin.g(kin.mean);
        for p in &mut points[start..] {
            p.deviation = kin.g(p.m) - g_mean;
            kin.deviation += p.w * p.deviation;
        }
    }
    Ok(kin)
}

/// The stabilising modulus κ_s of quadratic F-bar: Lamé's λ of the material with its Poisson's
/// ratio capped at [`FBAR_POISSON`]; 0 for the other elements (see the module's doc).
fn stabilization_modulus(geo: &ElementGeometry, material: &Material) -> f64 {
    if geo.nodes_per_element != 10 {
        return 0.0;
    }
    Material { poisson: material.poisson.min(FBAR_POISSON), ..*material }.lame().0
}

impl Kinematics {
    /// F̄ at a point, with α.
    fn modified(&self, p: &PatchPoint) -> (Matrix3<f64>, f64) {
        if self.linear {
            (p.f + Matrix3::identity() * ((self.mean - p.m) / 3.0), 1.0)
        } else {
            let alpha = cube_root(self.mean / p.m);
            (p.f * alpha, alpha)
        }
    }

    /// x of M = α (I − ⅓ x yᵀ): F, or I for the linear law.
    fn x(&self, p: &PatchPoint) -> V9 {
        if self.linear {
            IDENTITY
        } else {
            flat(&p.f)
        }
    }

    /// The factor s in y = ∂m/∂F / s: J, or 1 for the linear law.
    fn y_scale(&self, p: &PatchPoint) -> f64 {
        if self.linear {
            1.0
        } else {
            p.m
        }
    }

    /// The measure's log for finite strain (g = ln m), itself for the linear law (g = m).
    fn g(&self, m: f64) -> f64 {
        if self.linear {
            m
        } else {
            m.ln()
        }
    }

    /// g′(m).
    fn g1(&self, m: f64) -> f64 {
        if self.linear {
            1.0
        } else {
            1.0 / m
        }
    }

    /// g″(m).
    fn g2(&self, m: f64) -> f64 {
        if self.linear {
            0.0
        } else {
            -1.0 / (m * m)
        }
    }

    /// The stabilisation's stress factor s_q = κ_s (w_q d_q g′(m_q) − c_q g′(m̄) D): its force is
    /// s_q ∂m_q.
    fn stabilization_factor(&self, p: &PatchPoint) -> f64 {
        if self.kappa == 0.0 {
            return 0.0;
        }
        let c = p.w / self.volume;
        self.kappa * (p.w * p.deviation * self.g1(p.m) - c * self.g1(self.mean) * self.deviation)
    }

    /// ϕ in φ = ∂Φ/∂m̄ = ϕ x.
    fn phi(&self, alpha: f64) -> f64 {
        if self.linear {
            1.0 / 3.0
        } else {
            alpha / (3.0 * self.mean)
        }
    }
}

/// The modified deformation gradients F̄ of every quadrature point of the
/// patch, in the order of its elements and their points.
pub fn patch_gradients(
    geo: &ElementGeometry,
    patch: usize,
    law: Law,
    u: &[f64],
) -> Result<Vec<Matrix3<f64>>, FemError> {
    let mut points = Vec::new();
    let kin = gather(geo, patch, law, 0.0, u, &mut points)?;
    Ok(points.iter().map(|p| kin.modified(p).0).collect())
}

/// Internal forces of the patches `patches`, one after the other in `f` (3 per patch node):
/// the modified gradients of all their quadrature points first, then every stress at once
/// ([`Material::stresses`], which vectorises the co-rotational law). The same values, bit
/// for bit, as [`patch_force_tangent`] without a tangent, patch by patch.
pub fn patch_forces(
    geo: &ElementGeometry,
    patches: Range<usize>,
    material: &Material,
    u: &[f64],
    f: &mut [f64],
    scratch: &mut PatchScratch,
) -> Result<(), FemError> {
    let PatchScratch { points, gradients, stresses, kinematics, .. } = scratch;
    points.clear();
    gradients.clear();
    kinematics.clear();
    for patch in patches.clone() {
        let start = points.len();
        let kin = gather(geo, patch, material.law, stabilization_modulus(geo, material), u, points)?;
        for p in &mut points[start..] {
            let (fbar, alpha) = kin.modified(p);
            p.alpha = alpha;
            gradients.push(fbar);
        }
        kinematics.push((start, kin));
    }
    stresses.resize(gradients.len(), Matrix3::zeros());
    material.stresses(gradients, stresses);
    let mut offset = 0;
    for (i, patch) in patches.enumerate() {
        let (start, kin) = &kinematics[i];
        let end = kinematics.get(i + 1).map_or(points.len(), |k| k.0);
        let fp = &mut f[offset..offset + 3 * geo.patches.nodes(patch).len()];
        offset += fp.len();
        let mut sigma_bar = 0.0;
        for (p, stress) in points[*start..end].iter_mut().zip(&stresses[*start..end]) {
            p.stress = flat(stress);
            sigma_bar += p.w * kin.phi(p.alpha) * dot(&p.stress, &kin.x(p));
        }
        fp.fill(0.0);
        for p in &points[*start..end] {
            add_point_force(geo, patch, kin, p, sigma_bar, fp);
        }
        check_finite(geo, patch, fp)?;
    }
    Ok(())
}

/// Adds a point's force g · ∇N_a to the patch's nodal forces `f`, with
/// g = w Mᵀ P̄ + σ̄ c ∂m = w α (P̄ − ⅓ (x·P̄) y) + σ̄ c ∂m and y = ∂m / s.
fn add_point_force(
    geo: &ElementGeometry,
    patch: usize,
    kin: &Kinematics,
    p: &PatchPoint,
    sigma_bar: f64,
    f: &mut [f64],
) {
    let c = p.w / kin.volume;
    let xp = dot(&kin.x(p), &p.stress);
    let (wa, dm_factor) =
        (p.w * p.alpha, sigma_bar * c - p.w * p.alpha * xp / (3.0 * kin.y_scale(p)) + kin.stabilization_factor(p));
    let g: V9 = std::array::from_fn(|r| wa * p.stress[r] + dm_factor * p.dm[r]);
    let npe = geo.nodes_per_element;
    let grads = &geo.grads[p.grads..p.grads + npe];
    for (&la, ga) in geo.patches.local_nodes(patch, p.slot).iter().zip(grads) {
        for i in 0..3 {
            f[3 * la as usize + i] += g[3 * i] * ga[0] + g[3 * i + 1] * ga[1] + g[3 * i + 2] * ga[2];
        }
    }
}

/// Fails when a force of the patch is not finite.
fn check_finite(geo: &ElementGeometry, patch: usize, f: &[f64]) -> Result<(), FemError> {
    if f.iter().any(|v| !v.is_finite()) {
        return Err(FemError::NonFinite(format!(
            "internal force of the patch of element {}",
            geo.patches.elements(patch)[0]
        )));
    }
    Ok(())
}

/// The second derivatives of patch point `p` (of tangent `tangent` = ∂P/∂F at F̄) in the
/// patch's consistent tangent: D, on its own deformation gradient, and a, coupling it to the
/// patch's mean m̄ (`sigma_bar`: σ̄).
fn point_terms(kin: &Kinematics, p: &PatchPoint, tangent: &Tangent, sigma_bar: f64) -> (Tangent, V9) {
    let (x, dm) = (kin.x(p), &p.dm);
    let c = p.w / kin.volume;
    let alpha = p.alpha;
    let xp = dot(&x, &p.stress);
    let y = dm.map(|v| v / kin.y_scale(p));
    let mt_p: V9 = std::array::from_fn(|r| alpha * (p.stress[r] - xp * y[r] / 3.0));
    // D = w (Mᵀ A M + P̄ : ∂²Φ/∂F²) + σ̄ c ∂²m.
    let ax = mat_vec(tangent, &x);
    let xax = dot(&x, &ax);
    let a2 = alpha * alpha;
    let mut d: Tangent = std::array::from_fn(|r| {
        std::array::from_fn(|s| {
            p.w * a2 * (tangent[r][s] - (ax[r] * y[s] + y[r] * ax[s]) / 3.0 + xax * y[r] * y[s] / 9.0)
        })
    });
    let phi = kin.phi(alpha);
    // a = w (Mᵀ A φ + P̄ : ∂²Φ/∂F∂m̄).
    let mut av: V9 = std::array::from_fn(|r| p.w * phi * alpha * (ax[r] - xax * y[r] / 3.0));
    // The stabilisation: s_q ∂²m_q + κ_s w_q (g′(m_q)² + d_q g″(m_q)) ∂m_q ⊗ ∂m_q in D, and
    // −κ_s g′(m̄) w_q g′(m_q) ∂m_q in a (s_q ∂²m_q with the finite-strain terms below).
    let stabilization = kin.stabilization_factor(p);
    if kin.kappa > 0.0 {
        let diagonal = kin.kappa * p.w * (kin.g1(p.m).powi(2) + p.deviation * kin.g2(p.m));
        let coupling = -kin.kappa * kin.g1(kin.mean) * p.w * kin.g1(p.m);
        for r in 0..9 {
            for s in 0..9 {
                d[r][s] += diagonal * dm[r] * dm[s];
            }
            av[r] += coupling * dm[r];
        }
    }
    if !kin.linear {
        let finv = Matrix3::from_fn(|r, c| y[3 * c + r]);
        let tau = xp; // P̄ : F
        let jac = p.m;
        for r in 0..9 {
            let (i, jj) = (r / 3, r % 3);
            for s in 0..9 {
                let (kk, l) = (s / 3, s % 3);
                let t = finv[(jj, kk)] * finv[(l, i)];
                // P̄ : ∂²Φ/∂F² = −α/3 (P̄⊗y + y⊗P̄) + α τ/9 y⊗y + α τ/3 T.
                let g_ff = -alpha / 3.0 * (p.stress[r] * y[s] + y[r] * p.stress[s])
                    + alpha * tau / 9.0 * y[r] * y[s]
                    + alpha * tau / 3.0 * t;
                // ∂²J = J (y⊗y − T).
                d[r][s] += p.w * g_ff + (sigma_bar * c + stabilization) * jac * (y[r] * y[s] - t);
            }
            av[r] += p.w * mt_p[r] / (3.0 * kin.mean);
        }
    }
    (d, av)
}

/// Internal force (`f`, 3 per patch node) and consistent tangent `k` (row-major, local dof
/// `3a + i` over the patch's nodes) of patch `patch`.
pub fn patch_force_tangent(
    geo: &ElementGeometry,
    patch: usize,
    material: &Material,
    u: &[f64],
    f: &mut [f64],
    k: &mut [f64],
    scratch: &mut PatchScratch,
) -> Result<(), FemError> {
    let PatchScratch { points, tangents, .. } = scratch;
    points.clear();
    let kin = gather(geo, patch, material.law, stabilization_modulus(geo, material), u, points)?;
    let ndof = f.len();
    // Stresses and tangents at F̄; σ̄ and γ.
    let (mut sigma_bar, mut gamma) = (0.0, 0.0);
    tangents.clear();
    for p in points.iter_mut() {
        let x = kin.x(p);
        let (fbar, alpha) = kin.modified(p);
        p.alpha = alpha;
        let (stress, t) = material.stress_tangent(&fbar);
        let phi = kin.phi(alpha);
        gamma += p.w * phi * phi * dot(&x, &mat_vec(&t, &x));
        tangents.push(t);
        p.stress = flat(&stress);
        sigma_bar += p.w * phi * dot(&p.stress, &x);
        if !kin.linear {
            // P̄ : ∂²Φ/∂m̄² with ∂²Φ/∂m̄² = −2α / (9 m̄²) F.
            gamma -= p.w * 2.0 * alpha / (9.0 * kin.mean * kin.mean) * dot(&p.stress, &x);
        }
    }
    // The stabilisation's share of γ: κ_s (g′(m̄)² V − g″(m̄) D).
    gamma += kin.kappa * (kin.g1(kin.mean).powi(2) * kin.volume - kin.g2(kin.mean) * kin.deviation);
    f.fill(0.0);
    k.fill(0.0);
    let (mut a_bar, mut b_bar) = (vec![0.0; ndof], vec![0.0; ndof]);
    let npe = geo.nodes_per_element;
    for (q, p) in points.iter().enumerate() {
        add_point_force(geo, patch, &kin, p, sigma_bar, f);
        let (dm, c) = (&p.dm, p.w / kin.volume);
        let grads = &geo.grads[p.grads..p.grads + npe];
        let local = geo.patches.local_nodes(patch, p.slot);
        let (d, av) = point_terms(&kin, p, &tangents[q], sigma_bar);
        let bv: V9 = dm.map(|v| c * v);
        for (a, &la) in local.iter().enumerate() {
            let ga = grads[a];
            let la = la as usize;
            for i in 0..3 {
                a_bar[3 * la + i] += av[3 * i] * ga[0] + av[3 * i + 1] * ga[1] + av[3 * i + 2] * ga[2];
                b_bar[3 * la + i] += bv[3 * i] * ga[0] + bv[3 * i + 1] * ga[1] + bv[3 * i + 2] * ga[2];
            }
            // Q[i][kL] = Σ_J ∇N_aJ D[iJ][kL]; K_ab,ik = Σ_L Q[i][kL] ∇N_bL.
            let mut qa = [[0.0; 9]; 3];
            for i in 0..3 {
                for j in 0..3 {
                    let row = &d[3 * i + j];
                    for s in 0..9 {
                        qa[i][s] += ga[j] * row[s];
                    }
                }
            }
            // Blocks on and above the diagonal only (patch node la ≤ lb); mirrored below.
            for (b, &lb) in local.iter().enumerate().filter(|(_, &lb)| lb >= la as u16) {
                let gb = grads[b];
                for i in 0..3 {
                    let out = &mut k[(3 * la + i) * ndof + 3 * lb as usize..][..3];
                    for kk in 0..3 {
                        out[kk] += qa[i][3 * kk] * gb[0] + qa[i][3 * kk + 1] * gb[1] + qa[i][3 * kk + 2] * gb[2];
                    }
                }
            }
        }
    }
    // The patch coupling on the blocks on and above the diagonal, then the tangent's symmetry.
    for r in 0..ndof {
        let first = 3 * (r / 3);
        let row = &mut k[r * ndof + first..(r + 1) * ndof];
        for (s, v) in (first..ndof).zip(row) {
            *v += a_bar[r] * b_bar[s] + b_bar[r] * a_bar[s] + gamma * b_bar[r] * b_bar[s];
        }
    }
    mirror_upper_blocks(k, ndof);
    check_finite(geo, patch, f)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::material::Formulation;
    use crate::patch::Patches;

    #[test]
    fn cube_root_is_within_one_ulp() {
        for i in 0..100_000 {
            let x = 10f64.powf(-6.0 + 12.0 * i as f64 / 100_000.0);
            let (fast, exact) = (cube_root(x), x.cbrt());
            assert!(fast.to_bits().abs_diff(exact.to_bits()) <= 1, "{x}: {fast} against {exact}");
        }
        assert_eq!(cube_root(1.0), 1.0);
        assert_eq!(cube_root(8.0), 2.0);
        assert_eq!(cube_root(0.0), 0.0);
        assert!(cube_root(f64::INFINITY).is_infinite());
    }

    /// On one-tetrahedron patches J̄ = J, so F-bar (and B-bar) must reproduce the
    /// standard element's force and tangent: two independent code paths.
    #[test]
    fn single_tetrahedron_patches_equal_the_standard_element() {
        let m = mesh::box_tet([0.0; 3], [1.0, 0.7, 0.5], [2, 2, 1]).unwrap();
        let mut geo = ElementGeometry::new(&m, Formulation::Fbar).unwrap();
        geo.patches = Patches::singletons(&geo.connectivity, 4);
        let u: Vec<f64> = (0..3 * m.num_nodes()).map(|i| 0.04 * ((i * 37 % 11) as f64 / 11.0 - 0.5)).collect();
        for law in [Law::Linear, Law::Corotational, Law::Svk, Law::NeoHookean] {
            let material = Material::new(law, 3000.0, 0.49);
            let mut scratch = PatchScratch::default();
            for e in 0..geo.len() {
                let (mut f1, mut k1, mut f2, mut k2) = (vec![0.0; 12], vec![0.0; 144], vec![0.0; 12], vec![0.0; 144]);
                patch_force_tangent(&geo, e, &material, &u, &mut f1, &mut k1, &mut scratch).unwrap();
                geo.force_tangent(e, &material, &u, &mut f2, Some(&mut k2)).unwrap();
                let scale = k2.iter().fold(0.0f64, |a, b| a.max(b.abs()));
                let df = f1.iter().zip(&f2).fold(0.0f64, |a, (x, y)| a.max((x - y).abs()));
                let dk = k1.iter().zip(&k2).fold(0.0f64, |a, (x, y)| a.max((x - y).abs()));
                assert!(df < 1e-10 * scale && dk < 1e-10 * scale, "{law:?} element {e}: |df| {df:e}, |dk| {dk:e}");
            }
        }
    }

    /// The chunked force path (all stresses of many patches at once) and the tangent path
    /// must give the same forces bit for bit: the solver mixes them.
    #[test]
    fn chunked_forces_equal_the_tangent_path() {
        let m = mesh::box_tet([0.0; 3], [1.0, 0.7, 0.5], [4, 3, 3]).unwrap();
        let geo = ElementGeometry::new(&m, Formulation::Fbar).unwrap();
        let np = geo.patches.len();
        let u: Vec<f64> = (0..3 * m.num_nodes()).map(|i| 0.04 * ((i * 37 % 11) as f64 / 11.0 - 0.5)).collect();
        for law in [Law::Linear, Law::Corotational, Law::Svk, Law::NeoHookean] {
            let material = Material::new(law, 3000.0, 0.49);
            let mut scratch = PatchScratch::default();
            let mut chunked = vec![0.0; 3 * geo.patches.node_offset(np)];
            patch_forces(&geo, 0..np, &material, &u, &mut chunked, &mut scratch).unwrap();
            let mut offset = 0;
            for p in 0..np {
                let nd = 3 * geo.patches.nodes(p).len();
                let (mut f, mut k) = (vec![0.0; nd], vec![0.0; nd * nd]);
                patch_force_tangent(&geo, p, &material, &u, &mut f, &mut k, &mut scratch).unwrap();
                assert_eq!(f, chunked[offset..offset + nd], "{law:?}, patch {p}");
                offset += nd;
            }
        }
    }
}
