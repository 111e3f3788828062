//! Constitutive laws: first Piola-Kirchhoff stress P(F) and its consistent
//! tangent A = ∂P/∂F for linear, co-rotational, Saint-Venant-Kirchhoff and
//! compressible Neo-Hookean elasticity.
//!
//! The tangent is stored as a 9×9 array with index `3*i + J` for `P_iJ` and
//! `3*k + L` for `F_kL` (row-major flattening of the 3×3 tensors).

use nalgebra::Matrix3;
use serde::{Deserialize, Serialize};

use crate::lanes::{Lanes, Mask};

/// ∂P/∂F as a 9×9 array (row-major flattening on both sides).
pub type Tangent = [[f64; 9]; 9];

/// The constitutive law.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Law {
    /// Hooke's law on the small-strain tensor ε = sym(F) − I.
    Linear,
    /// Co-rotational linear elasticity: F = R·S (polar decomposition),
    /// ε = S − I, P = R·(λ tr(ε) I + 2μ ε). Invariant to rigid rotations.
    Corotational,
    /// Saint-Venant-Kirchhoff: E = ½(FᵀF − I), S = λ tr(E) I + 2μE, P = F·S.
    Svk,
    /// Compressible Neo-Hookean: W = μ/2 (tr(FᵀF) − 3) − μ ln J + λ/2 (ln J)².
    NeoHookean,
}

impl Law {
    /// The law's name for people: "linear", "co-rotational", "SVK", "Neo-Hookean".
    pub fn display_name(self) -> &'static str {
        match self {
            Law::Linear => "linear",
            Law::Corotational => "co-rotational",
            Law::Svk => "SVK",
            Law::NeoHookean => "Neo-Hookean",
        }
    }

    /// Whether the law is only defined for det F > 0 (all but linear).
    pub fn needs_positive_jacobian(self) -> bool {
        self != Law::Linear
    }
}

/// How the elements treat the volume change, the part of the deformation that
/// locks displacement elements when the material is nearly incompressible.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Formulation {
    /// `fbar` when Poisson's ratio is at least [`FBAR_POISSON`], `standard` otherwise.
    #[default]
    Auto,
    /// Displacement elements: each quadrature point deforms by its own F.
    Standard,
    /// F-bar (de Souza Neto et al. 1996, 2005): each quadrature point uses
    /// F̄ = (J̄/J)^⅓ F, whose volume ratio J̄ is the volume average of J over a
    /// patch: the element itself for H8 (the Q1-P0 / mean-dilatation hexahedron) and
    /// T10 (stabilised: see [`crate::fbar`]), and a group of about six face-adjacent
    /// tetrahedra for T4 (the F-bar-patch tetrahedron). The linear law uses its
    /// small-strain form, B-bar.
    Fbar,
}

impl Formulation {
    /// The formulation's name for people: "auto", "standard", "F-bar".
    pub fn display_name(self) -> &'static str {
        match self {
            Formulation::Auto => "auto",
            Formulation::Standard => "standard",
            Formulation::Fbar => "F-bar",
        }
    }
}

/// Principal stretch 1/√3 at which Saint-Venant-Kirchhoff's uniaxial compressive stress peaks:
/// compressed further, the stress falls.
pub const SVK_LIMIT_STRETCH: f64 = 0.577_350_269_189_625_8;

/// The smallest principal stretch above which a body that lost its stability under SVK may have
/// buckled rather than passed SVK's limit: a block crushed by a force reaches its limit point
/// with its most compressed element at 0.65 to 0.8, a slender column buckles at 0.84.
pub const SVK_BUCKLING_STRETCH: f64 = 0.8;

/// Poisson's ratio from which [`Formulation::Auto`] selects F-bar.
pub const FBAR_POISSON: f64 = 0.45;

/// An isotropic elastic material: law, Young's modulus (Pa), Poisson's ratio, density (kg/m³).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Material {
    /// The constitutive law.
    pub law: Law,
    /// Element formulation (default: automatic from Poisson's ratio).
    #[serde(default)]
    pub formulation: Formulation,
    /// Polynomial order of the elements: 1 (the mesh's own cells, default) or 2, quadratic
    /// tetrahedra (T10) made from a T4 mesh by [`Problem::new`](crate::Problem::new). A mesh
    /// read with quadratic cells is solved with them whatever the order.
    /// Not written when 1, so that what linear elements wrote before it existed stays the same.
    #[serde(default = "linear_order", skip_serializing_if = "is_linear_order")]
    pub order: u8,
    /// Young's modulus in Pa.
    pub young: f64,
    /// Poisson's ratio, in (−1, 0.5).
    pub poisson: f64,
    /// Mass density in kg/m³ (used by body forces).
    #[serde(default = "default_density")]
    pub density: f64,
}

fn default_density() -> f64 {
    1000.0
}

/// A stress or modulus in pascals (as [`Material::young`] is), in kilopascals, as reports give it.
pub fn kpa(pascals: f64) -> f64 {
    pascals / 1e3
}

fn linear_order() -> u8 {
    1
}

fn is_linear_order(order: &u8) -> bool {
    *order == 1
}

impl Material {
    /// A material with the default density of 1000 kg/m³.
    pub fn new(law: Law, young: f64, poisson: f64) -> Self {
        Material { law, young, poisson, formulation: Formulation::Auto, order: 1, density: default_density() }
    }

    /// The same material on elements of the given polynomial order (1 or 2).
    pub fn with_order(self, order: u8) -> Self {
        Material { order, ..self }
    }

    /// The same material with the given element formulation.
    pub fn with_formulation(self, formulation: Formulation) -> Self {
        Material { formulation, ..self }
    }

    /// The formulation in use: [`Formulation::Auto`] resolved from Poisson's ratio.
    pub fn resolved_formulation(&self) -> Formulation {
        match self.formulation {
            Formulation::Auto if self.poisson >= FBAR_POISSON => Formulation::Fbar,
            Formulation::Auto => Formulation::Standard,
            f => f,
        }
    }

    /// Checks that the parameters are physical.
    pub fn validate(&self) -> Result<(), String> {
        if !(self.young > 0.0 && self.young.is_finite()) {
            return Err(format!("Young's modulus must be positive and finite, got {}", self.young));
        }
        if !(self.poisson > -1.0 && self.poisson < 0.5) {
            return Err(format!("Poisson's ratio must lie in (-1, 0.5), got {}", self.poisson));
        }
        if !(self.density >= 0.0 && self.density.is_finite()) {
            return Err(format!("density must be non-negative and finite, got {}", self.density));
        }
        if !(1..=2).contains(&self.order) {
            return Err(format!(
                "order must be 1 (the mesh's own elements) or 2 (quadratic tetrahedra), got {}",
                self.order
            ));
        }
        Ok(())
    }

    /// Lamé constants (λ, μ) from Young's modulus and Poisson's ratio.
    pub fn lame(&self) -> (f64, f64) {
        let (e, nu) = (self.young, self.poisson);
        (e * nu / ((1.0 + nu) * (1.0 - 2.0 * nu)), e / (2.0 * (1.0 + nu)))
    }

    /// Strain energy density W(F) in J/m³.
    pub fn energy(&self, f: &Matrix3<f64>) -> f64 {
        let (lambda, mu) = self.lame();
        let id = Matrix3::identity();
        match self.law {
            Law::Linear => {
                let eps = (f + f.transpose()) * 0.5 - id;
                0.5 * lambda * eps.trace().powi(2) + mu * eps.norm_squared()
            }
            Law::Corotational => {
                let (_, s) = polar(f);
                let eps = s - id;
                0.5 * lambda * eps.trace().powi(2) + mu * eps.norm_squared()
            }
            Law::Svk => {
                let e = (f.transpose() * f - id) * 0.5;
                0.5 * lambda * e.trace().powi(2) + mu * e.norm_squared()
            }
            Law::NeoHookean => {
                let lnj = f.determinant().ln();
                0.5 * mu * (f.norm_squared() - 3.0) - mu * lnj + 0.5 * lambda * lnj * lnj
            }
        }
    }

    /// First Piola-Kirchhoff stress P(F) alone (cheaper than [`Material::stress_tangent`]).
    /// The caller guarantees det F > 0 for laws that need it.
    pub fn stress(&self, f: &Matrix3<f64>) -> Matrix3<f64> {
        let (lambda, mu) = self.lame();
        let id = Matrix3::<f64>::identity();
        match self.law {
            Law::Linear => {
                let eps = (f + f.transpose()) * 0.5 - id;
                id * (lambda * eps.trace()) + eps * (2.0 * mu)
            }
            Law::Svk => {
                let e = (f.transpose() * f - id) * 0.5;
                f * (id * (lambda * e.trace()) + e * (2.0 * mu))
            }
            Law::NeoHookean => {
                let finv_t = f.try_inverse().unwrap_or_else(Matrix3::zeros).transpose();
                (f - finv_t) * mu + finv_t * (lambda * f.determinant().ln())
            }
            Law::Corotational => corotational_stress(&rotation(f), f, lambda, mu),
        }
    }

    /// First Piola-Kirchhoff stresses at many points, `out[i]` = [`Material::stress`]`(fs[i])`
    /// bit for bit; the co-rotational law's rotations are computed several at a time
    /// ([`rotations_each`]). The caller guarantees det F > 0 for laws that need it.
    pub fn stresses(&self, fs: &[Matrix3<f64>], out: &mut [Matrix3<f64>]) {
        if self.law != Law::Corotational {
            out.iter_mut().zip(fs).for_each(|(p, f)| *p = self.stress(f));
            return;
        }
        let (lambda, mu) = self.lame();
        rotations_each(fs, |i, r| out[i] = corotational_stress(&r, &fs[i], lambda, mu));
    }

    /// First Piola-Kirchhoff stress P(F) and its tangent ∂P/∂F.
    /// The caller guarantees det F > 0 for laws that need it.
    pub fn stress_tangent(&self, f: &Matrix3<f64>) -> (Matrix3<f64>, Tangent) {
        let (lambda, mu) = self.lame();
        let id = Matrix3::<f64>::identity();
        let d = |a: usize, b: usize| if a == b { 1.0 } else { 0.0 };
        let mut t = [[0.0; 9]; 9];
        match self.law {
            Law::Linear => {
                let eps = (f + f.transpose()) * 0.5 - id;
                let p = id * (lambda * eps.trace()) + eps * (2.0 * mu);
                fill(&mut t, |i, j, k, l| lambda * d(i, j) * d(k, l) + mu * (d(i, k) * d(j, l) + d(i, l) * d(j, k)));
                (p, t)
            }
            Law::Svk => {
                let e = (f.transpose() * f - id) * 0.5;
                let s = id * (lambda * e.trace()) + e * (2.0 * mu);
                let f_ft = f * f.transpose();
                // A_iJkL = δ_ik S_JL + λ F_iJ F_kL + μ (F Fᵀ)_ik δ_JL + μ F_iL F_kJ
                fill(&mut t, |i, j, k, l| {
                    d(i, k) * s[(j, l)]
                        + lambda * f[(i, j)] * f[(k, l)]
                        + mu * f_ft[(i, k)] * d(j, l)
                        + mu * f[(i, l)] * f[(k, j)]
                });
                (f * s, t)
            }
            Law::NeoHookean => {
                let jac = f.determinant();
                let finv = f.try_inverse().unwrap_or_else(Matrix3::zeros);
                let lnj = jac.ln();
                let p = (f - finv.transpose()) * mu + finv.transpose() * (lambda * lnj);
                // A_iJkL = μ δ_ik δ_JL + (μ − λ ln J) F⁻¹_Jk F⁻¹_Li + λ F⁻¹_Ji F⁻¹_Lk
                fill(&mut t, |i, j, k, l| {
                    mu * d(i, k) * d(j, l)
                        + (mu - lambda * lnj) * finv[(j, k)] * finv[(l, i)]
                        + lambda * finv[(j, i)] * finv[(l, k)]
                });
                (p, t)
            }
            Law::Corotational => corotational(f, lambda, mu),
        }
    }
}

fn fill(t: &mut Tangent, a: impl Fn(usize, usize, usize, usize) -> f64) {
    for i in 0..3 {
        for j in 0..3 {
            for k in 0..3 {
                for l in 0..3 {
                    t[3 * i + j][3 * k + l] = a(i, j, k, l);
                }
            }
        }
    }
}

/// Polar decomposition F = R·S with R a proper rotation and S symmetric
/// positive definite, for det F > 0: Higham's scaled Newton iteration
/// X ← ½(γX + X⁻ᵀ/γ), with X⁻ᵀ from the cofactor matrix. It converges
/// quadratically, so once a step changes X by less than 10⁻⁸ (relative) the
/// new iterate is exact to rounding. Falls back to the SVD if it does not converge.
pub fn polar(f: &Matrix3<f64>) -> (Matrix3<f64>, Matrix3<f64>) {
    let r = rotation(f);
    let s = r.transpose() * f;
    (r, (s + s.transpose()) * 0.5)
}

/// The rotation R of the polar decomposition F = R·S ([`polar`]).
pub fn rotation(f: &Matrix3<f64>) -> Matrix3<f64> {
    let (x, converged) = newton_polar(std::array::from_fn(|k| Lanes([f[(k / 3, k % 3)]])));
    if !converged.0[0] {
        return polar_svd(f).0;
    }
    Matrix3::from_fn(|i, j| x[3 * i + j].0[0])
}

/// Calls `each(i, R)` with the rotation of every `fs[i]` ([`rotation`], bit for bit), four at a
/// time with vector instructions.
pub fn rotations_each(fs: &[Matrix3<f64>], mut each: impl FnMut(usize, Matrix3<f64>)) {
    for (c, chunk) in fs.chunks(4).enumerate() {
        // Padding lanes hold the identity, which converges at once.
        let x: [Lanes<4>; 9] = std::array::from_fn(|k| {
            Lanes(std::array::from_fn(|l| chunk.get(l).map_or(f64::from(k % 4 == 0), |f| f[(k / 3, k % 3)])))
        });
        let (x, converged) = newton_polar_x4(x);
        for (l, f) in chunk.iter().enumerate() {
            let r = if converged.0[l] { Matrix3::from_fn(|i, j| x[3 * i + j].0[l]) } else { polar_svd(f).0 };
            each(4 * c + l, r);
        }
    }
}

/// [`newton_polar`] on four lanes, compiled for AVX where the processor has it.
fn newton_polar_x4(x: [Lanes<4>; 9]) -> ([Lanes<4>; 9], Mask<4>) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx") {
        #[target_feature(enable = "avx")]
        fn avx(x: [Lanes<4>; 9]) -> ([Lanes<4>; 9], Mask<4>) {
            newton_polar(x)
        }
        // SAFETY: the processor has AVX (checked above).
        return unsafe { avx(x) };
    }
    newton_polar(x)
}

/// Higham's scaled Newton iteration on `N` matrices at once, one per lane of `x`
/// (entries `x[3r + c]`). A lane stops changing once it has converged, so its result does
/// not depend on the others. Returns the iterates and the lanes that converged (det X = 0
/// or a non-finite value stops a lane unconverged).
#[inline(always)]
fn newton_polar<const N: usize>(mut x: [Lanes<N>; 9]) -> ([Lanes<N>; 9], Mask<N>) {
    // Rows (columns) of the 2×2 minor of each cofactor entry.
    const PAIR: [(usize, usize); 3] = [(1, 2), (2, 0), (0, 1)];
    let splat = Lanes::<N>::splat;
    let (mut active, mut converged, mut scaled) = (Mask([true; N]), Mask([false; N]), Mask([true; N]));
    for _ in 0..30 {
        if !active.any() {
            break;
        }
        let mut cof = [splat(0.0); 9];
        for (k, c) in cof.iter_mut().enumerate() {
            let ((r0, r1), (c0, c1)) = (PAIR[k / 3], PAIR[k % 3]);
            *c = x[3 * r0 + c0] * x[3 * r1 + c1] - x[3 * r0 + c1] * x[3 * r1 + c0];
        }
        let det = x[0] * cof[0] + x[1] * cof[1] + x[2] * cof[2];
        let (mut norm2, mut cof_norm2) = (splat(0.0), splat(0.0));
        for k in 0..9 {
            norm2 = norm2 + x[k] * x[k];
            cof_norm2 = cof_norm2 + cof[k] * cof[k];
        }
        // X⁻ᵀ = cof(X) / det X, so X ← a X + b cof(X) with a = γ/2, b = 1/(2γ det X) and
        // γ = (‖X⁻¹‖ / ‖X‖)^½. Near convergence the scaling only slows the quadratic rate
        // (Higham): γ = 1.
        let gamma = scaled.select((cof_norm2 / (det * det * norm2)).sqrt().sqrt(), splat(1.0));
        let (a, b) = (splat(0.5) * gamma, splat(0.5) / (gamma * det));
        let (mut change2, mut next) = (splat(0.0), [splat(0.0); 9]);
        for k in 0..9 {
            next[k] = a * x[k] + b * cof[k];
            let d = next[k] - x[k];
            change2 = change2 + d * d;
        }
        let take = active.and(det.finite_nonzero());
        active = take.and(change2.gt(splat(1e-16) * norm2));
        converged = converged.or(take.and_not(active));
        scaled = change2.gt(splat(1e-4) * norm2);
        for (x, next) in x.iter_mut().zip(next) {
            *x = take.select(next, *x);
        }
    }
    (x, converged)
}

/// The cofactor matrix, cof(X) = det(X) X⁻ᵀ.
pub(crate) fn cofactor(x: &Matrix3<f64>) -> Matrix3<f64> {
    let c = |r0: usize, r1: usize, c0: usize, c1: usize| x[(r0, c0)] * x[(r1, c1)] - x[(r0, c1)] * x[(r1, c0)];
    Matrix3::new(
        c(1, 2, 1, 2),
        c(1, 2, 2, 0),
        c(1, 2, 0, 1),
        c(2, 0, 1, 2),
        c(2, 0, 2, 0),
        c(2, 0, 0, 1),
        c(0, 1, 1, 2),
        c(0, 1, 2, 0),
        c(0, 1, 0, 1),
    )
}

fn polar_svd(f: &Matrix3<f64>) -> (Matrix3<f64>, Matrix3<f64>) {
    let svd = f.svd(true, true);
    let (mut u, v_t) = (svd.u.expect("SVD with U"), svd.v_t.expect("SVD with Vᵀ"));
    let mut sigma = svd.singular_values;
    if (u * v_t).determinant() < 0.0 {
        // Reflection: flip the smallest singular direction.
        let k = sigma.imin();
        sigma[k] = -sigma[k];
        u.column_mut(k).neg_mut();
    }
    let s = v_t.transpose() * Matrix3::from_diagonal(&sigma) * v_t;
    (u * v_t, (s + s.transpose()) * 0.5)
}

/// Co-rotational stress P = R·(λ tr(ε) I + 2μ ε), ε = S − I, from the rotation R of the polar
/// decomposition F = R·S: since R·S = F and tr S = R : F, P = (λ (R : F − 3) − 2μ) R + 2μ F.
fn corotational_stress(r: &Matrix3<f64>, f: &Matrix3<f64>, lambda: f64, mu: f64) -> Matrix3<f64> {
    r * (lambda * (r.dot(f) - 3.0) - 2.0 * mu) + f * (2.0 * mu)
}

/// Co-rotational stress and its consistent tangent, including the variation
/// of the rotation: with Ω = Rᵀ dR = [ω]×, ω = (tr(S) I − S)⁻¹ axial(Rᵀ dF − dFᵀ R).
fn corotational(f: &Matrix3<f64>, lambda: f64, mu: f64) -> (Matrix3<f64>, Tangent) {
    let id = Matrix3::<f64>::identity();
    let (r, s) = polar(f);
    let eps = s - id;
    let sigma = id * (lambda * eps.trace()) + eps * (2.0 * mu);
    let p = corotational_stress(&r, f, lambda, mu);
    let g_inv = (id * s.trace() - s).try_inverse().unwrap_or_else(Matrix3::zeros);
    let mut t = [[0.0; 9]; 9];
    for k in 0..3 {
        for l in 0..3 {
            let mut df = Matrix3::zeros();
            df[(k, l)] = 1.0;
            let m = r.transpose() * df - df.transpose() * r;
            let omega = g_inv * nalgebra::Vector3::new(m[(2, 1)], m[(0, 2)], m[(1, 0)]);
            let big_omega = omega.cross_matrix();
            let ds = r.transpose() * df - big_omega * s;
            let dsigma = id * (lambda * ds.trace()) + ds * (2.0 * mu);
            let dp = r * big_omega * sigma + r * dsigma;
            for i in 0..3 {
                for j in 0..3 {
                    t[3 * i + j][3 * k + l] = dp[(i, j)];
                }
            }
        }
    }
    (p, t)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample_f() -> Matrix3<f64> {
        Matrix3::new(1.1, 0.05, -0.02, 0.03, 0.95, 0.04, -0.06, 0.02, 1.07)
    }

    #[test]
    fn stress_is_energy_gradient_and_tangent_is_stress_gradient() {
        let h = 1e-6;
        for law in [Law::Linear, Law::Corotational, Law::Svk, Law::NeoHookean] {
            let m = Material::new(law, 5000.0, 0.45);
            let f = sample_f();
            let (p, t) = m.stress_tangent(&f);
            assert!((m.stress(&f) - p).norm() < 1e-12 * m.young, "{law:?}: stress() and stress_tangent() differ");
            for k in 0..3 {
                for l in 0..3 {
                    let mut fp = f;
                    fp[(k, l)] += h;
                    let mut fm = f;
                    fm[(k, l)] -= h;
                    let dw = (m.energy(&fp) - m.energy(&fm)) / (2.0 * h);
                    assert!((dw - p[(k, l)]).abs() < 1e-5 * m.young, "{law:?}: dW/dF {dw} vs P {}", p[(k, l)]);
                    let (pp, _) = m.stress_tangent(&fp);
                    let (pm, _) = m.stress_tangent(&fm);
                    for i in 0..3 {
                        for j in 0..3 {
                            let fd = (pp[(i, j)] - pm[(i, j)]) / (2.0 * h);
                            let an = t[3 * i + j][3 * k + l];
                            assert!((fd - an).abs() < 1e-5 * m.young, "{law:?} A[{i}{j}{k}{l}]: {an} vs fd {fd}");
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn lame_constants() {
        let m = Material::new(Law::Svk, 300.0, 0.4);
        let (l, mu) = m.lame();
        assert!((mu - 300.0 / 2.8).abs() < 1e-12);
        assert!((l - 300.0 * 0.4 / (1.4 * 0.2)).abs() < 1e-12);
    }

    #[test]
    fn polar_decomposition_is_exact() {
        // A mild deformation, and a large rotation with a strong anisotropic stretch.
        let rotation = nalgebra::Rotation3::from_axis_angle(&nalgebra::Vector3::y_axis(), 2.3).into_inner();
        let stretch = Matrix3::new(3.0, 0.4, 0.0, 0.4, 0.5, 0.1, 0.0, 0.1, 1.2);
        for f in [sample_f(), rotation * stretch] {
            let (r2, s2) = polar_svd(&f);
            let (r, s) = polar(&f);
            assert!((r - r2).norm() < 1e-12 && (s - s2).norm() < 1e-12 * s2.norm());
            assert!((r * s - f).norm() < 1e-12 * f.norm());
            assert!((r.transpose() * r - Matrix3::identity()).norm() < 1e-12);
            assert!((r.determinant() - 1.0).abs() < 1e-12);
            assert!((s - s.transpose()).norm() < 1e-14 * s.norm());
        }
        assert!((rotation * stretch - polar(&(rotation * stretch)).0 * stretch).norm() < 1e-12);
    }

    /// The four-lane rotations equal the one-lane ones bit for bit, whatever the other
    /// lanes hold: mild and strong deformations, a rotation, a singular matrix (the SVD
    /// fallback) and a count that leaves a partial last chunk.
    #[test]
    fn vectorised_polar_and_stresses_equal_the_scalar_ones() {
        let turn = nalgebra::Rotation3::from_axis_angle(&nalgebra::Vector3::x_axis(), 1.1).into_inner();
        let mut fs: Vec<Matrix3<f64>> = (0..9)
            .map(|i| {
                let t = i as f64;
                Matrix3::new(
                    1.0 + 0.3 * t.sin(),
                    0.2 * t,
                    -0.1,
                    0.05 * t,
                    0.9,
                    0.3 * t.cos(),
                    0.1,
                    -0.2,
                    1.2 - 0.05 * t,
                )
            })
            .collect();
        fs.insert(3, turn);
        fs.insert(5, Matrix3::zeros());
        fs.push(turn * sample_f());
        let mut seen = vec![false; fs.len()];
        rotations_each(&fs, |i, r| {
            assert_eq!(r, rotation(&fs[i]), "matrix {i}");
            seen[i] = true;
        });
        assert!(seen.iter().all(|&s| s));
        // The other laws' `stresses` is `stress` point by point: only the co-rotational one has a
        // path of its own to check.
        let deformations: Vec<Matrix3<f64>> = fs.iter().filter(|f| f.determinant() > 0.0).copied().collect();
        let m = Material::new(Law::Corotational, 5000.0, 0.45);
        let mut out = vec![Matrix3::zeros(); deformations.len()];
        m.stresses(&deformations, &mut out);
        for (f, p) in deformations.iter().zip(&out) {
            assert_eq!(*p, m.stress(f));
        }
    }
}
