//! A picture of a registration: the organ seen from the side (x horizontal, z up), at rest and
//! registered, the cloud, and the targets registered and true.

use std::path::Path;

use mesh::Point;
use plot::{scatter_plot, PlotSpec, PointSet};

use anyhow::Result;
use register::Organ;

/// Draws the side view of `organ` registered with displacement `u` to `cloud` into the PNG file
/// `path`: rest surface (grey), registered surface (blue), cloud (orange), registered targets
/// (red) linked to their true positions (green) when `truth` is given.
pub fn side_view(
    path: &Path,
    title: &str,
    organ: &Organ,
    u: &[f64],
    cloud: &[Point],
    targets: &[Point],
    truth: Option<&[Point]>,
) -> Result<()> {
    let xz = |p: &Point| (p[0], p[2]);
    let rest = organ.surface().vertices.iter().map(xz).collect();
    let registered = organ.deformed_surface(u).vertices.iter().map(xz).collect();
    let mut sets = vec![
        PointSet { name: "surface at rest".into(), points: rest, radius: 1, color: 7 },
        PointSet { name: "registered surface".into(), points: registered, radius: 1, color: 0 },
        PointSet { name: "intraoperative cloud".into(), points: cloud.iter().map(xz).collect(), radius: 1, color: 3 },
    ];
    let mut links = Vec::new();
    if let Some(truth) = truth {
        sets.push(PointSet {
            name: "targets, true".into(),
            points: truth.iter().map(xz).collect(),
            radius: 5,
            color: 2,
        });
        links = targets.iter().zip(truth).map(|(a, b)| (xz(a), xz(b))).collect();
    }
    sets.push(PointSet {
        name: "targets, registered".into(),
        points: targets.iter().map(xz).collect(),
        radius: 4,
        color: 1,
    });
    let spec = PlotSpec { title: title.into(), x_label: "x (m)".into(), y_label: "z (m)".into(), log_y: false };
    Ok(scatter_plot(path, &spec, &sets, &links)?)
}
