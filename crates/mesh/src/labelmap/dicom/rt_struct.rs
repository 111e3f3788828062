//! DICOM RT Structure Sets (RTSTRUCT), as treatment planning systems, 3D Slicer (SlicerRT) and
//! TotalSegmentator (through rt-utils) write them: each structure (ROI) a stack of closed planar
//! contours, polygons in DICOM's patient frame (LPS, mm), drawn on the slices of the CT they were
//! made on. The CT itself is not needed: the contours are filled on a grid of their own, its
//! slices where the contours lie (the smallest gap between them, all others a whole number of
//! gaps apart) and its pixels half that gap wide, between [`FINEST_MM`] and [`COARSEST_MM`]
//! (coarser, and said so, when the contours span more than [`VOXEL_BUDGET`] voxels); the
//! structure chosen is filled alone on a grid of its own extent. A pixel is inside a structure
//! when its centre is inside an odd number of the structure's contours on its slice, so that a
//! contour inside another is a hole, as planning systems and SlicerRT read them; a slice between
//! two drawn ones (a structure drawn on every other slice in places) takes the shape between
//! theirs, interpolated from their signed distance maps. Structures may overlap (an organ and its tumour, the body and
//! everything): each goes to the first layer it does not overlap, as for a DICOM SEG. Points and
//! open contours (markers, lines) have no volume: their structure is listed, empty, with a
//! warning.

use std::collections::{BTreeMap, BTreeSet};

use dicom_dictionary_std::tags;
use dicom_object::DefaultDicomObject;

use super::{in_layers, items, number, numbers, slice_step, text};
use crate::labelmap::{Frame, Labelmap};
use crate::length::LengthUnit;
use crate::{cross, dot, norm, Point};

/// The SOP class of an RT Structure Set.
pub(super) const RT_STRUCTURE_SET: &str = "1.2.840.10008.5.1.4.1.1.481.3";

/// The finest pixel of the grid the contours are filled on (mm): finer than a CT's, so that the
/// filled area follows the polygons.
const FINEST_MM: f64 = 0.5;

/// The coarsest pixel (mm) of the grid, within the budget: a CT's. Pixels finer than half the
/// slices' spacing would add triangles to the organ's surface, not shape.
const COARSEST_MM: f64 = 1.0;

/// The most voxels a layer of the grid holds: the pixels grow beyond [`FINEST_MM`] for contours
/// spanning more (a body outline).
const VOXEL_BUDGET: f64 = 16_777_216.0;

/// How far (mm) a contour's points may lie off its plane, and two contours' heights apart on one
/// slice: the rounding of their decimal strings.
const PLANE_TOLERANCE_MM: f64 = 0.05;

/// One closed contour: its points and its height along the slices' normal.
struct Contour {
    roi: u32,
    points: Vec<Point>,
    height: f64,
}

/// Reads an RT Structure Set (`object`, of the class [`RT_STRUCTURE_SET`]): every structure, or
/// only the one `wanted` names (its number, else its name in any case) when one does, so that its
/// grid is its own and not that of the largest structure (the body's outline).
pub(super) fn read(object: &DefaultDicomObject, wanted: Option<&str>) -> Result<Labelmap, String> {
    let mut names: BTreeMap<u32, String> = BTreeMap::new();
    for item in items(object, tags::STRUCTURE_SET_ROI_SEQUENCE) {
        let roi = number(item, tags::ROI_NUMBER)?;
        names.insert(roi, text(item, tags::ROI_NAME).filter(|n| !n.is_empty()).unwrap_or_else(|| format!("ROI {roi}")));
    }
    let mut warnings = Vec::new();
    let (mut contours, without_volume) = closed_contours(object, &mut names, &mut warnings)?;
    if let Some(roi) = wanted.and_then(|w| chosen(&names, w)) {
        contours.retain(|c| c.roi == roi);
        names.retain(|&n, _| n == roi);
    }
    if contours.is_empty() {
        return Err(match names.is_empty() {
            true => "it describes no structure (its StructureSetROISequence and ROIContourSequence are empty)".into(),
            false => "no structure has a closed contour: nothing to fill".into(),
        });
    }
    let (axes, contours) = in_common_planes(contours, &names)?;
    let mut heights: Vec<f64> = contours.iter().map(|c| c.height).collect();
    heights.sort_by(f64::total_cmp);
    heights.dedup_by(|a, b| (*a - *b).abs() < PLANE_TOLERANCE_MM);
    let step = slice_step(&heights, None, "contours")?
        .ok_or("all its contours lie in one plane: a structure of one slice has no thickness")?;
    let grid = Grid::new(&contours, axes, heights[0], step, heights.len(), &mut warnings);
    let frame_pixels = grid.columns * grid.rows;
    let mut by_slice: BTreeMap<(u32, usize), Vec<&Contour>> = BTreeMap::new();
    for contour in &contours {
        by_slice.entry((contour.roi, grid.slice_of(contour.height))).or_default().push(contour);
    }
    // Each structure's slices as drawn, then the slices between two drawn ones (drawn every slice
    // near a tumour, every other one elsewhere) by shape-based interpolation.
    let mut drawn: BTreeMap<u32, BTreeMap<usize, Vec<usize>>> = BTreeMap::new();
    let mut crossing: BTreeMap<u32, usize> = BTreeMap::new();
    for (&(roi, k), on_slice) in &by_slice {
        let mut pixels = Vec::new();
        grid.fill(on_slice, |pixel| pixels.push(pixel));
        drawn.entry(roi).or_default().insert(k, pixels);
        if grid.contours_cross(on_slice) {
            *crossing.entry(roi).or_default() += 1;
        }
    }
    let mut voxels: BTreeMap<u32, Vec<u32>> = BTreeMap::new();
    for (&roi, slices) in &drawn {
        let own = voxels.entry(roi).or_default();
        let ks: Vec<usize> = slices.keys().copied().collect();
        let mut distances: Option<(usize, Vec<f64>)> = None;
        for (i, &k) in ks.iter().enumerate() {
            own.extend(slices[&k].iter().map(|&pixel| (pixel + frame_pixels * k) as u32));
            let Some(&next) = ks.get(i + 1).filter(|&&next| next > k + 1) else { continue };
            let below = match distances.take() {
                Some((at, d)) if at == k => d,
                _ => grid.signed_distances(&slices[&k]),
            };
            let above = grid.signed_distances(&slices[&next]);
            for slice in k + 1..next {
                let t = (slice - k) as f64 / (next - k) as f64;
                // Where the two shapes' boundaries are equally near, the lower one's pixel.
                let between = |p: usize| (1.0 - t) * below[p] + t * above[p];
                let inside = (0..frame_pixels).filter(|&p| between(p) < 0.0 || (between(p) == 0.0 && below[p] < 0.0));
                own.extend(inside.map(|pixel| (pixel + frame_pixels * slice) as u32));
            }
            distances = Some((next, above));
        }
    }
    voxels.retain(|_, own| !own.is_empty());
    let dims = [grid.columns, grid.rows, grid.slices];
    let (layers, labels, segments) =
        in_layers(&names, &voxels, (dims.iter().product(), frame_pixels), true, &mut warnings);
    for (name, layer, label) in &segments {
        let roi = *label as u32;
        if let Some(slices) = crossing.get(&roi) {
            warnings.push((
                Some((*layer, *label)),
                format!(
                    "contours of '{name}' cross on {slices} slice(s): filled even–odd, where two overlap is a hole, \
                     as planning systems read them; draw them as one outline if they are one"
                ),
            ));
        }
        let why = match (without_volume.contains(&roi), drawn.contains_key(&roi)) {
            (true, false) => "is drawn as points or open lines (markers, not outlines): it has no volume",
            (false, false) => "has no contour",
            _ => continue,
        };
        warnings.push((Some((*layer, *label)), format!("'{name}' {why}")));
    }
    let (affine, named_unit) = (grid.affine, Some(LengthUnit::Millimetre));
    Ok(Labelmap { dims, layers, labels, affine, frame: Frame::Lps, segments, placed: true, warnings, named_unit })
}

/// The structure `wanted` names: its number, else its name (any case), when exactly one has it.
fn chosen(names: &BTreeMap<u32, String>, wanted: &str) -> Option<u32> {
    let wanted = wanted.trim();
    if let Ok(number) = wanted.parse::<u32>() {
        return names.contains_key(&number).then_some(number);
    }
    let mut named = names.iter().filter(|(_, name)| name.eq_ignore_ascii_case(wanted));
    match (named.next(), named.next()) {
        (Some((&roi, _)), None) => Some(roi),
        _ => None,
    }
}

/// The closed planar contours of every structure, and the structures drawn only as points or open
/// lines; a structure with contours but not in `names` is added to it as "ROI n", with a warning.
fn closed_contours(
    object: &DefaultDicomObject,
    names: &mut BTreeMap<u32, String>,
    warnings: &mut Vec<(Option<(usize, i32)>, String)>,
) -> Result<(Vec<Contour>, BTreeSet<u32>), String> {
    let mut contours = Vec::new();
    let mut without_volume = BTreeSet::new();
    for item in items(object, tags::ROI_CONTOUR_SEQUENCE) {
        let roi = number(item, tags::REFERENCED_ROI_NUMBER)?;
        if let std::collections::btree_map::Entry::Vacant(entry) = names.entry(roi) {
            entry.insert(format!("ROI {roi}"));
            warnings.push((None, format!("contours of ROI {roi}, which the file does not describe, are read")));
        }
        for (c, contour) in items(item, tags::CONTOUR_SEQUENCE).iter().enumerate() {
            let context = |e: String| format!("'{}', contour {}: {e}", names[&roi], c + 1);
            let kind = text(contour, tags::CONTOUR_GEOMETRIC_TYPE).unwrap_or_else(|| "CLOSED_PLANAR".into());
            if kind != "CLOSED_PLANAR" {
                without_volume.insert(roi);
                continue;
            }
            let data = numbers(contour, tags::CONTOUR_DATA).map_err(context)?;
            if data.len() % 3 != 0 || data.iter().any(|v| !v.is_finite()) {
                return Err(context(format!("its ContourData hold {} numbers, not x, y, z triples", data.len())));
            }
            let points: Vec<Point> = data.chunks_exact(3).map(|p| [p[0], p[1], p[2]]).collect();
            if points.len() >= 3 {
                contours.push(Contour { roi, points, height: 0.0 });
            }
        }
    }
    Ok((contours, without_volume))
}

/// The slices' axes (`u`, `v` in their plane, `n` their normal, right-handed) and the contours
/// with their heights along `n`: every contour must lie flat in a plane of that normal.
fn in_common_planes(
    mut contours: Vec<Contour>,
    names: &BTreeMap<u32, String>,
) -> Result<([Point; 3], Vec<Contour>), String> {
    // The normal of the largest contour (Newell's method: twice its area along its normal).
    let newell = |points: &[Point]| {
        (0..points.len()).fold([0.0; 3], |sum: Point, i| {
            let c = cross(points[i], points[(i + 1) % points.len()]);
            std::array::from_fn(|d| sum[d] + c[d])
        })
    };
    let largest = contours.iter().map(|c| newell(&c.points)).max_by(|a, b| norm(*a).total_cmp(&norm(*b)));
    let normal = largest.filter(|n| norm(*n) > 0.0).ok_or("its contours enclose no area")?;
    // Its sign: its largest component positive (+z for axial slices, whatever the winding).
    let big = (0..3).max_by(|&a, &b| normal[a].abs().total_cmp(&normal[b].abs())).unwrap_or(2);
    let n = normal.map(|c| normal[big].signum() * c / norm(normal));
    let e = (0..3).min_by(|&a, &b| n[a].abs().total_cmp(&n[b].abs())).unwrap_or(0);
    let axis: Point = std::array::from_fn(|d| f64::from(d == e));
    let u = crate::sub(axis, n.map(|c| c * dot(axis, n)));
    let u = u.map(|c| c / norm(u));
    let v = cross(n, u);
    for contour in &mut contours {
        let heights: Vec<f64> = contour.points.iter().map(|p| dot(*p, n)).collect();
        let (low, high) = heights.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &x| (l.min(x), h.max(x)));
        if high - low > PLANE_TOLERANCE_MM {
            return Err(format!(
                "a contour of '{}' is not in a plane of the others' normal ({:.3}, {:.3}, {:.3}): its points lie \
                 {:.2} mm apart along it; only contours on parallel slices are read",
                names[&contour.roi],
                n[0],
                n[1],
                n[2],
                high - low
            ));
        }
        contour.height = 0.5 * (low + high);
    }
    Ok(([u, v, n], contours))
}

/// The grid the contours are filled on: pixels `spacing` wide along `u` and `v`, slices `step`
/// apart along `n`, with an empty pixel and slice around the contours.
struct Grid {
    axes: [Point; 3],
    /// The in-plane coordinates (along `u`, `v`) of pixel (0, 0)'s centre, and the lowest slice's
    /// height.
    corner: [f64; 3],
    spacing: f64,
    step: f64,
    columns: usize,
    rows: usize,
    slices: usize,
    affine: [[f64; 4]; 3],
}

impl Grid {
    /// The grid of `contours` (on `heights` slices from `lowest`, `step` apart); a warning when its
    /// pixels are coarser than [`COARSEST_MM`].
    fn new(
        contours: &[Contour],
        axes: [Point; 3],
        lowest: f64,
        step: f64,
        heights: usize,
        warnings: &mut Vec<(Option<(usize, i32)>, String)>,
    ) -> Grid {
        let [u, v, n] = axes;
        let (mut low, mut high) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for p in contours.iter().flat_map(|c| &c.points) {
            for (d, axis) in [u, v].into_iter().enumerate() {
                low[d] = low[d].min(dot(*p, axis));
                high[d] = high[d].max(dot(*p, axis));
            }
        }
        let slices = ((contours.iter().map(|c| c.height).fold(f64::NEG_INFINITY, f64::max) - lowest) / step).round()
            as usize
            + 3;
        let area = (high[0] - low[0]) * (high[1] - low[1]);
        let spacing = (0.5 * step).clamp(FINEST_MM, COARSEST_MM).max((area * slices as f64 / VOXEL_BUDGET).sqrt());
        if spacing > COARSEST_MM {
            warnings.push((
                None,
                format!(
                    "its contours span {:.0} × {:.0} mm on {heights} slices: they are filled on pixels of {spacing:.2} \
                     mm, which keeps the grid under {VOXEL_BUDGET} voxels",
                    high[0] - low[0],
                    high[1] - low[1]
                ),
            ));
        }
        // Half a pixel and one more beyond the contours: no pixel centre on their box.
        let [columns, rows] = std::array::from_fn(|d| ((high[d] - low[d]) / spacing).ceil() as usize + 2);
        let corner = [low[0] - 0.5 * spacing, low[1] - 0.5 * spacing, lowest - step];
        let origin: Point = std::array::from_fn(|d| corner[0] * u[d] + corner[1] * v[d] + corner[2] * n[d]);
        let affine = std::array::from_fn(|r| [u[r] * spacing, v[r] * spacing, n[r] * step, origin[r]]);
        Grid { axes, corner, spacing, step, columns, rows, slices, affine }
    }

    /// The slice a contour at `height` lies on.
    fn slice_of(&self, height: f64) -> usize {
        ((height - self.corner[2]) / self.step).round() as usize
    }

    /// Whether two of `contours` (of one structure, on one slice) overlap without one holding the
    /// other: they cross, where a contour inside another is a hole.
    fn contours_cross(&self, contours: &[&Contour]) -> bool {
        if contours.len() < 2 {
            return false;
        }
        let fills: Vec<BTreeSet<usize>> = contours
            .iter()
            .map(|c| {
                let mut pixels = BTreeSet::new();
                self.fill(&[c], |p| {
                    pixels.insert(p);
                });
                pixels
            })
            .collect();
        fills.iter().enumerate().any(|(i, a)| {
            fills[i + 1..].iter().any(|b| {
                let shared = a.intersection(b).count();
                shared > 0 && shared < a.len().min(b.len())
            })
        })
    }

    /// The signed distance (pixels) of each pixel of a slice to the boundary of the `inside` ones:
    /// negative inside, so that its zero level between two slices' shapes, weighted by how near
    /// each lies, is the shape between them (shape-based interpolation, Raya and Udupa 1990).
    fn signed_distances(&self, inside: &[usize]) -> Vec<f64> {
        let mut is_inside = vec![false; self.columns * self.rows];
        inside.iter().for_each(|&p| is_inside[p] = true);
        let outside: Vec<bool> = is_inside.iter().map(|&i| !i).collect();
        let to_inside = squared_distances(&is_inside, self.columns, self.rows);
        let to_outside = squared_distances(&outside, self.columns, self.rows);
        to_inside.iter().zip(&to_outside).map(|(a, b)| a.sqrt() - b.sqrt()).collect()
    }

    /// Calls `inside` with each pixel (column + columns × row) of the slice whose centre lies
    /// inside an odd number of `contours`.
    fn fill(&self, contours: &[&Contour], mut inside: impl FnMut(usize)) {
        let [u, v, _] = self.axes;
        // Edges in pixel coordinates: pixel (i, j)'s centre is at (i, j).
        let at = |p: &Point, d: usize, axis: Point| (dot(*p, axis) - self.corner[d]) / self.spacing;
        let mut edges: Vec<[f64; 4]> = Vec::new();
        for contour in contours {
            let points: Vec<[f64; 2]> = contour.points.iter().map(|p| [at(p, 0, u), at(p, 1, v)]).collect();
            for (i, a) in points.iter().enumerate() {
                let b = points[(i + 1) % points.len()];
                if a[1] != b[1] {
                    edges.push([a[0], a[1], b[0], b[1]]);
                }
            }
        }
        let mut crossings = Vec::new();
        for row in 0..self.rows {
            let y = row as f64;
            crossings.clear();
            crossings.extend(
                edges
                    .iter()
                    .filter(|e| (e[1] <= y) != (e[3] <= y))
                    .map(|e| e[0] + (y - e[1]) * (e[2] - e[0]) / (e[3] - e[1])),
            );
            crossings.sort_by(f64::total_cmp);
            for pair in crossings.chunks_exact(2) {
                let first = pair[0].ceil().max(0.0) as usize;
                let end = (pair[1].ceil().max(0.0) as usize).min(self.columns);
                (first..end).for_each(|column| inside(column + self.columns * row));
            }
        }
    }
}

/// The squared Euclidean distance (pixels) from each pixel of a `columns` × `rows` image to the
/// nearest `feature` pixel, infinite where there is none (Felzenszwalb and Huttenlocher 2012: the
/// lower envelope of parabolas along the rows, then along the columns).
fn squared_distances(feature: &[bool], columns: usize, rows: usize) -> Vec<f64> {
    let mut d: Vec<f64> = feature.iter().map(|&f| if f { 0.0 } else { f64::INFINITY }).collect();
    let mut line = Vec::new();
    for row in d.chunks_exact_mut(columns) {
        line.clear();
        line.extend_from_slice(row);
        lower_envelope(&line, row);
    }
    let mut column_out = vec![0.0; rows];
    for c in 0..columns {
        line.clear();
        line.extend((0..rows).map(|r| d[c + columns * r]));
        lower_envelope(&line, &mut column_out);
        column_out.iter().enumerate().for_each(|(r, &v)| d[c + columns * r] = v);
    }
    d
}

/// `out[q] = min over p of (q − p)² + f[p]`, for one line of [`squared_distances`].
fn lower_envelope(f: &[f64], out: &mut [f64]) {
    let Some(first) = f.iter().position(|v| v.is_finite()) else {
        return out.fill(f64::INFINITY);
    };
    let parabola = |p: usize| f[p] + (p * p) as f64;
    let (mut vertices, mut bounds) = (vec![first], vec![f64::NEG_INFINITY]);
    for (q, _) in f.iter().enumerate().skip(first + 1).filter(|(_, v)| v.is_finite()) {
        // Where q's parabola falls below the last kept one's; z[0] = −∞ keeps the first.
        let meets = |p: usize| (parabola(q) - parabola(p)) / (2.0 * (q - p) as f64);
        while meets(*vertices.last().unwrap()) <= *bounds.last().unwrap() {
            vertices.pop();
            bounds.pop();
        }
        bounds.push(meets(*vertices.last().unwrap()));
        vertices.push(q);
    }
    let mut j = 0;
    for (q, value) in out.iter_mut().enumerate() {
        while j + 1 < vertices.len() && bounds[j + 1] < q as f64 {
            j += 1;
        }
        let p = vertices[j];
        *value = (q.abs_diff(p) * q.abs_diff(p)) as f64 + f[p];
    }
}

#[cfg(test)]
mod tests {
    use dicom_core::value::DataSetSequence;
    use dicom_core::{DataElement, PrimitiveValue, VR};
    use dicom_object::mem::InMemElement;
    use dicom_object::meta::FileMetaTableBuilder;
    use dicom_object::InMemDicomObject;

    use super::*;
    use crate::labelmap::dicom::parse_dicom;

    fn text_element(tag: dicom_object::Tag, vr: VR, text: &str) -> InMemElement {
        DataElement::new(tag, vr, PrimitiveValue::from(text))
    }

    /// An RT Structure Set of `structures` (number, name) and `contours` (structure, geometric
    /// type, points).
    fn rt_struct(structures: &[(u32, &str)], contours: &[(u32, &str, Vec<Point>)]) -> Vec<u8> {
        let described = structures
            .iter()
            .map(|&(roi, name)| {
                InMemDicomObject::from_element_iter([
                    text_element(tags::ROI_NUMBER, VR::IS, &roi.to_string()),
                    text_element(tags::ROI_NAME, VR::LO, name),
                ])
            })
            .collect::<Vec<_>>();
        let mut rois: BTreeMap<u32, Vec<InMemDicomObject>> = BTreeMap::new();
        for (roi, kind, points) in contours {
            let data: Vec<String> = points.iter().flatten().map(|c| format!("{c}")).collect();
            rois.entry(*roi).or_default().push(InMemDicomObject::from_element_iter([
                text_element(tags::CONTOUR_GEOMETRIC_TYPE, VR::CS, kind),
                text_element(tags::NUMBER_OF_CONTOUR_POINTS, VR::IS, &points.len().to_string()),
                text_element(tags::CONTOUR_DATA, VR::DS, &data.join("\\")),
            ]));
        }
        let contoured = rois
            .into_iter()
            .map(|(roi, contours)| {
                InMemDicomObject::from_element_iter([
                    text_element(tags::REFERENCED_ROI_NUMBER, VR::IS, &roi.to_string()),
                    DataElement::new(tags::CONTOUR_SEQUENCE, VR::SQ, DataSetSequence::from(contours)),
                ])
            })
            .collect::<Vec<_>>();
        let object = InMemDicomObject::from_element_iter([
            text_element(tags::SOP_CLASS_UID, VR::UI, RT_STRUCTURE_SET),
            text_element(tags::SOP_INSTANCE_UID, VR::UI, "2.25.2"),
            text_element(tags::MODALITY, VR::CS, "RTSTRUCT"),
            DataElement::new(tags::STRUCTURE_SET_ROI_SEQUENCE, VR::SQ, DataSetSequence::from(described)),
            DataElement::new(tags::ROI_CONTOUR_SEQUENCE, VR::SQ, DataSetSequence::from(contoured)),
        ]);
        let file = object.with_meta(FileMetaTableBuilder::new().transfer_syntax("1.2.840.10008.1.2")).unwrap();
        let mut bytes = Vec::new();
        file.write_all(&mut bytes).unwrap();
        bytes
    }

    /// A square of side `side` mm centred at (x, y) at height z (counter-clockwise or not).
    fn square(x: f64, y: f64, z: f64, side: f64, clockwise: bool) -> Vec<Point> {
        let h = side / 2.0;
        let mut points = vec![[x - h, y - h, z], [x + h, y - h, z], [x + h, y + h, z], [x - h, y + h, z]];
        if clockwise {
            points.reverse();
        }
        points
    }

    /// The world point of a labelmap's voxel centre.
    fn world(map: &Labelmap, ijk: [usize; 3]) -> Point {
        std::array::from_fn(|r| (0..3).map(|c| map.affine[r][c] * ijk[c] as f64).sum::<f64>() + map.affine[r][3])
    }

    /// A 10 mm square on three slices 1 mm apart, with a 4 mm hole in the middle one, and a
    /// tumour overlapping it: the areas are the polygons' to the pixel, the hole is a hole, the
    /// tumour takes a layer of its own and the voxels lie where the contours are.
    #[test]
    fn contours_are_filled_even_odd_where_they_lie() {
        let mut contours: Vec<(u32, &str, Vec<Point>)> =
            (0..3).map(|k| (1, "CLOSED_PLANAR", square(20.0, -5.0, 100.0 + k as f64, 10.0, k == 1))).collect();
        contours.push((1, "CLOSED_PLANAR", square(20.0, -5.0, 101.0, 4.0, false)));
        contours.push((2, "CLOSED_PLANAR", square(18.0, -7.0, 100.0, 3.0, false)));
        contours.push((3, "POINT", vec![[0.0, 0.0, 100.0]]));
        contours.push((9, "CLOSED_PLANAR", square(40.0, 40.0, 100.0, 2.0, false)));
        let map = parse_dicom(&rt_struct(&[(1, "Liver"), (2, "GTV"), (3, "marker")], &contours), None).unwrap();
        assert_eq!(map.frame, Frame::Lps);
        assert_eq!(map.spacing(), [0.5, 0.5, 1.0], "pixels of half the slices' spacing");
        assert_eq!(map.layers, 2, "the tumour overlaps the liver");
        let (liver, _) = map.select("liver").unwrap();
        // 10 × 10 mm is 400 pixels of 0.5 mm, twice, and 100 − 16 mm² (336 pixels) with the hole.
        assert_eq!(liver.count(), 400 + 336 + 400);
        let (tumour, _) = map.select("GTV").unwrap();
        assert_eq!(tumour.count(), 36, "3 × 3 mm on one slice");
        // The filled pixels' centres lie inside the square, and all of it is covered.
        let [ni, nj, nk] = map.dims;
        let (mut low, mut high) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
        for k in 0..nk {
            for j in 0..nj {
                for i in 0..ni {
                    if map.labels[map.layers * (i + ni * (j + nj * k))] == 1 {
                        let p = world(&map, [i, j, k]);
                        (0..3).for_each(|d| (low[d], high[d]) = (low[d].min(p[d]), high[d].max(p[d])));
                    }
                }
            }
        }
        assert_eq!((low, high), ([15.25, -9.75, 100.0], [24.75, -0.25, 102.0]), "pixel centres inside the square");
        let marker = map.warnings.iter().find(|(of, _)| *of == Some((0, 3))).map(|w| w.1.as_str());
        assert!(marker.is_some_and(|w| w.contains("'marker' is drawn as points")), "{:?}", map.warnings);
        assert_eq!(map.select("ROI 9").unwrap().0.count(), 16, "contours of a structure the file does not describe");
        assert!(map.warnings.iter().any(|(_, w)| w.starts_with("contours of ROI 9, which the file does not describe")));
    }

    /// Contours on oblique slices are filled in their planes: the grid's slices are their planes
    /// and the filled area is the polygons', on pixels of 1 mm ([`COARSEST_MM`]) for slices 3 mm
    /// apart.
    #[test]
    fn oblique_slices_keep_their_plane() {
        let (c, s) = (30_f64.to_radians().cos(), 30_f64.to_radians().sin());
        // The squares turned by 30° about x: their normal is (0, −sin, cos).
        let turn = |p: Point| [p[0], c * p[1] - s * p[2], s * p[1] + c * p[2]];
        let contours: Vec<(u32, &str, Vec<Point>)> = (0..4)
            .map(|k| {
                (7, "CLOSED_PLANAR", square(0.0, 0.0, 3.0 * k as f64, 12.0, false).into_iter().map(turn).collect())
            })
            .collect();
        let map = parse_dicom(&rt_struct(&[(7, "liver")], &contours), None).unwrap();
        let normal = [map.affine[0][2], map.affine[1][2], map.affine[2][2]].map(|x| x / 3.0);
        assert!(norm(crate::sub(normal, [0.0, -s, c])) < 1e-9, "{normal:?}");
        assert_eq!(map.spacing().map(|s| (s * 1e9).round() / 1e9), [COARSEST_MM, COARSEST_MM, 3.0]);
        assert_eq!(map.select("liver").unwrap().0.count(), 4 * 12 * 12);
    }

    #[test]
    fn what_cannot_be_filled_is_refused_by_name() {
        let error = |structures: &[(u32, &str)], contours: &[(u32, &str, Vec<Point>)]| {
            parse_dicom(&rt_struct(structures, contours), None).unwrap_err()
        };
        let flat = error(&[(1, "liver")], &[(1, "CLOSED_PLANAR", square(0.0, 0.0, 5.0, 10.0, false))]);
        assert!(flat.starts_with("all its contours lie in one plane"), "{flat}");
        let mut bent = square(0.0, 0.0, 5.0, 10.0, false);
        bent[2][2] = 6.0;
        let bent = error(
            &[(1, "liver")],
            &[(1, "CLOSED_PLANAR", square(0.0, 0.0, 0.0, 10.0, false)), (1, "CLOSED_PLANAR", bent)],
        );
        assert!(bent.starts_with("a contour of 'liver' is not in a plane"), "{bent}");
        let off = [0.0, 2.0, 3.5].map(|z| (1, "CLOSED_PLANAR", square(0.0, 0.0, z, 10.0, false)));
        let off = error(&[(1, "liver")], &off);
        assert!(off.starts_with("its contours do not lie on slices 1.5 mm apart"), "{off}");
        let points = error(&[(1, "marker")], &[(1, "POINT", vec![[0.0, 0.0, 0.0]])]);
        assert_eq!(points, "no structure has a closed contour: nothing to fill");
        assert!(error(&[], &[]).starts_with("it describes no structure"));
    }

    /// A small structure beside a body's outline is filled on a grid of its own when it is the one
    /// wanted, not on the coarse pixels the body's extent needs.
    #[test]
    fn the_structure_wanted_gets_a_grid_of_its_own() {
        let mut contours: Vec<(u32, &str, Vec<Point>)> =
            (0..=300).map(|z| (1, "CLOSED_PLANAR", square(0.0, 0.0, z as f64, 500.0, false))).collect();
        let gtv = [(100.0, 2.0), (101.0, 4.0), (102.0, 2.0)];
        contours.extend(gtv.map(|(z, side)| (2, "CLOSED_PLANAR", square(10.0, 20.0, z, side, false))));
        let file = rt_struct(&[(1, "BODY"), (2, "GTV")], &contours);
        let all = parse_dicom(&file, None).unwrap();
        assert!(all.spacing()[0] > 1.5, "{:?}", all.spacing());
        assert!(all.warnings.iter().any(|(_, w)| w.starts_with("its contours span 500 × 500 mm on 301 slices")));
        for wanted in ["gtv", "2"] {
            let own = parse_dicom(&file, Some(wanted)).unwrap();
            assert_eq!(own.spacing(), [0.5, 0.5, 1.0], "{wanted}");
            assert_eq!(own.select("GTV").unwrap().0.count(), 16 + 64 + 16, "{wanted}: 2, 4 and 2 mm squares");
            assert!(own.warnings.is_empty(), "{:?}", own.warnings);
        }
        // A name no structure has: all of them, for the message that lists them.
        assert_eq!(parse_dicom(&file, Some("liver")).unwrap().segments.len(), 2);
    }

    /// Two outlines of one structure that cross on a slice are filled even–odd, and said to cross;
    /// a hole inside an outline is not.
    #[test]
    fn crossing_contours_are_said_to_cross() {
        let mut contours: Vec<(u32, &str, Vec<Point>)> = Vec::new();
        for z in [0.0, 1.0] {
            contours.push((1, "CLOSED_PLANAR", square(0.0, 0.0, z, 10.0, false)));
            contours.push((1, "CLOSED_PLANAR", square(6.0, 0.0, z, 10.0, false)));
            contours.push((2, "CLOSED_PLANAR", square(40.0, 0.0, z, 10.0, false)));
            contours.push((2, "CLOSED_PLANAR", square(40.0, 0.0, z, 4.0, false)));
        }
        let map = parse_dicom(&rt_struct(&[(1, "crossed"), (2, "holed")], &contours), None).unwrap();
        let said: Vec<&str> = map.warnings.iter().map(|(_, w)| w.as_str()).collect();
        assert!(said.iter().any(|w| w.starts_with("contours of 'crossed' cross on 2 slice(s)")), "{said:?}");
        assert!(!said.iter().any(|w| w.contains("'holed'")), "{said:?}");
        // 10 × 10 mm twice, less twice their 4 × 10 mm overlap, in pixels of 0.5 mm, on 2 slices.
        assert_eq!(map.select("crossed").unwrap().0.count(), 2 * (2 * 400 - 2 * 160));
    }

    /// A round end on coarse slices (a tumour drawn every 5 mm) tapers from its neighbour: not
    /// said to be cut; an end as large as its neighbour is.
    #[test]
    fn only_an_end_as_large_as_its_neighbour_is_cut() {
        let slices = |sizes: &[usize]| -> Vec<u32> {
            sizes.iter().enumerate().flat_map(|(k, &n)| (0..n).map(move |p| (p + 1000 * k) as u32)).collect()
        };
        assert_eq!(super::super::cut_at_an_end(&slices(&[54, 77, 100, 77, 54]), 1000), None);
        let cut = super::super::cut_at_an_end(&slices(&[40, 77, 100, 95, 92]), 1000).unwrap();
        assert!(cut.starts_with("its last slice holds 92 pixels, 92 % of its largest"), "{cut}");
    }

    /// The distance transform is the brute force's, on an image with features in clusters, alone
    /// on a row or a column, and none at all.
    #[test]
    fn squared_distances_are_the_nearest_features() {
        let (columns, rows) = (23, 17);
        let feature: Vec<bool> = (0..columns * rows).map(|p| (p * 7919) % 97 < 3 || p == 5 + 23 * 9).collect();
        let d = squared_distances(&feature, columns, rows);
        for (p, &distance) in d.iter().enumerate() {
            let brute = (0..columns * rows)
                .filter(|&f| feature[f])
                .map(|f| (f % columns).abs_diff(p % columns).pow(2) + (f / columns).abs_diff(p / columns).pow(2))
                .min()
                .unwrap();
            assert_eq!(distance, brute as f64, "pixel {p}");
        }
        assert!(squared_distances(&[false; 12], 4, 3).iter().all(|d| d.is_infinite()));
    }

    /// A structure drawn every 2 mm in one part and every 4 mm (or 6 mm) in another takes the
    /// shapes between its contours where it was not drawn, a cone drawn at its ends only keeps its
    /// taper.
    #[test]
    fn slices_between_contours_take_the_shapes_between_them() {
        // Squares of side 10, 8, 6, 4 and 2 mm at z = 0, 2, 4, 8 and 14 mm; slices 2 mm apart.
        let drawn = [(0.0, 10.0), (2.0, 8.0), (4.0, 6.0), (8.0, 4.0), (14.0, 2.0)];
        let contours: Vec<(u32, &str, Vec<Point>)> =
            drawn.iter().map(|&(z, side)| (1, "CLOSED_PLANAR", square(0.0, 0.0, z, side, false))).collect();
        let map = parse_dicom(&rt_struct(&[(1, "pyramid"), (2, "empty")], &contours), None).unwrap();
        let (pyramid, _) = map.select("pyramid").unwrap();
        // In pixels of 1 mm: z = 0, 2, 4 as drawn; 6 halfway from 6 to 4 mm (5 mm: the lower's 6
        // where the sides are as near, its corners, farther from the 4 mm square, left out); 8 as
        // drawn; 10 and 12 a third and two thirds of the way from 4 to 2 mm; 14 as drawn.
        assert_eq!(pixels_per_slice(&pyramid), [0, 100, 64, 36, 32, 16, 16, 4, 4, 0]);
        assert!(map.warnings.iter().any(|(_, w)| w == "'empty' has no contour"), "{:?}", map.warnings);
        let e = map.select("empty").unwrap_err().to_string();
        assert!(e.contains("label 2 ('empty') has no voxel ('empty' has no contour)"), "{e}");

        // A cone from a 12 mm radius at z = 2 to 4 mm at z = 18, drawn on its first two slices,
        // then at its end only.
        let circle = |z: f64, r: f64| -> Vec<Point> {
            (0..64)
                .map(|i| (i as f64 * std::f64::consts::TAU / 64.0).sin_cos())
                .map(|(s, c)| [r * c, r * s, z])
                .collect()
        };
        let contours: Vec<(u32, &str, Vec<Point>)> =
            [(0.0, 12.0), (2.0, 12.0), (18.0, 4.0)].iter().map(|&(z, r)| (1, "CLOSED_PLANAR", circle(z, r))).collect();
        let cone = parse_dicom(&rt_struct(&[(1, "cone")], &contours), None).unwrap().select("cone").unwrap().0;
        // Each slice between holds its circle's area, to half a pixel of radius (nearest-slice
        // filling would be 4 to 8 mm off).
        let counts = pixels_per_slice(&cone);
        for (j, &count) in counts[3..10].iter().enumerate() {
            let (r, filled) = (11.0 - j as f64, (count as f64 / std::f64::consts::PI).sqrt());
            assert!((filled - r).abs() < 0.5, "z = {} mm: radius {filled:.2} mm for {r} mm, {counts:?}", 4 + 2 * j);
        }
    }

    /// The inside pixels of each slice of a labelmap.
    fn pixels_per_slice(map: &crate::labelmap::VoxelMask) -> Vec<usize> {
        let frame = map.dims[0] * map.dims[1];
        (0..map.dims[2]).map(|k| map.inside[k * frame..(k + 1) * frame].iter().filter(|&&i| i).count()).collect()
    }
}
