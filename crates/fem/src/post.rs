//! Derived fields: Green-Lagrange strain and von Mises stress per cell.

use nalgebra::Matrix3;

use crate::element::ElementGeometry;
use crate::material::Material;

/// Mean over each cell's quadrature points of the Green-Lagrange strain
/// E = ½(FᵀF − I), as 6 components per cell (xx, yy, zz, xy, yz, xz).
pub fn green_strain(geometry: &ElementGeometry, u: &[f64]) -> Vec<f64> {
    let mut out = Vec::with_capacity(6 * geometry.len());
    for e in 0..geometry.len() {
        let mut mean = Matrix3::zeros();
        for q in 0..geometry.points_per_element {
            let f = geometry.deformation_gradient(e, q, u);
            mean += (f.transpose() * f - Matrix3::identity()) * 0.5;
        }
        mean /= geometry.points_per_element as f64;
        out.extend_from_slice(&[mean[(0, 0)], mean[(1, 1)], mean[(2, 2)], mean[(0, 1)], mean[(1, 2)], mean[(0, 2)]]);
    }
    out
}

/// Mean over each cell's quadrature points of the von Mises equivalent of the
/// Cauchy stress σ = J⁻¹ P Fᵀ (Pa).
pub fn von_mises(geometry: &ElementGeometry, material: &Material, u: &[f64]) -> Vec<f64> {
    (0..geometry.len())
        .map(|e| {
            let n = geometry.points_per_element;
            (0..n)
                .map(|q| {
                    let f = geometry.deformation_gradient(e, q, u);
                    let p = material.stress(&f);
                    let s = p * f.transpose() / f.determinant();
                    let dev = s - Matrix3::identity() * (s.trace() / 3.0);
                    (1.5 * dev.norm_squared()).sqrt()
                })
                .sum::<f64>()
                / n as f64
        })
        .collect()
}

/// Largest nodal displacement magnitude (m).
pub fn max_displacement(u: &[f64]) -> f64 {
    u.chunks(3).map(|d| (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt()).fold(0.0, f64::max)
}
