//! Structured box meshes.

use std::collections::HashMap;

use crate::{norm, CellKind, Cells, Mesh, MeshError, Point, TriSurface, HEX_TO_TETS, MAX_CELLS};

/// Node index of grid point (i, j, k) in an (nx+1)×(ny+1)×(nz+1) lattice, x fastest.
fn lattice_index(n: [usize; 3], i: usize, j: usize, k: usize) -> usize {
    i + (n[0] + 1) * (j + (n[1] + 1) * k)
}

/// The lattice of a box `[lo, hi]` cut into `n` boxes, each to be meshed with `per_box` cells;
/// an error for an empty box or more than [`MAX_CELLS`] cells.
fn lattice(lo: Point, hi: Point, n: [usize; 3], per_box: usize) -> Result<Vec<Point>, MeshError> {
    if n.contains(&0) || (0..3).any(|d| !(hi[d] > lo[d])) {
        return Err(MeshError::Invalid(format!("box {lo:?}..{hi:?} with {n:?} cells is empty")));
    }
    let cells = n.iter().fold(per_box as u128, |c, &k| c * k as u128);
    if cells > MAX_CELLS as u128 {
        return Err(MeshError::Invalid(format!(
            "box with {n:?} divisions makes {cells} cells, more than {MAX_CELLS} (the memory of a workstation)"
        )));
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

/// A box `[lo, hi]` meshed with `n[0]×n[1]×n[2]` trilinear hexahedra.
pub fn box_hex(lo: Point, hi: Point, n: [usize; 3]) -> Result<Mesh, MeshError> {
    Mesh::new(lattice(lo, hi, n, 1)?, Cells::Hex8(hex_cells(n)))
}

/// A box `[lo, hi]` with `n[0]×n[1]×n[2]` hexahedra each split into 6 tetrahedra
/// (a conforming split along each cube's main diagonal).
pub fn box_tet(lo: Point, hi: Point, n: [usize; 3]) -> Result<Mesh, MeshError> {
    let nodes = lattice(lo, hi, n, HEX_TO_TETS.len())?;
    let tets = hex_cells(n).iter().flat_map(|h| HEX_TO_TETS.map(|t| t.map(|k| h[k]))).collect();
    Mesh::new(nodes, Cells::Tet4(tets))
}

/// A box `[lo, hi]` with `n[0]×n[1]×n[2]` cells of the given kind: hexahedra ([`box_hex`]), or
/// hexahedra split into 6 tetrahedra ([`box_tet`]), linear or quadratic ([`Mesh::quadratic`]).
pub fn box_mesh(kind: CellKind, lo: Point, hi: Point, n: [usize; 3]) -> Result<Mesh, MeshError> {
    match kind {
        CellKind::Hex8 => box_hex(lo, hi, n),
        CellKind::Tet4 => box_tet(lo, hi, n),
        CellKind::Tet10 => box_tet(lo, hi, n)?.quadratic(),
    }
}

/// A sphere's surface of radius `r` about the origin: the icosahedron subdivided `level` times
/// (20 * 4^level triangles, outward), its vertices on the sphere.
pub fn icosphere(r: f64, level: usize) -> TriSurface {
    let t = (1.0 + 5f64.sqrt()) / 2.0;
    let mut v: Vec<Point> = vec![
        [-1.0, t, 0.0],
        [1.0, t, 0.0],
        [-1.0, -t, 0.0],
        [1.0, -t, 0.0],
        [0.0, -1.0, t],
        [0.0, 1.0, t],
        [0.0, -1.0, -t],
        [0.0, 1.0, -t],
        [t, 0.0, -1.0],
        [t, 0.0, 1.0],
        [-t, 0.0, -1.0],
        [-t, 0.0, 1.0],
    ];
    let mut f: Vec<[usize; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    for _ in 0..level {
        let mut mid: HashMap<(usize, usize), usize> = HashMap::new();
        let mut next = Vec::with_capacity(4 * f.len());
        for tri in &f {
            let m: [usize; 3] = std::array::from_fn(|e| {
                let (a, b) = (tri[e], tri[(e + 1) % 3]);
                *mid.entry((a.min(b), a.max(b))).or_insert_with(|| {
                    v.push(std::array::from_fn(|d| 0.5 * (v[a][d] + v[b][d])));
                    v.len() - 1
                })
            });
            next.push([tri[0], m[0], m[2]]);
            next.push([tri[1], m[1], m[0]]);
            next.push([tri[2], m[2], m[1]]);
            next.push([m[0], m[1], m[2]]);
        }
        f = next;
    }
    let vertices = v.iter().map(|p| p.map(|c| c * r / norm(*p))).collect();
    TriSurface { vertices, triangles: f }
}
