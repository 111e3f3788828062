//! Patient coordinate frames: RAS (3D Slicer's internal frame, the one OpenIGTLink streams) and
//! LPS (DICOM's, in which Slicer 4.11 and later save models and markups), and the `SPACE=` tag by
//! which a surface file's header names one.

use std::fmt;
use std::fs::File;
use std::io::Read as _;
use std::path::Path;

use crate::length::LengthUnit;
use crate::{MeshError, Point, TriSurface};

/// An anatomical coordinate frame, named by where its axes point: RAS has x towards the patient's
/// right, y anterior, z superior; LPS has x towards the left, y posterior, z superior. The two
/// differ by the sign of x and y.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub enum Frame {
    /// Right, anterior, superior: 3D Slicer's internal frame and OpenIGTLink's.
    #[serde(rename = "RAS")]
    Ras,
    /// Left, posterior, superior: DICOM's, and the frame of Slicer's files since 4.11.
    #[serde(rename = "LPS")]
    Lps,
}

impl Frame {
    /// Its name: "RAS" or "LPS".
    pub fn name(self) -> &'static str {
        match self {
            Frame::Ras => "RAS",
            Frame::Lps => "LPS",
        }
    }

    /// `p`, given in this frame, in frame `to` (x and y negated when the frames differ).
    pub fn convert(self, to: Frame, p: Point) -> Point {
        if self == to {
            p
        } else {
            [-p[0], -p[1], p[2]]
        }
    }

    /// Converts `points` from this frame to frame `to` in place.
    pub fn convert_all(self, to: Frame, points: &mut [Point]) {
        if self != to {
            points.iter_mut().for_each(|p| *p = self.convert(to, *p));
        }
    }
}

/// The change from the frame points are given in to the frame an organ is in: x and y negated
/// when both frames are known and differ, nothing otherwise. It is its own inverse, so the same
/// change brings results back.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct FrameChange {
    flips: bool,
}

impl FrameChange {
    /// The change from `from` to `to` (none when either is unknown).
    pub fn between(from: Option<Frame>, to: Option<Frame>) -> FrameChange {
        FrameChange { flips: matches!((from, to), (Some(a), Some(b)) if a != b) }
    }

    /// Whether it negates x and y.
    pub fn flips(self) -> bool {
        self.flips
    }

    /// A point (or a vector) changed.
    pub fn point(self, p: Point) -> Point {
        if self.flips {
            [-p[0], -p[1], p[2]]
        } else {
            p
        }
    }

    /// A rigid transform (homogeneous 4 × 4, acting on points of the one frame) as it acts on
    /// points of the other: S M S with S = diag(−1, −1, 1, 1) when the change flips.
    pub fn transform(self, m: [[f64; 4]; 4]) -> [[f64; 4]; 4] {
        let s = |i: usize| if self.flips && i < 2 { -1.0 } else { 1.0 };
        std::array::from_fn(|i| std::array::from_fn(|j| s(i) * s(j) * m[i][j]))
    }
}

/// Coordinates given from outside (a cloud, a stream, arrays from Python) against the organ's:
/// their unit, and the change between their frame and the organ's. Results go back through the
/// same (the change is its own inverse).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct GivenCoordinates {
    /// Their unit.
    pub unit: LengthUnit,
    /// From their frame to the organ's, and back.
    pub change: FrameChange,
}

impl From<LengthUnit> for GivenCoordinates {
    /// Coordinates in `unit`, in the organ's frame.
    fn from(unit: LengthUnit) -> Self {
        GivenCoordinates { unit, change: FrameChange::default() }
    }
}

impl GivenCoordinates {
    /// A given point (or vector) in the organ's frame, in metres.
    pub fn point_in(self, p: Point) -> Point {
        self.change.point(self.unit.point_to_metres(p))
    }

    /// A point (or vector) of the organ's frame, in metres, as given.
    pub fn point_out(self, p: Point) -> Point {
        self.unit.point_from_metres(self.change.point(p))
    }

    /// A length (m) in the given unit.
    pub fn length_out(self, metres: f64) -> f64 {
        self.unit.from_metres(metres)
    }

    /// A rigid transform of the organ's frame (homogeneous 4 × 4, rows, its translation in m) as
    /// it acts on given coordinates.
    pub fn transform_out(self, m: [[f64; 4]; 4]) -> [[f64; 4]; 4] {
        let mut t = self.change.transform(m);
        (0..3).for_each(|r| t[r][3] = self.unit.from_metres(t[r][3]));
        t
    }
}

impl fmt::Display for Frame {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for Frame {
    type Err = String;

    /// "RAS" or "LPS", any case.
    fn from_str(name: &str) -> Result<Frame, String> {
        match name.trim().to_ascii_uppercase().as_str() {
            "RAS" => Ok(Frame::Ras),
            "LPS" => Ok(Frame::Lps),
            other => Err(format!("unknown coordinate system '{other}' (expected RAS or LPS)")),
        }
    }
}

/// The frame that a header names by a `SPACE=RAS` or `SPACE=LPS` tag (any case), as 3D Slicer
/// writes it in the header of STL and legacy VTK files; `None` without a tag, an error for a
/// tag naming another frame.
pub fn frame_in_header(header: &str) -> Result<Option<Frame>, String> {
    let upper = header.to_ascii_uppercase();
    let Some(at) = upper.find("SPACE=") else {
        return Ok(None);
    };
    let value: String = upper[at + 6..].chars().take_while(char::is_ascii_alphanumeric).collect();
    value.parse().map(Some).map_err(|e| format!("header tag SPACE={value}: {e}"))
}

/// The frame a surface file names, where 3D Slicer writes it: `SPACE=` in the 80-byte header
/// of a binary STL or the `solid` line of an ASCII one, in the title line (line 2) of a legacy
/// VTK file, in the `#` comments of an OBJ or the `comment` lines of a PLY header; the string
/// array `SPACE` of a `.vtp` or `.vtu` file's field data. Other formats name none.
pub fn surface_frame(path: impl AsRef<Path>) -> Result<Option<Frame>, MeshError> {
    let path = path.as_ref();
    if matches!(super::extension(path).as_str(), "vtp" | "vtu") {
        return super::vtk_xml::xml_frame(path);
    }
    match header_text(path)? {
        Some(header) => frame_in_header(&header).map_err(|message| MeshError::parse(path, message)),
        None => Ok(None),
    }
}

/// The unit an OBJ file's header comment names, as Materialise Mimics and 3-matic write it (and
/// 3D Slicer reads it): `vertex coordinates are measured in units, where 1 unit = 10.000000 mm`
/// (here cm); `None` for other files and an OBJ without it; an error for a unit that is none of
/// m, cm, mm and µm.
pub fn surface_unit(path: impl AsRef<Path>) -> Result<Option<LengthUnit>, MeshError> {
    const KEY: &str = "vertex coordinates are measured in units, where 1 unit =";
    let path = path.as_ref();
    if super::extension(path) != "obj" {
        return Ok(None);
    }
    let Some(header) = header_text(path)?.map(|h| h.to_ascii_lowercase()) else { return Ok(None) };
    let Some(at) = header.find(KEY) else { return Ok(None) };
    let mut words = header[at + KEY.len()..].split_whitespace();
    let (scale, unit) = (words.next().and_then(|w| w.parse::<f64>().ok()), words.next());
    let named = match (scale, unit) {
        (Some(scale), Some("mm")) => LengthUnit::ALL.into_iter().find(|u| (u.millimetres() / scale - 1.0).abs() < 1e-6),
        _ => None,
    };
    named.map(Some).ok_or_else(|| {
        let line = header[at..].lines().next().unwrap_or_default();
        MeshError::parse(path, format!("its header says \"{line}\": a unit none of m, cm, mm, µm; convert the file"))
    })
}

/// The header of a surface file where [`surface_frame`] and [`surface_unit`] look (`None` for a
/// format without one).
fn header_text(path: &Path) -> Result<Option<String>, MeshError> {
    let kind = super::extension(path);
    if !["stl", "vtk", "obj", "ply"].contains(&kind.as_str()) {
        return Ok(None);
    }
    // The headers are short: a binary STL's is 80 bytes, a VTK title at most 256 characters.
    let mut start = Vec::with_capacity(HEADER_BYTES);
    let io = |error| MeshError::Io { path: path.display().to_string(), error };
    File::open(path).and_then(|f| f.take(HEADER_BYTES as u64).read_to_end(&mut start)).map_err(io)?;
    let lines = || start.split(|&b| b == b'\n').map(<[u8]>::trim_ascii);
    let comments = |prefix: &[u8]| -> Vec<u8> {
        let header = lines().take_while(|l| !l.eq_ignore_ascii_case(b"end_header"));
        header.filter(|l| l.starts_with(prefix)).flat_map(|l| [l, b"\n"].concat()).collect()
    };
    let header = match kind.as_str() {
        "stl" => match lines().find(|l| !l.is_empty()) {
            Some(solid) if solid.get(..5).is_some_and(|s| s.eq_ignore_ascii_case(b"solid")) => solid.to_vec(),
            _ => start[..start.len().min(80)].to_vec(),
        },
        "vtk" => lines().nth(1).unwrap_or_default().to_vec(),
        "obj" => comments(b"#"),
        _ => comments(b"comment"),
    };
    Ok(Some(String::from_utf8_lossy(&header).into_owned()))
}

/// How much of a file [`header_text`] reads.
const HEADER_BYTES: usize = 1024;

/// Reads a surface ([`super::read_surface`]) and the frame it names ([`surface_frame`]); a
/// `.vtp` or `.vtu` file, which names it in its body, is read once for both, and so is a legacy
/// `.vtk` file, whose field data may name it too (a string array `SPACE`, as VTK saves a
/// Slicer model's).
pub fn read_surface_with_frame(path: impl AsRef<Path>) -> Result<(TriSurface, Option<Frame>), MeshError> {
    read_surface_noted(path).map(|(surface, frame, _)| (surface, frame))
}

/// [`read_surface_with_frame`], with what a user should know of the file as read, a line each (a
/// binary STL whose header's triangle count its size belies).
pub fn read_surface_noted(path: impl AsRef<Path>) -> Result<(TriSurface, Option<Frame>, Vec<String>), MeshError> {
    let path = path.as_ref();
    let lfs = |e| super::named_if_lfs(path, e);
    match super::extension(path).as_str() {
        "vtp" | "vtu" => {
            let (surface, frame) = super::vtk_xml::read_xml_surface_with_frame(path).map_err(lfs)?;
            Ok((surface, frame, Vec::new()))
        }
        "vtk" => {
            let (surface, space) = super::legacy_vtk::read_vtk_surface_and_space(path).map_err(lfs)?;
            let in_field = space.map(|s| frame_in_header(&format!("SPACE={}", s.trim()))).transpose();
            let in_field = in_field.map_err(|message| MeshError::parse(path, message))?.flatten();
            Ok((surface, surface_frame(path)?.or(in_field), Vec::new()))
        }
        _ => {
            let frame = surface_frame(path)?;
            let (surface, warnings) = super::read_surface_noting(path)?;
            Ok((surface, frame, warnings))
        }
    }
}

/// Writes a surface with its frame named in the header as 3D Slicer reads it: `.vtk` (binary
/// `POLYDATA`, title `augsim SPACE=…`), `.stl` (binary, header `augsim binary STL SPACE=…`) or
/// `.obj` (first comment `# augsim SPACE=…`). Other formats: an error.
pub fn write_surface_in_frame(path: impl AsRef<Path>, surface: &TriSurface, frame: Frame) -> Result<(), MeshError> {
    let path = path.as_ref();
    let title = format!("augsim SPACE={frame}");
    match super::extension(path).as_str() {
        "vtk" => super::legacy_vtk::write_surface_vtk_titled(path, surface, &title),
        "stl" => super::surface_io::write_stl_titled(path, surface, &format!("augsim binary STL SPACE={frame}")),
        "obj" => super::surface_io::write_obj_titled(path, surface, &title),
        _ => Err(MeshError::parse(
            path,
            format!("cannot name the frame {frame} in this format: write .vtk, .stl or .obj"),
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Materialise's unit comment in an OBJ names its unit; one of no unit augsim knows is refused;
    /// other files, and an OBJ without it, name none.
    #[test]
    fn an_obj_names_its_unit_as_mimics_writes_it() {
        let dir = tempfile::tempdir().unwrap();
        let obj = |name: &str, comment: &str| {
            let path = dir.path().join(name);
            std::fs::write(&path, format!("# Mimics export\n{comment}\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")).unwrap();
            surface_unit(path)
        };
        let says = |scale: &str| format!("# Vertex coordinates are measured in units, where 1 unit = {scale} mm");
        assert_eq!(obj("cm.obj", &says("10.000000")).unwrap(), Some(LengthUnit::Centimetre));
        assert_eq!(obj("m.obj", &says("1000.000000")).unwrap(), Some(LengthUnit::Metre));
        assert_eq!(obj("mm.obj", &says("1")).unwrap(), Some(LengthUnit::Millimetre));
        assert_eq!(obj("plain.obj", "# no unit").unwrap(), None);
        assert_eq!(obj("cm.stl", &says("10")).unwrap(), None);
        let e = obj("inch.obj", &says("25.4")).unwrap_err().to_string();
        assert!(e.contains("1 unit = 25.4 mm\": a unit none of m, cm, mm, µm"), "{e}");
    }

    #[test]
    fn lps_and_ras_differ_by_the_sign_of_x_and_y() {
        let p = [1.0, -2.0, 3.0];
        assert_eq!(Frame::Lps.convert(Frame::Ras, p), [-1.0, 2.0, 3.0]);
        assert_eq!(Frame::Ras.convert(Frame::Lps, Frame::Lps.convert(Frame::Ras, p)), p);
        assert_eq!(Frame::Ras.convert(Frame::Ras, p), p);
        let change = FrameChange::between(Some(Frame::Ras), Some(Frame::Lps));
        assert_eq!(change.point(p), Frame::Ras.convert(Frame::Lps, p));
        assert_eq!(FrameChange::between(None, Some(Frame::Lps)), FrameChange::default(), "an unknown frame: no change");
        assert!(!FrameChange::between(Some(Frame::Lps), Some(Frame::Lps)).flips());
        // A transform changed acts on changed points as the transform on the points.
        let m = [[0.0, -1.0, 0.0, 1.0], [1.0, 0.0, 0.0, 2.0], [0.0, 0.0, 1.0, 3.0], [0.0, 0.0, 0.0, 1.0]];
        let apply = |m: [[f64; 4]; 4], p: Point| {
            std::array::from_fn::<f64, 3, _>(|i| (0..3).map(|j| m[i][j] * p[j]).sum::<f64>() + m[i][3])
        };
        assert_eq!(apply(change.transform(m), change.point(p)), change.point(apply(m, p)));
        let mut points = vec![p, [0.5, 0.0, -1.0]];
        Frame::Ras.convert_all(Frame::Lps, &mut points);
        assert_eq!(points, [[-1.0, 2.0, 3.0], [-0.5, -0.0, -1.0]]);
        assert_eq!("lps".parse::<Frame>(), Ok(Frame::Lps));
        assert!("IJK".parse::<Frame>().unwrap_err().contains("IJK"));
    }

    /// A mesh written naming its frame reads back as it was, and names its frame as a surface
    /// file does (a `SPACE` string of the field data, where 3D Slicer reads it).
    #[test]
    fn a_volume_mesh_names_its_frame_in_its_field_data() {
        let dir = tempfile::tempdir().unwrap();
        let mut mesh = crate::box_tet([0.0; 3], [0.04, 0.02, 0.02], [2, 1, 1]).unwrap();
        mesh.regions.insert("top".into(), vec![0, 1]);
        let path = dir.path().join("organ.vtu");
        super::super::write_mesh_in_frame(&path, &mesh, &[], Some(Frame::Ras)).unwrap();
        assert_eq!(surface_frame(&path).unwrap(), Some(Frame::Ras));
        let back = super::super::read_mesh(&path).unwrap();
        assert_eq!((back.nodes, back.regions), (mesh.nodes.clone(), mesh.regions.clone()));
        super::super::write_mesh_in_frame(&path, &mesh, &[], None).unwrap();
        assert_eq!(surface_frame(&path).unwrap(), None);
    }

    /// Given coordinates in mm and RAS against an LPS organ: a point goes in and back out as it
    /// was; a transform given back acts on given points as it acts on the organ's (m).
    #[test]
    fn given_coordinates_convert_points_lengths_and_transforms_both_ways() {
        let given = GivenCoordinates {
            unit: LengthUnit::Millimetre,
            change: FrameChange::between(Some(Frame::Ras), Some(Frame::Lps)),
        };
        let p = [10.0, -20.0, 30.0];
        assert_eq!(given.point_in(p), [-0.01, 0.02, 0.03]);
        assert_eq!(given.point_out(given.point_in(p)), p);
        assert_eq!(given.length_out(0.0025), 2.5);
        let m = [[0.0, -1.0, 0.0, 0.001], [1.0, 0.0, 0.0, 0.002], [0.0, 0.0, 1.0, 0.003], [0.0, 0.0, 0.0, 1.0]];
        let apply = |m: [[f64; 4]; 4], p: Point| {
            std::array::from_fn::<f64, 3, _>(|i| (0..3).map(|j| m[i][j] * p[j]).sum::<f64>() + m[i][3])
        };
        let moved = apply(given.transform_out(m), p);
        let expected = given.point_out(apply(m, given.point_in(p)));
        assert!((0..3).all(|d| (moved[d] - expected[d]).abs() < 1e-12), "{moved:?} {expected:?}");
        assert_eq!(GivenCoordinates::from(LengthUnit::Metre), GivenCoordinates::default());
    }

    #[test]
    fn space_tags_are_found_anywhere_in_a_header() {
        assert_eq!(frame_in_header("solid SPACE=LPS"), Ok(Some(Frame::Lps)));
        assert_eq!(frame_in_header("3D Slicer output. space=ras"), Ok(Some(Frame::Ras)));
        assert_eq!(frame_in_header("SPACE=RAS\0\0\0"), Ok(Some(Frame::Ras)));
        assert_eq!(frame_in_header("vtk output"), Ok(None));
        assert!(frame_in_header("SPACE=IJK").unwrap_err().contains("SPACE=IJK"));
    }
}
