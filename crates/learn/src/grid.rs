//! The regular grid and the one tensor layout used everywhere.

use serde::{Deserialize, Serialize};

/// Number of channels of input and target fields (x, y, z components).
pub const CHANNELS: usize = 3;

/// The grid tensor layout, as written into manifests and model files.
pub const LAYOUT: &str = "[channel, x, y, z], C order, z fastest: index = ((c*nx + i)*ny + j)*nz + k; \
                          shards prepend the sample axis; masks are [x, y, z]";

/// Number of nodes of a regular grid along x, y and z (serialized as `[nx, ny, nz]`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(from = "[usize; 3]", into = "[usize; 3]")]
pub struct GridShape {
    /// Nodes along x.
    pub nx: usize,
    /// Nodes along y.
    pub ny: usize,
    /// Nodes along z.
    pub nz: usize,
}

impl From<[usize; 3]> for GridShape {
    fn from([nx, ny, nz]: [usize; 3]) -> Self {
        GridShape { nx, ny, nz }
    }
}

impl From<GridShape> for [usize; 3] {
    fn from(g: GridShape) -> Self {
        [g.nx, g.ny, g.nz]
    }
}

impl std::fmt::Display for GridShape {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}x{}x{}", self.nx, self.ny, self.nz)
    }
}

impl GridShape {
    /// A grid of `nx × ny × nz` nodes.
    pub fn new(nx: usize, ny: usize, nz: usize) -> Self {
        GridShape { nx, ny, nz }
    }

    /// `[nx, ny, nz]`.
    pub fn dims(&self) -> [usize; 3] {
        [self.nx, self.ny, self.nz]
    }

    /// Number of grid nodes.
    pub fn nodes(&self) -> usize {
        self.nx * self.ny * self.nz
    }

    /// Number of values of a 3-channel field on the grid.
    pub fn field_len(&self) -> usize {
        CHANNELS * self.nodes()
    }

    /// Linear index of node `(i, j, k)` in a mask (`[x, y, z]`, z fastest).
    pub fn node_index(&self, i: usize, j: usize, k: usize) -> usize {
        (i * self.ny + j) * self.nz + k
    }

    /// Linear index of channel `c` at node `(i, j, k)` in a field (`[channel, x, y, z]`).
    pub fn field_index(&self, c: usize, i: usize, j: usize, k: usize) -> usize {
        ((c * self.nx + i) * self.ny + j) * self.nz + k
    }

    /// Grid coordinates `(i, j, k)` of a node index.
    pub fn node_coords(&self, node: usize) -> [usize; 3] {
        let k = node % self.nz;
        let j = (node / self.nz) % self.ny;
        let i = node / (self.nz * self.ny);
        [i, j, k]
    }
}
