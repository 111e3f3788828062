//! Pictures of a registered frame: a side view (PNG: the organ seen from the side, x horizontal,
//! z up) and a 3D page (HTML, plot's viewer), each with the organ at rest and registered, the
//! cloud, and the targets registered and true.

use std::path::Path;

use mesh::length::mm;
use mesh::Point;
use plot::viewer::{write_html, Layer, PointLayer, Scalar, Scene};
use plot::{scatter_plot, PlotSpec, PointSet};

use anyhow::Result;
use register::{Organ, RigidResult};

/// A registered frame as its pictures show it, in the organ's frame (m): a rigid alignment's
/// pose is undone on the cloud, the targets and the truth.
pub struct RegisteredFrame<'a> {
    /// The organ.
    pub organ: &'a Organ,
    /// Its surface's vertices registered.
    pub registered: Vec<Point>,
    /// The cloud registered to.
    pub cloud: Vec<Point>,
    /// The targets at rest.
    pub rest_targets: &'a [Point],
    /// The targets registered.
    pub targets: Vec<Point>,
    /// The targets' true positions, when known.
    pub truth: Option<Vec<Point>>,
}

impl<'a> RegisteredFrame<'a> {
    /// The frame of `organ` registered with displacement `u` to `cloud` (registered `targets`
    /// and `truth` in the cloud's frame, moved back by `rigid` when the registration aligned it).
    pub fn new(
        organ: &'a Organ,
        u: &'a [f64],
        rigid: Option<&RigidResult>,
        cloud: &[Point],
        (rest_targets, targets): (&'a [Point], &[Point]),
        truth: Option<&[Point]>,
    ) -> RegisteredFrame<'a> {
        let back = |points: &[Point]| -> Vec<Point> {
            match rigid {
                Some(r) => points.iter().map(|&p| r.cloud_to_organ.apply(p)).collect(),
                None => points.to_vec(),
            }
        };
        RegisteredFrame {
            organ,
            registered: organ.deformed_surface(u).vertices,
            cloud: back(cloud),
            rest_targets,
            targets: back(targets),
            truth: truth.map(back),
        }
    }

    /// Writes `stem`.png (the side view) and `stem`.html (the 3D page, `notes` under its title).
    pub fn write(&self, stem: &Path, title: &str, notes: Vec<String>) -> Result<()> {
        self.side_view(&stem.with_extension("png"), &format!("{title} (side view)"))?;
        Ok(write_html(&stem.with_extension("html"), &self.scene(title, notes))?)
    }

    /// Draws the side view into the PNG file `path`: rest surface (grey), registered surface
    /// (blue), cloud (orange), registered targets (red) linked to their true positions (green)
    /// when known.
    fn side_view(&self, path: &Path, title: &str) -> Result<()> {
        let xz = |p: &Point| (p[0], p[2]);
        let rest = self.organ.surface().vertices.iter().map(xz).collect();
        let registered = self.registered.iter().map(xz).collect();
        let mut sets = vec![
            PointSet { name: "surface at rest".into(), points: rest, radius: 1, color: 7 },
            PointSet { name: "registered surface".into(), points: registered, radius: 1, color: 0 },
            PointSet {
                name: "intraoperative cloud".into(),
                points: self.cloud.iter().map(xz).collect(),
                radius: 1,
                color: 3,
            },
        ];
        let mut links = Vec::new();
        if let Some(truth) = &self.truth {
            sets.push(PointSet {
                name: "targets, true".into(),
                points: truth.iter().map(xz).collect(),
                radius: 5,
                color: 2,
            });
            links = self.targets.iter().zip(truth).map(|(a, b)| (xz(a), xz(b))).collect();
        }
        sets.push(PointSet {
            name: "targets, registered".into(),
            points: self.targets.iter().map(xz).collect(),
            radius: 4,
            color: 1,
        });
        let spec = PlotSpec { title: title.into(), x_label: "x (m)".into(), y_label: "z (m)".into(), log_y: false };
        Ok(scatter_plot(path, &spec, &sets, &links)?)
    }

    /// The 3D page's scene: the organ's surface at rest and registered, coloured by its
    /// displacement (mm), with the cloud and the targets at rest, registered and true.
    pub fn scene(&self, title: &str, notes: Vec<String>) -> Scene {
        let surface = self.organ.surface();
        let moved = mesh::distances(&surface.vertices, &self.registered).iter().map(|&d| mm(d)).collect();
        let mut points = vec![
            PointLayer { name: "intraoperative cloud".into(), positions: self.cloud.clone(), colour: [31, 119, 180] },
            PointLayer {
                name: "targets at rest".into(),
                positions: self.rest_targets.to_vec(),
                colour: [150, 150, 150],
            },
            PointLayer { name: "targets, registered".into(), positions: self.targets.clone(), colour: [214, 39, 40] },
        ];
        if let Some(truth) = &self.truth {
            points.push(PointLayer { name: "targets, true".into(), positions: truth.clone(), colour: [44, 160, 44] });
        }
        Scene {
            title: title.into(),
            notes,
            triangles: surface.triangles.iter().map(|t| t.map(|i| i as u32)).collect(),
            rest: surface.vertices.clone(),
            layers: vec![Layer { name: "registered".into(), positions: self.registered.clone() }],
            colour: Some(Scalar { name: "displacement".into(), unit: "mm".into(), values: moved }),
            points,
        }
    }
}

/// The lines under a registered frame's 3D page: `headline` (its figures), the σ predicted at its
/// targets (m), when known, and its warnings.
pub fn frame_notes(headline: String, target_std: Option<&[f64]>, warnings: &[String]) -> Vec<String> {
    let mut notes = vec![headline];
    if let Some(std) = target_std {
        let (mean, max) = (mm(mesh::stats::mean(std)), mm(mesh::stats::max(std)));
        notes.push(format!("σ predicted at the targets: mean {mean:.2} mm, max {max:.2} mm"));
    }
    notes.extend(warnings.iter().map(|w| format!("warning: {w}")));
    notes
}

#[cfg(test)]
mod tests {
    use super::*;
    use register::RigidTransform;
    use std::time::Duration;

    #[test]
    fn the_pictures_show_the_frame_in_the_organ_s_frame() {
        let organ = Organ::new(mesh::box_tet([0.0; 3], [0.1, 0.1, 0.1], [2, 2, 2]).unwrap(), None).unwrap();
        // Every node moved 3 mm down, 4 mm along x: 5 mm.
        let u: Vec<f64> = (0..organ.mesh().num_nodes()).flat_map(|_| [0.004, 0.0, -0.003]).collect();
        let shift = RigidTransform::from_axis_angle([0.0, 0.0, 1.0], 0.0, [-0.5, 0.0, 0.0]).unwrap();
        let rigid = RigidResult {
            cloud_to_organ: shift,
            iterations: 1,
            converged: true,
            rms: 0.0,
            kept: 1,
            points: 1,
            time: Duration::ZERO,
        };
        let rest = [[0.05, 0.05, 0.05]];
        let in_cloud = |p: Point| [p[0] + 0.5, p[1], p[2]];
        let (cloud, targets) = ([in_cloud([0.05, 0.05, 0.097])], [in_cloud([0.054, 0.05, 0.047])]);
        let truth = [in_cloud([0.055, 0.05, 0.046])];
        let frame = RegisteredFrame::new(&organ, &u, Some(&rigid), &cloud, (&rest, &targets), Some(&truth));
        let scene = frame.scene("t", vec!["n".into()]);
        scene.validate().unwrap();
        assert_eq!(scene.layers.len(), 1);
        assert_eq!(scene.rest.len(), organ.surface().vertices.len());
        let colour = scene.colour.as_ref().unwrap();
        assert!(colour.values.iter().all(|&v| (v - 5.0).abs() < 1e-9), "{:?}", colour.values);
        let moved = scene.layers[0].positions[0];
        let at_rest = scene.rest[0];
        assert!((moved[0] - at_rest[0] - 0.004).abs() < 1e-12 && (moved[2] - at_rest[2] + 0.003).abs() < 1e-12);
        let names: Vec<&str> = scene.points.iter().map(|p| p.name.as_str()).collect();
        assert_eq!(names, ["intraoperative cloud", "targets at rest", "targets, registered", "targets, true"]);
        // The cloud's pose undone: back over the organ.
        let close = |a: Point, b: Point| mesh::distance(a, b) < 1e-12;
        assert!(close(scene.points[0].positions[0], [0.05, 0.05, 0.097]));
        assert!(close(scene.points[2].positions[0], [0.054, 0.05, 0.047]));
        assert!(close(scene.points[3].positions[0], [0.055, 0.05, 0.046]));
        // Without the truth, no layer of it; both files written.
        let frame = RegisteredFrame::new(&organ, &u, None, &cloud, (&rest, &targets), None);
        assert_eq!(frame.scene("t", Vec::new()).points.len(), 3);
        let dir = tempfile::tempdir().unwrap();
        frame.write(&dir.path().join("registration"), "t", Vec::new()).unwrap();
        for f in ["registration.png", "registration.html"] {
            assert!(std::fs::metadata(dir.path().join(f)).unwrap().len() > 1000, "{f}");
        }
    }
}
