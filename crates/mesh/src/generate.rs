//! Structured box meshes.

use crate::{CellKind, Cells, Mesh, MeshError, Point, HEX_TO_TETS};

/// Node index of grid point (i, j, k) in an (nx+1)×(ny+1)×(nz+1) lattice, x fastest.
fn lattice_index(n: [usize; 3], i: usize, j: usize, k: usize) -> usize {
    i + (n[0] + 1) * (j + (n[1] + 1) * k)
}

fn lattice(lo: Point, hi: Point, n: [usize; 3]) -> Result<Vec<Point>, MeshError> {
    if n.contains(&0) || (0..3).any(|d| !(hi[d] > lo[d])) {
        return Err(MeshError::Invalid(format!("box {lo:?}..{hi:?} with {n:?} cells is empty")));
    }
    let mut nodes = Vec::with_capacity((n[0] + 1) * (n[1] + 1) * (n[2] + 1));
    for k in 0..=n[2] {
        for j in 0..=n[1] {
            for i in 0..=n[0] {
                let t = [i as f64 / n[0] as f64, j as f64 / n[1] as f64, k as f64 / n[2] as f64];
                nodes.push(std::array::from_fn(|d| lo[d] + t[d] * (hi[d] - lo[d])));
            }
        }
    }
    Ok(nodes)
}

fn hex_cells(n: [usize; 3]) -> Vec<[usize; 8]> {
    let mut cells = Vec::with_capacity(n[0] * n[1] * n[2]);
    for k in 0..n[2] {
        for j in 0..n[1] {
            for i in 0..n[0] {
                let v = |a, b, c| lattice_index(n, i + a, j + b, k + c);
                cells.push([
                    v(0, 0, 0),
                    v(1, 0, 0),
                    v(1, 1, 0),
                    v(0, 1, 0),
                    v(0, 0, 1),
                    v(1, 0, 1),
                    v(1, 1, 1),
                    v(0, 1, 1),
                ]);
            }
        }
    }
    cells
}

/// A box [lo, hi] meshed with n[0]×n[1]×n[2] trilinear hexahedra.
pub fn box_hex(lo: Point, hi: Point, n: [usize; 3]) -> Result<Mesh, MeshError> {
    Mesh::new(lattice(lo, hi, n)?, Cells::Hex8(hex_cells(n)))
}

/// A box [lo, hi] with n[0]×n[1]×n[2] hexahedra each split into 6 tetrahedra
/// (a conforming split along each cube's main diagonal).
pub fn box_tet(lo: Point, hi: Point, n: [usize; 3]) -> Result<Mesh, MeshError> {
    let tets = hex_cells(n).iter().flat_map(|h| HEX_TO_TETS.map(|t| t.map(|k| h[k]))).collect();
    Mesh::new(lattice(lo, hi, n)?, Cells::Tet4(tets))
}

/// A box [lo, hi] with n[0]×n[1]×n[2] cells of the given kind: hexahedra ([`box_hex`]), or
/// hexahedra split into 6 tetrahedra ([`box_tet`]), linear or quadratic ([`Mesh::quadratic`]).
pub fn box_mesh(kind: CellKind, lo: Point, hi: Point, n: [usize; 3]) -> Result<Mesh, MeshError> {
    match kind {
        CellKind::Hex8 => box_hex(lo, hi, n),
        CellKind::Tet4 => box_tet(lo, hi, n),
        CellKind::Tet10 => box_tet(lo, hi, n)?.quadratic(),
    }
}
