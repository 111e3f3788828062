//! Derived fields: strain (small under the linear law, Green-Lagrange under the others) and von
//! Mises stress per cell, from the deformation gradient each quadrature point is evaluated at (F̄
//! under F-bar).

use nalgebra::Matrix3;

use crate::element::ElementGeometry;
use crate::fbar;
use crate::material::{Formulation, Law, Material, SVK_LIMIT_STRETCH};
use crate::FemError;

/// The deformation gradient each quadrature point is evaluated at (F, or F̄
/// under F-bar), index `e * points + q`.
fn effective_gradients(geometry: &ElementGeometry, law: Law, u: &[f64]) -> Result<Vec<Matrix3<f64>>, FemError> {
    let nq = geometry.points_per_element;
    let mut out = vec![Matrix3::identity(); geometry.len() * nq];
    for p in 0..geometry.patches.len() {
        let elements = geometry.patches.elements(p);
        let gradients = match geometry.formulation {
            Formulation::Fbar => fbar::patch_gradients(geometry, p, law, u)?,
            _ => elements.iter().flat_map(|&e| (0..nq).map(move |q| geometry.deformation_gradient(e, q, u))).collect(),
        };
        for (slot, &e) in elements.iter().enumerate() {
            out[e * nq..(e + 1) * nq].copy_from_slice(&gradients[slot * nq..(slot + 1) * nq]);
        }
    }
    Ok(out)
}

/// `each` applied to every cell's effective deformation gradients.
fn per_cell<T>(
    geometry: &ElementGeometry,
    material: &Material,
    u: &[f64],
    each: impl Fn(&[Matrix3<f64>]) -> T,
) -> Result<Vec<T>, FemError> {
    let gradients = effective_gradients(geometry, material.law, u)?;
    Ok(gradients.chunks(geometry.points_per_element).map(each).collect())
}

/// The name of the strain [`strain`] gives under `law`: `small_strain` for the linear law,
/// `green_strain` for the others.
pub fn strain_name(law: Law) -> &'static str {
    if law == Law::Linear {
        "small_strain"
    } else {
        "green_strain"
    }
}

/// Mean over each cell's quadrature points of the strain the law is written in, as 6 components
/// per cell (xx, yy, zz, xy, yz, xz): the small strain ε = ½(F + Fᵀ) − I that the linear law
/// solves, the Green-Lagrange strain E = ½(FᵀF − I) under the others.
pub fn strain(geometry: &ElementGeometry, material: &Material, u: &[f64]) -> Result<Vec<f64>, FemError> {
    let linear = material.law == Law::Linear;
    let cells = per_cell(geometry, material, u, |fs| {
        let strain = |f: &Matrix3<f64>| match linear {
            true => (f + f.transpose()) * 0.5 - Matrix3::identity(),
            false => (f.transpose() * f - Matrix3::identity()) * 0.5,
        };
        let mean = fs.iter().map(strain).sum::<Matrix3<f64>>() / fs.len() as f64;
        [mean[(0, 0)], mean[(1, 1)], mean[(2, 2)], mean[(0, 1)], mean[(1, 2)], mean[(0, 2)]]
    })?;
    Ok(cells.into_iter().flatten().collect())
}

/// Mean over each cell's quadrature points of the von Mises equivalent of the Cauchy stress
/// (Pa): σ = J⁻¹ P Fᵀ, and under the linear law its own small-strain stress σ = λ tr(ε) I + 2μ ε
/// (which knows no current configuration).
pub fn von_mises(geometry: &ElementGeometry, material: &Material, u: &[f64]) -> Result<Vec<f64>, FemError> {
    per_cell(geometry, material, u, |fs| {
        fs.iter()
            .map(|f| {
                let s = match material.law {
                    Law::Linear => material.stress(f),
                    _ => material.stress(f) * f.transpose() / f.determinant(),
                };
                let dev = s - Matrix3::identity() * (s.trace() / 3.0);
                (1.5 * dev.norm_squared()).sqrt()
            })
            .sum::<f64>()
            / fs.len() as f64
    })
}

/// The cells turned inside out by `u` (a quadrature point's det F ≤ 0, F̄ under F-bar), and the
/// smallest det F of all: the linear law, which knows no finite strain, solves into them.
pub fn inverted_cells(geometry: &ElementGeometry, law: Law, u: &[f64]) -> Result<(usize, f64), FemError> {
    let gradients = effective_gradients(geometry, law, u)?;
    let cells = gradients.chunks(geometry.points_per_element).map(|fs| fs.iter().map(|f| f.determinant()));
    let smallest: Vec<f64> = cells.map(|dets| dets.fold(f64::INFINITY, f64::min)).collect();
    Ok((smallest.iter().filter(|&&j| j <= 0.0).count(), smallest.iter().copied().fold(f64::INFINITY, f64::min)))
}

/// Each cell's volume ratio J = det F (det F̄ under F-bar), the mean over its quadrature points:
/// 1 where it keeps its volume.
pub fn volume_ratios(geometry: &ElementGeometry, law: Law, u: &[f64]) -> Result<Vec<f64>, FemError> {
    let gradients = effective_gradients(geometry, law, u)?;
    let points = geometry.points_per_element;
    Ok(gradients.chunks(points).map(|fs| fs.iter().map(|f| f.determinant()).sum::<f64>() / points as f64).collect())
}

/// Each cell's least and greatest principal stretch over its quadrature points (from F̄ under
/// F-bar).
pub fn principal_stretches(geometry: &ElementGeometry, law: Law, u: &[f64]) -> Result<Vec<(f64, f64)>, FemError> {
    let gradients = effective_gradients(geometry, law, u)?;
    let stretches = |f: &Matrix3<f64>| {
        let squared = (f.transpose() * f).symmetric_eigenvalues();
        (squared.min().max(0.0).sqrt(), squared.max().max(0.0).sqrt())
    };
    Ok(gradients
        .chunks(geometry.points_per_element)
        .map(|fs| fs.iter().map(stretches).fold((f64::INFINITY, 0.0), |(a, b), (l, g)| (a.min(l), f64::max(b, g))))
        .collect())
}

/// The cells compressed past [`SVK_LIMIT_STRETCH`] by `u` (a quadrature point's least principal
/// stretch below it, from F̄ under F-bar), where Saint-Venant-Kirchhoff's stress falls as the
/// compression grows; and the most compressed cell with its stretch (`None` without cells).
pub fn over_compressed_cells(
    geometry: &ElementGeometry,
    law: Law,
    u: &[f64],
) -> Result<(usize, Option<(usize, f64)>), FemError> {
    let stretches: Vec<f64> = principal_stretches(geometry, law, u)?.into_iter().map(|(least, _)| least).collect();
    let over = stretches.iter().filter(|&&s| s < SVK_LIMIT_STRETCH).count();
    Ok((over, stretches.into_iter().enumerate().min_by(|a, b| a.1.total_cmp(&b.1))))
}

/// Largest nodal displacement magnitude (m).
pub fn max_displacement(u: &[f64]) -> f64 {
    u.chunks(3).map(|d| (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt()).fold(0.0, f64::max)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A box stretched uniformly by 10 % along x: under the linear law the strain written is the
    /// small strain (εxx = 0.1, not Green's 0.105) and the von Mises stress that of the linear
    /// stress, 2μ εxx; under SVK, Green's strain.
    #[test]
    fn the_linear_law_writes_its_own_small_strain_and_stress() {
        let mesh = mesh::box_tet([0.0; 3], [1.0, 0.5, 0.5], [2, 1, 1]).unwrap();
        let geometry = ElementGeometry::new(&mesh, Formulation::Standard).unwrap();
        let u: Vec<f64> = mesh.nodes.iter().flat_map(|p| [0.1 * p[0], 0.0, 0.0]).collect();
        let linear = Material::new(Law::Linear, 3000.0, 0.3);
        let (_, mu) = linear.lame();
        let strain_of = |material: &Material| strain(&geometry, material, &u).unwrap();
        assert!(strain_of(&linear).chunks(6).all(|e| (e[0] - 0.1).abs() < 1e-12 && e[1].abs() < 1e-12));
        for vm in von_mises(&geometry, &linear, &u).unwrap() {
            assert!((vm - 2.0 * mu * 0.1).abs() < 1e-9 * mu, "{vm} against {}", 2.0 * mu * 0.1);
        }
        let svk = Material::new(Law::Svk, 3000.0, 0.3);
        assert!(strain_of(&svk).chunks(6).all(|e| (e[0] - 0.105).abs() < 1e-12));
        assert_eq!((strain_name(Law::Linear), strain_name(Law::Svk)), ("small_strain", "green_strain"));
    }

    /// A bar of two cubes along x, the first compressed to a stretch of 0.5 along x, the second to
    /// 0.9: the first cube's six tetrahedra are past SVK's limit stretch 1/√3, the least stretch 0.5.
    #[test]
    fn cells_past_svk_s_limit_stretch_are_counted() {
        let mesh = mesh::box_tet([0.0; 3], [1.0, 0.5, 0.5], [2, 1, 1]).unwrap();
        let geometry = ElementGeometry::new(&mesh, Formulation::Standard).unwrap();
        let ux = |x: f64| if x <= 0.5 { -0.5 * x } else { -0.25 - 0.1 * (x - 0.5) };
        let u: Vec<f64> = mesh.nodes.iter().flat_map(|p| [ux(p[0]), 0.0, 0.0]).collect();
        let (over, least) = over_compressed_cells(&geometry, Law::Svk, &u).unwrap();
        let (cell, stretch) = least.unwrap();
        assert_eq!(over, 6);
        let first_cube = mesh.cells.cell(cell).iter().all(|&n| mesh.nodes[n][0] <= 0.5);
        assert!((stretch - 0.5).abs() < 1e-12 && first_cube, "{cell}: {stretch}");
        let stretches = principal_stretches(&geometry, Law::Svk, &u).unwrap();
        let compressed = |(least, most): (f64, f64)| {
            ((least - 0.5).abs() < 1e-12 || (least - 0.9).abs() < 1e-12) && (most - 1.0).abs() < 1e-12
        };
        assert!(stretches.iter().all(|&s| compressed(s)), "{stretches:?}");
    }
}
