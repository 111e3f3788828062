//! The volumetric route for surfaces that local repair cannot mend.
//!
//! Exports of segmentation tools are often broken in ways that [`repair_surface`] refuses, since
//! no local change mends them uniquely: non-manifold vertices and edges, self-intersections,
//! inconsistent orientation, large holes, stray pieces. [`repair_or_rebuild`] tries local repair
//! first; when it fails, the surface is rebuilt through voxels ([`rebuild_surface`]):
//!
//! 1. voxelised by ray-parity voting along the three axes ([`voxelise_surface`]): holes and
//!    doubled parts are outvoted, and orientation plays no part;
//! 2. its largest piece kept (refused when another is of similar size: not one organ) and its
//!    cavities filled;
//! 3. extracted as a closed surface ([`mask_surface`]: marching tetrahedra, Taubin smoothing,
//!    quadric decimation).
//!
//! Voxels are 1/150 of the largest extent by default (1.3 mm for a 20 cm liver), so the grid
//! never exceeds about 150³ voxels. The report gives the route and, for the volumetric one, the
//! mean and largest distance from the result's vertices to the input surface.

use rayon::prelude::*;

use crate::bvh::SurfaceBvh;
use crate::isosurface::{mask_surface, ExtractOptions, ExtractReport, MAX_THIN_SHARE};
use crate::length::number;
use crate::length::LengthUnit;
use crate::repair::{largest_extent, repair_surface, RepairOptions, RepairReport};
use crate::volume::voxelise_surface;
use crate::{bounds, MeshError, Point, TriSurface};

/// Options of the volumetric route.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RebuildOptions {
    /// Voxels along the largest extent (default 150).
    pub voxels_across: usize,
    /// The extraction's smoothing and decimation, and the largest second piece it accepts.
    pub extract: ExtractOptions,
}

impl Default for RebuildOptions {
    fn default() -> Self {
        RebuildOptions { voxels_across: 150, extract: ExtractOptions::default() }
    }
}

/// What the volumetric route did.
#[derive(Clone, Debug, PartialEq)]
pub struct RebuildReport {
    /// Why local repair could not mend the surface.
    pub reason: String,
    /// The voxel size (the surface's unit).
    pub voxel: f64,
    /// What the extraction did (pieces dropped, cavities filled, volumes).
    pub extract: ExtractReport,
    /// Mean distance from the result's vertices to the input surface (the surface's unit).
    pub mean_distance: f64,
    /// Largest distance from the result's vertices to the input surface (the surface's unit).
    pub max_distance: f64,
    /// The input's edges that border a single triangle, and its edges in all.
    pub open_edges: (usize, usize),
}

/// The route a surface took to become closed and manifold.
#[derive(Clone, Debug, PartialEq)]
pub enum Route {
    /// Local repair mended it (or it needed none).
    Local(RepairReport),
    /// Local repair could not; it was rebuilt through voxels.
    Volumetric(RebuildReport),
}

impl Route {
    /// What was done, one line each; lengths are given in mm when the `unit` of the surface's
    /// coordinates is known, otherwise in that unit.
    pub fn lines(&self, unit: Option<LengthUnit>) -> Vec<String> {
        match self {
            Route::Local(report) => {
                let mut lines = vec!["route: local repair".to_string()];
                let changes = report.lines();
                if changes.is_empty() {
                    lines.push("nothing to repair (a closed, oriented, manifold surface)".into());
                }
                lines.extend(changes);
                lines
            }
            Route::Volumetric(r) => {
                let mm = |x: f64| match unit {
                    Some(unit) => format!("{:.2} mm", crate::length::mm(unit.to_metres(x))),
                    None => format!("{} (the surface's unit)", number(x)),
                };
                let e = &r.extract;
                let mut lines = vec![
                    format!("route: volumetric (local repair cannot mend it: {})", r.reason),
                    format!(
                        "voxelised at {} ({} voxels inside), {} triangles extracted, decimated to {}",
                        mm(r.voxel),
                        e.voxels,
                        e.extracted_triangles,
                        e.triangles
                    ),
                ];
                lines.extend(e.cleaning_lines());
                lines.push(format!("enclosed volume: {}", e.volume_text(unit)));
                lines.push(format!(
                    "distance to the input surface: mean {}, largest {}",
                    mm(r.mean_distance),
                    mm(r.max_distance)
                ));
                lines
            }
        }
    }

    /// Problems left in place: tolerated self-intersections of a local repair; an input open over
    /// more than 1 % of its edges, which the voxels closed (a part may be missing).
    pub fn warnings(&self) -> Vec<String> {
        match self {
            Route::Local(report) => report.warnings(),
            Route::Volumetric(r) => {
                let (open, edges) = r.open_edges;
                if !(open as f64 > LARGE_OPENING * edges as f64) {
                    return Vec::new();
                }
                vec![format!(
                    "the input surface is open along {open} of its {edges} edges (holes larger than local repair \
                     fills): the voxels closed it, flat where a part may be missing (cut off?); check the organ"
                )]
            }
        }
    }
}

/// The share of an input's edges open (bordering a single triangle) over which a rebuilt surface
/// is warned about: an export's small holes stay under it.
const LARGE_OPENING: f64 = 0.01;

/// The edges of `surface` that border a single triangle, and its edges in all.
fn open_edges(surface: &TriSurface) -> (usize, usize) {
    let mut uses = std::collections::HashMap::<(usize, usize), usize>::new();
    for t in &surface.triangles {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            *uses.entry((a.min(b), a.max(b))).or_default() += 1;
        }
    }
    (uses.values().filter(|&&n| n == 1).count(), uses.len())
}

/// A closed, outward oriented 2-manifold from a surface as a segmentation tool exported it: by
/// local repair ([`repair_surface`]) when it can mend it, otherwise through voxels
/// ([`rebuild_surface`]). Refused: no triangles, out-of-range indices, non-finite coordinates,
/// and what is not one organ (see [`rebuild_surface`]).
pub fn repair_or_rebuild(
    surface: &TriSurface,
    repair: &RepairOptions,
    rebuild: &RebuildOptions,
) -> Result<(TriSurface, Route), MeshError> {
    crate::repair::check_input(surface, repair)?;
    refuse_flat(surface)?;
    match repair_surface(surface, repair) {
        Ok((repaired, report)) => Ok((repaired, Route::Local(report))),
        Err(e) => {
            let reason = match e {
                MeshError::Invalid(m) => m,
                other => other.to_string(),
            };
            // Both reasons: the local one is often the cause (a hole too large to close), the
            // voxels' failure what followed from it.
            let (rebuilt, report) = rebuild_surface(surface, reason.clone(), rebuild).map_err(|e| {
                let (open, edges) = open_edges(surface);
                let open = match open {
                    0 => String::new(),
                    n => format!(
                        "; {n} of its {edges} edges border a single triangle: the surface is open, more than the \
                         holes local repair fills (a part missing, cut off?)"
                    ),
                };
                MeshError::Invalid(format!(
                    "local repair cannot mend it ({reason}), and rebuilt through voxels: {}{open}",
                    e.message()
                ))
            })?;
            Ok((rebuilt, Route::Volumetric(report)))
        }
    }
}

/// Refuses a surface without triangles or flat (its smallest extent under 1/1000 of its
/// largest: it encloses no organ); returns its largest extent.
fn refuse_flat(surface: &TriSurface) -> Result<f64, MeshError> {
    let used: Vec<Point> =
        surface.triangles.iter().flatten().filter_map(|&k| surface.vertices.get(k).copied()).collect();
    if used.is_empty() {
        return Err(MeshError::Invalid("surface has no triangles: nothing to mesh".into()));
    }
    let largest = largest_extent(surface);
    let (lo, hi) = bounds(&used);
    let smallest = (0..3).map(|d| hi[d] - lo[d]).fold(f64::INFINITY, f64::min);
    if !(largest > 0.0) || smallest < 1e-3 * largest {
        return Err(MeshError::Invalid(format!(
            "the surface is flat (extent {} by {}): not an organ",
            number(largest),
            number(smallest)
        )));
    }
    Ok(largest)
}

/// The surface rebuilt through voxels (see the module's documentation); `reason` says why.
/// Refused with a clear error: an empty or flat surface, one that encloses no volume or one
/// mostly thinner than a voxel, several pieces of similar size.
pub fn rebuild_surface(
    surface: &TriSurface,
    reason: String,
    options: &RebuildOptions,
) -> Result<(TriSurface, RebuildReport), MeshError> {
    let largest = refuse_flat(surface)?;
    let voxel = largest / options.voxels_across.max(10) as f64;
    let mask = voxelise_surface(surface, voxel)?;
    if !mask.inside.contains(&true) {
        return Err(MeshError::Invalid(format!(
            "the surface encloses no volume at voxels of {} (its unit) (flat or open on every side): not an organ",
            number(voxel)
        )));
    }
    // A sheet: the extraction's refusal of it would speak of an image's slices.
    let thin = mask.thin_share();
    if thin > MAX_THIN_SHARE {
        return Err(MeshError::Invalid(format!(
            "the surface is thinner than the voxels it is rebuilt through ({}) over {:.0} % of what it encloses: \
             a sheet or a shell, not an organ's closed surface",
            number(voxel),
            100.0 * thin
        )));
    }
    // Refused there when it holds several pieces of similar size.
    let (rebuilt, extract) = mask_surface(&mask, &options.extract).map_err(|e| {
        MeshError::Invalid(format!("the surface, voxelised at {} (its unit): {}", number(voxel), e.message()))
    })?;
    let bvh = SurfaceBvh::new(surface)?;
    let distances: Vec<f64> = rebuilt.vertices.par_iter().map(|&p| bvh.distance(p)).collect();
    let mean_distance = distances.iter().sum::<f64>() / distances.len() as f64;
    let max_distance = distances.iter().copied().fold(0.0, f64::max);
    let open_edges = open_edges(surface);
    Ok((rebuilt, RebuildReport { reason, voxel, extract, mean_distance, max_distance, open_edges }))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::generate::icosphere;
    use crate::surface::check_closed_manifold;
    use std::f64::consts::PI;

    fn moved(mut s: TriSurface, by: Point) -> TriSurface {
        s.vertices.iter_mut().for_each(|p| (0..3).for_each(|d| p[d] += by[d]));
        s
    }

    fn joined(parts: &[TriSurface]) -> TriSurface {
        let mut out = TriSurface::default();
        for s in parts {
            let base = out.vertices.len();
            out.vertices.extend(&s.vertices);
            out.triangles.extend(s.triangles.iter().map(|t| t.map(|k| k + base)));
        }
        out
    }

    #[test]
    fn a_broken_export_goes_through_the_volumetric_route() {
        // Two overlapping spheres (they cross each other), a small one glued to the first at a
        // vertex (non-manifold once the vertices are merged), three holes.
        let a = icosphere(30.0, 4);
        let b = moved(icosphere(20.0, 4), [35.0, 0.0, 0.0]);
        let top = a.vertices.iter().copied().max_by(|p, q| p[2].total_cmp(&q[2])).unwrap();
        let c = moved(icosphere(10.0, 3), [top[0], top[1], top[2] + 10.0]);
        let mut broken = joined(&[a.clone(), b.clone(), c.clone()]);
        broken.triangles.remove(2000);
        broken.triangles.remove(1500);
        broken.triangles.remove(100);
        assert!(repair_surface(&broken, &RepairOptions::default()).is_err());
        let (result, route) =
            repair_or_rebuild(&broken, &RepairOptions::default(), &RebuildOptions::default()).unwrap();
        let Route::Volumetric(report) = &route else { panic!("{route:?}") };
        let volume = check_closed_manifold(&result).unwrap().volume;
        // The union: the spheres less their lens, plus the small sphere.
        let (r1, r2, d) = (30.0, 20.0, 35.0);
        let lens = PI
            * (r1 + r2 - d)
            * (r1 + r2 - d)
            * (d * d + 2.0 * d * r2 - 3.0 * r2 * r2 + 2.0 * d * r1 + 6.0 * r1 * r2 - 3.0 * r1 * r1)
            / (12.0 * d);
        let expected = a.enclosed_volume() + b.enclosed_volume() + c.enclosed_volume()
            - lens * a.enclosed_volume() / (4.0 / 3.0 * PI * r1.powi(3));
        let lines = route.lines(Some(LengthUnit::Millimetre));
        eprintln!(
            "{lines:#?}\nvolume {volume:.0}, expected {expected:.0} ({:+.2} %)",
            100.0 * (volume / expected - 1.0)
        );
        assert!((volume / expected - 1.0).abs() < 0.03, "{volume} vs {expected}");
        assert!(report.reason.contains("non-manifold"), "{}", report.reason);
        assert!(report.mean_distance < 0.3 * report.voxel && report.max_distance < 2.0 * report.voxel, "{report:?}");
        assert!(lines[0].starts_with("route: volumetric (local repair cannot mend it: "));
        assert!(lines.last().unwrap().starts_with("distance to the input surface: mean "));
        // The organ is kept whole: its volume lies within 3 % of the voxels it was extracted from.
        let e = &report.extract;
        assert!((e.volume / e.voxel_volume - 1.0).abs() < 0.03, "{e:?}");
        let change = format!("{:+.1} % from the voxels)", 100.0 * (e.volume / e.voxel_volume - 1.0));
        assert!(lines.iter().any(|l| l.starts_with("enclosed volume: ") && l.ends_with(&change)), "{lines:?}");
    }

    #[test]
    fn a_decimation_fold_goes_through_the_volumetric_route() {
        // A quadric decimation that does not keep the topology folds a flap of two triangles back
        // to back onto an edge of the surface, as CT liver exports so decimated show.
        let sphere = icosphere(30.0, 4);
        let mut folded = sphere.clone();
        let [a, b, _] = folded.triangles[0];
        let tip = folded.vertices[a].map(|x| 1.3 * x);
        folded.vertices.push(tip);
        let c = folded.vertices.len() - 1;
        folded.triangles.extend([[a, b, c], [b, a, c]]);
        let refused = repair_surface(&folded, &RepairOptions::default()).unwrap_err().to_string();
        assert!(refused.contains("non-manifold edge") && refused.contains("cannot be repaired"), "{refused}");
        let (result, route) =
            repair_or_rebuild(&folded, &RepairOptions::default(), &RebuildOptions::default()).unwrap();
        let Route::Volumetric(report) = &route else { panic!("{route:?}") };
        let volume = check_closed_manifold(&result).unwrap().volume;
        let expected = sphere.enclosed_volume();
        assert!((volume / expected - 1.0).abs() < 0.03, "{volume} vs {expected}");
        assert!(report.reason.contains("non-manifold edge"), "{}", report.reason);
        assert!(report.mean_distance < 0.3 * report.voxel, "{report:?}");
    }

    #[test]
    fn a_mendable_surface_takes_the_local_route() {
        let mut s = icosphere(30.0, 3);
        s.triangles.remove(10);
        let (result, route) = repair_or_rebuild(&s, &RepairOptions::default(), &RebuildOptions::default()).unwrap();
        assert!(matches!(&route, Route::Local(r) if r.holes_filled == vec![3]));
        assert_eq!(result.triangles.len(), 1280);
        assert_eq!(route.lines(Some(LengthUnit::Millimetre))[0], "route: local repair");
    }

    #[test]
    fn debris_is_dropped_and_what_is_not_an_organ_refused() {
        let organ = icosphere(30.0, 3);
        let debris = moved(icosphere(3.0, 1), [60.0, 0.0, 0.0]);
        let (_, route) =
            repair_or_rebuild(&joined(&[organ.clone(), debris]), &RepairOptions::default(), &RebuildOptions::default())
                .unwrap();
        let Route::Volumetric(report) = route else { panic!() };
        assert_eq!(report.extract.dropped_pieces.len(), 1);
        assert!(report.reason.contains("separate pieces"));

        let error = |s: &TriSurface| {
            repair_or_rebuild(s, &RepairOptions::default(), &RebuildOptions::default()).unwrap_err().to_string()
        };
        let twins = joined(&[organ.clone(), moved(icosphere(28.0, 3), [80.0, 0.0, 0.0])]);
        assert!(error(&twins).contains("several pieces of similar size"), "{}", error(&twins));
        let square = TriSurface {
            vertices: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]],
            triangles: vec![[0, 1, 2], [0, 2, 3]],
        };
        assert!(error(&square).contains("flat"), "{}", error(&square));
        // Closed, both sides of the square: local repair finds nothing to mend, but no organ.
        let pillow = TriSurface { triangles: vec![[0, 1, 2], [0, 2, 3], [0, 2, 1], [0, 3, 2]], ..square };
        assert!(error(&pillow).contains("the surface is flat"), "{}", error(&pillow));
        assert!(error(&TriSurface::default()).contains("no triangles"));
    }

    /// A closed surface thinner than the voxels it is rebuilt through (a pancake a voxel thick) is
    /// refused as a sheet, in a surface's words, not an image's; one a few voxels thick is rebuilt.
    #[test]
    fn a_surface_thinner_than_its_voxels_is_refused_as_a_sheet() {
        let options = RebuildOptions::default();
        let pancake = |thickness: f64| {
            let mut s = icosphere(30.0, 4);
            s.vertices.iter_mut().for_each(|p| p[2] *= thickness / 60.0);
            rebuild_surface(&s, "broken".into(), &options)
        };
        // Voxels of 60 / 150 = 0.4.
        let error = pancake(0.5).unwrap_err().to_string();
        assert!(error.contains("thinner than the voxels it is rebuilt through (0.4)"), "{error}");
        assert!(!error.contains("image") && !error.contains("slice"), "{error}");
        assert!(pancake(2.0).is_ok());
    }
}
