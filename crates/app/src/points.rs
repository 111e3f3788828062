//! Points read at a command's boundary, in any of the formats a user has (CSV, 3D Slicer's
//! `.fcsv` and `.mrk.json`, and for clouds `.npy`, `.ply` and the points of a model file: `.vtk`,
//! `.vtu`, `.stl`, `.obj`), brought into the one frame and the one unit the command works in.
//!
//! The frame policy: a command works in the frame of its organ (a surface's `SPACE=` header, or
//! the frame its targets file names). Points whose file names the other frame (RAS or LPS; a
//! model file in its `SPACE=` header, as 3D Slicer writes it) are
//! converted (x and y negated); points whose file names none are taken as being in the working
//! frame, or in the frame the user gives (`--frame`). When the organ's frame is not known, the
//! first point file to name one gives it, and a later file that names the other frame is refused:
//! which of the two the organ is in cannot be told.
//! Units: a file that names its unit (`.fcsv`, `.mrk.json`, CSV headers `x_mm`) is read in it;
//! other files in the unit the user gives (`--units`).

use std::path::Path;

use anyhow::Result;
use mesh::io::points::{read_points, LabelledPoints};
use mesh::io::Frame;
use mesh::length::LengthUnit;
use mesh::Point;

/// Where points read by a command go: its working frame (once known) and its working unit, and
/// the unit of files that name none.
#[derive(Clone, Debug, PartialEq)]
pub struct PointInput {
    /// The working frame: `None` until the organ or a file names one.
    pub frame: Option<Frame>,
    /// The unit the command works in.
    pub unit: LengthUnit,
    /// The unit of files that name none (the user's `--units`).
    pub given: LengthUnit,
    /// The frame of files that name none (the user's `--frame`; `None`: the working frame).
    pub given_frame: Option<Frame>,
    /// What named the working frame when the organ did not: a file, or `--frame`.
    named_by: Option<String>,
    /// What the files read hold that was left out (control points not placed), a line each.
    pub warnings: Vec<String>,
}

impl PointInput {
    /// An input into `frame` (when known) and `unit`, files naming no unit being in `given`.
    pub fn new(frame: Option<Frame>, unit: LengthUnit, given: LengthUnit) -> PointInput {
        PointInput { frame, unit, given, given_frame: None, named_by: None, warnings: Vec::new() }
    }

    /// The same input, files that name no frame being in `frame` (`None`: the working frame).
    /// Where the organ names no frame, `frame` names the working one: a file naming the other is
    /// then refused, as the results are written in `frame`.
    pub fn with_given_frame(self, frame: Option<Frame>) -> PointInput {
        let named_by = match (self.frame, frame) {
            (None, Some(given)) => Some(format!("--frame {given}")),
            _ => self.named_by,
        };
        PointInput { frame: self.frame.or(frame), given_frame: frame, named_by, ..self }
    }

    /// The working frame and what named it, when a file or `--frame` did rather than the organ.
    pub fn named_frame(&self) -> Option<(Frame, &str)> {
        self.frame.zip(self.named_by.as_deref())
    }

    /// Reads a points file (CSV, `.fcsv`, `.mrk.json`) with its labels, in the working frame and
    /// unit; its own frame becomes the working frame when there was none.
    pub fn read(&mut self, path: &Path) -> Result<LabelledPoints> {
        self.place(path, read_points(path)?)
    }

    /// Points read from `path`, in the working frame and unit (their frame becoming the working
    /// frame when there was none); an error when the organ names no frame and they name another
    /// than the file that gave the working frame.
    fn place(&mut self, path: &Path, mut points: LabelledPoints) -> Result<LabelledPoints> {
        self.warnings.extend(reading_warnings(path, &points));
        let namer = match (points.frame, self.given_frame) {
            (Some(_), _) => path.display().to_string(),
            (None, Some(given)) => format!("--frame {given}"),
            (None, None) => String::new(),
        };
        points.frame = points.frame.or(self.given_frame);
        match (points.frame, self.frame, &self.named_by) {
            (Some(own), Some(working), Some(first)) if own != working => anyhow::bail!(
                "{namer} gives the frame {own} where {first} gave {working}, and the organ names none: which \
                 one is the organ in? Name its frame (a SPACE= header, a targets file from 3D Slicer), or give \
                 every point in one frame"
            ),
            (Some(_), None, _) => self.named_by = Some(namer),
            _ => {}
        }
        self.frame = self.frame.or(points.frame);
        points.convert(self.frame, self.unit, self.given);
        Ok(points)
    }

    /// Reads the true target positions of a run of `frames` clouds: one points file, or a
    /// directory of one file per frame (in file-name order), as [`PointInput::read`]. Where the
    /// targets (`labels`) and a file are labelled throughout, its points are taken by label, in
    /// the targets' order; otherwise row by row.
    pub fn read_truths(&mut self, path: &Path, frames: usize, labels: &[String]) -> Result<Vec<Vec<Point>>> {
        let files = register::cloud::read_points_frames(path)?;
        if files.len() != frames {
            anyhow::bail!("{} truth file(s) for {frames} cloud frame(s)", files.len());
        }
        let mut truths = Vec::with_capacity(files.len());
        for file in &files {
            let truth = self.read(file)?;
            let warning = pairing_warning(file, &truth.labels, labels);
            if let Some(w) = warning.filter(|w| !self.warnings.contains(w)) {
                self.warnings.push(w);
            }
            truths.push(by_label(file, truth, labels)?);
        }
        Ok(truths)
    }

    /// Reads an intraoperative cloud: a points file as [`PointInput::read`], or a cloud of
    /// positions alone ([`register::cloud::holds_positions_only`]: it names no unit; a model
    /// file's `SPACE=` tag names its frame) in the given unit. An empty cloud is an error.
    pub fn read_cloud(&mut self, path: &Path) -> register::Result<Vec<Point>> {
        let points = if register::cloud::holds_positions_only(path) {
            let mut points = LabelledPoints::new(register::cloud::read_point_cloud(path)?);
            points.frame = mesh::io::surface_frame(path)?;
            points
        } else {
            read_points(path)?
        };
        let points = self.place(path, points).map_err(|e| register::RegisterError::Invalid(format!("{e:#}")))?.points;
        register::cloud::check_points(path, points)
    }
}

/// The warning for a truth file (`path`, labelled `truth`) that cannot be paired with the targets
/// (`targets`) by label, though one of them labels some points: they are paired row by row.
fn pairing_warning(path: &Path, truth: &[String], targets: &[String]) -> Option<String> {
    let count = |l: &[String]| l.iter().filter(|l| !l.is_empty()).count();
    let (t, g) = (count(truth), count(targets));
    let whole = |n: usize, l: &[String]| n > 0 && n == l.len();
    if (whole(t, truth) && whole(g, targets)) || (t == 0 && g == 0) {
        return None;
    }
    Some(format!(
        "{}: the truth labels {t} of its {} points, the targets {g}: paired with the targets row by row, not by \
         label (label every point of both files, or of neither, to be sure of the pairing)",
        path.display(),
        truth.len(),
    ))
}

/// The points of `truth` (read from `path`) in the order of the targets' `labels` when both are
/// labelled throughout (an error for a label missing from either or given twice), else as read.
fn by_label(path: &Path, truth: LabelledPoints, labels: &[String]) -> Result<Vec<Point>> {
    let labelled = |l: &[String]| !l.is_empty() && l.iter().all(|l| !l.is_empty());
    if !(labelled(labels) && labelled(&truth.labels)) {
        return Ok(truth.points);
    }
    let mut at = std::collections::HashMap::new();
    for (i, label) in truth.labels.iter().enumerate() {
        if at.insert(label.as_str(), i).is_some() {
            anyhow::bail!("{}: the label `{label}` is given twice", path.display());
        }
    }
    if let Some(extra) = truth.labels.iter().find(|l| !labels.contains(l)) {
        anyhow::bail!("{}: `{extra}` is no target's label (the targets are {})", path.display(), labels.join(", "));
    }
    labels
        .iter()
        .map(|label| match at.get(label.as_str()) {
            Some(&i) => Ok(truth.points[i]),
            None if truth.unplaced.contains(label) => anyhow::bail!(
                "{}: `{label}` is not placed (its positionStatus in 3D Slicer is undefined, preview or missing): place \
                 it, or leave the target out",
                path.display()
            ),
            None => anyhow::bail!("{}: no point is labelled `{label}`, a target's label", path.display()),
        })
        .collect()
}

/// A targets file (CSV, `.fcsv`, `.mrk.json`) with its rest positions in metres: read in the unit
/// the file names, else in `unit`; as they are in their own frame, which the file may name (the
/// frame the registration works in). With them, what a user should know of them as read
/// (control points left out as not placed, several point lists read as one).
pub fn read_targets(path: &Path, unit: LengthUnit) -> Result<(LabelledPoints, Vec<String>)> {
    let mut points = read_points(path)?;
    check_targets(path, &points)?;
    points.convert(None, LengthUnit::Metre, unit);
    let warnings = reading_warnings(path, &points);
    Ok((points, warnings))
}

/// Refuses the targets `points` read from `path` that hold none (a header alone, control points
/// none of which is placed) or a label twice: a label names one target (in the results, in 3D
/// Slicer, on the navigation system's stream).
pub fn check_targets(path: &Path, points: &LabelledPoints) -> Result<()> {
    if points.points.is_empty() {
        let unplaced =
            if points.unplaced.is_empty() { "" } else { " (none of its control points is placed in 3D Slicer)" };
        anyhow::bail!("{} holds no targets{unplaced}", path.display());
    }
    let mut seen = std::collections::HashMap::new();
    for (i, label) in points.labels.iter().enumerate().filter(|(_, l)| !l.is_empty()) {
        if let Some(first) = seen.insert(label.as_str(), i) {
            let lists = points.merged_lists_warning().map(|w| format!(" ({w})")).unwrap_or_default();
            anyhow::bail!(
                "{}: the label `{label}` names two targets (points {} and {}){lists}",
                path.display(),
                first + 1,
                i + 1
            );
        }
    }
    Ok(())
}

/// What a user should know of `points` as read from `path` ([`LabelledPoints::warnings`]), each
/// naming the file.
fn reading_warnings(path: &Path, points: &LabelledPoints) -> Vec<String> {
    points.warnings().into_iter().map(|w| format!("{}: {w}", path.display())).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clouds_and_points_come_in_the_working_frame_and_unit() {
        let dir = tempfile::tempdir().unwrap();
        let ras = dir.path().join("cloud.mrk.json");
        std::fs::write(
            &ras,
            r#"{"markups": [{"coordinateSystem": "RAS", "controlPoints": [{"label": "p", "position": [10, 20, 30]},
                {"label": "q", "position": [0, 0, 0], "positionStatus": "undefined"}]}]}"#,
        )
        .unwrap();
        let unplaced = format!(
            "{}: 1 control point not placed in 3D Slicer (positionStatus undefined, preview or missing) is left out: q",
            ras.display()
        );
        let (targets, warning) = read_targets(&ras, LengthUnit::Metre).unwrap();
        assert_eq!((targets.points, targets.labels), (vec![[0.01, 0.02, 0.03]], vec!["p".to_string()]));
        assert_eq!(
            (targets.frame, targets.unit, warning),
            (Some(Frame::Ras), Some(LengthUnit::Metre), vec![unplaced.clone()])
        );
        // A label names one target: two named alike are refused (unlabelled points are not).
        let twice = dir.path().join("twice.csv");
        std::fs::write(&twice, "label,x,y,z\na,1,2,3\nb,1,2,3\na,4,5,6\n").unwrap();
        let e = read_targets(&twice, LengthUnit::Metre).unwrap_err().to_string();
        assert!(e.ends_with("twice.csv: the label `a` names two targets (points 1 and 3)"), "{e}");
        std::fs::write(&twice, "x,y,z\n1,2,3\n1,2,3\n").unwrap();
        assert!(read_targets(&twice, LengthUnit::Metre).is_ok());
        // A markups file of two point lists is read as one, and says so; their labels must differ.
        let lists = dir.path().join("lists.mrk.json");
        let list = |label: &str| format!(r#"{{"controlPoints": [{{"label": "{label}", "position": [1, 2, 3]}}]}}"#);
        std::fs::write(&lists, format!(r#"{{"markups": [{}, {}]}}"#, list("a"), list("b"))).unwrap();
        let (targets, warnings) = read_targets(&lists, LengthUnit::Metre).unwrap();
        assert_eq!(targets.labels, ["a", "b"]);
        assert!(
            warnings[0].ends_with(
                "its 2 point lists (1, 1 points) are read as one list of 2, in that order: \
             save the one meant alone if the others are not part of it"
            ),
            "{warnings:?}"
        );
        std::fs::write(&lists, format!(r#"{{"markups": [{}, {}]}}"#, list("a"), list("a"))).unwrap();
        let e = read_targets(&lists, LengthUnit::Metre).unwrap_err().to_string();
        assert!(e.contains("names two targets (points 1 and 2) (its 2 point lists"), "{e}");
        let plain = dir.path().join("truth.csv");
        std::fs::write(&plain, "x,y,z\n1,2,3\n").unwrap();
        let mut input = PointInput::new(Some(Frame::Lps), LengthUnit::Metre, LengthUnit::Millimetre);
        assert_eq!(input.read_cloud(&ras).unwrap(), [[-0.01, -0.02, 0.03]]);
        assert_eq!(input.warnings, [unplaced], "the placeholder left out, said");
        assert_eq!(input.read(&plain).unwrap().points, [[1e-3, 2e-3, 3e-3]], "no named unit: the given one");
        // No working frame: the first file to name one gives it.
        let mut input = PointInput::new(None, LengthUnit::Millimetre, LengthUnit::Millimetre);
        assert_eq!(input.read(&plain).unwrap().points, [[1.0, 2.0, 3.0]]);
        assert_eq!(input.read(&ras).unwrap().labels, ["p"]);
        assert_eq!(input.frame, Some(Frame::Ras));
        // The organ names no frame and a file named RAS: one naming LPS cannot be placed.
        let lps = dir.path().join("truth.fcsv");
        let mut points = LabelledPoints::new(vec![[1.0, 2.0, 3.0]]);
        points.frame = Some(Frame::Lps);
        mesh::io::points::write_points(&lps, &points).unwrap();
        let refused = input.read(&lps).unwrap_err().to_string();
        assert!(
            refused.contains("gives the frame LPS where") && refused.contains("cloud.mrk.json gave RAS"),
            "{refused}"
        );
        // Where the organ names its frame, the other one is converted.
        let mut input = PointInput::new(Some(Frame::Ras), LengthUnit::Millimetre, LengthUnit::Millimetre);
        assert_eq!(input.read(&lps).unwrap().points, [[-1.0, -2.0, 3.0]]);
        assert_eq!(input.read_truths(&plain, 1, &[]).unwrap(), [[[1.0, 2.0, 3.0]]]);
        let two = input.read_truths(&plain, 2, &[]).unwrap_err().to_string();
        assert!(two.contains("1 truth file(s) for 2 cloud frame(s)"), "{two}");
        // Files that name no frame, in the frame given.
        let mut input = PointInput::new(Some(Frame::Lps), LengthUnit::Millimetre, LengthUnit::Millimetre)
            .with_given_frame(Some(Frame::Ras));
        assert_eq!(input.read(&plain).unwrap().points, [[-1.0, -2.0, 3.0]]);
        let npy = dir.path().join("cloud.npy");
        mesh::io::npy::write_f64(&npy, &[1, 3], &[1.0, 2.0, 3.0]).unwrap();
        assert_eq!(input.read_cloud(&npy).unwrap(), [[-1.0, -2.0, 3.0]]);
        let empty = dir.path().join("empty.csv");
        std::fs::write(&empty, "x,y,z\n").unwrap();
        assert!(input.read_cloud(&empty).is_err());
        std::fs::write(&plain, "label,x_mm,y_mm,z_mm\nT,1,2,3\n").unwrap();
        assert_eq!(
            read_targets(&plain, LengthUnit::Metre).unwrap().0.points,
            [[1e-3, 2e-3, 3e-3]],
            "the named unit wins"
        );
    }

    /// A CSV cloud is read exactly, by its header's columns in any order and case; its errors
    /// name the file and the line.
    #[test]
    fn a_csv_cloud_is_read_by_its_header() {
        let dir = tempfile::tempdir().unwrap();
        let mut input = PointInput::new(None, LengthUnit::Metre, LengthUnit::Metre);
        let path = dir.path().join("cloud.csv");
        let sample = [[0.0, -0.0, 1.0], [0.1, 1.0 / 3.0, -123456.789], [1e-300, f64::MIN_POSITIVE, 5e-324]];
        mesh::io::points::write_points_csv(&path, &sample).unwrap();
        let bits = |points: &[Point]| points.iter().map(|p| p.map(f64::to_bits)).collect::<Vec<_>>();
        assert_eq!(bits(&input.read_cloud(&path).unwrap()), bits(&sample));
        let mut read = |name: &str, text: &str| {
            let path = dir.path().join(name);
            std::fs::write(&path, text).unwrap();
            input.read_cloud(&path).map_err(|e| e.to_string())
        };
        let other_order = read("targets.CSV", "z, id ,X,y\r\n3,7,1,2\r\n\r\n -6 , 8, -4 ,-5\n\n");
        assert_eq!(other_order, Ok(vec![[1.0, 2.0, 3.0], [-4.0, -5.0, -6.0]]));
        let refused = [
            ("nox.csv", "a,y,z\n1,2,3\n", &["nox.csv", "line 1", "'x'"][..]),
            ("bad.csv", "x,y,z\n1,2,3\n\n4,abc,6\n", &["bad.csv", "line 4", "y", "\"abc\"", "not a number"]),
            ("count.csv", "x,y,z\n1,2,3\n4,5\n", &["line 3", "2 fields", "3 columns"]),
            ("nan.csv", "x,y,z\n1,2,3\n4,NaN,6\n", &["line 3", "not finite"]),
            ("inf.csv", "x,y,z\n-inf,2,3\n", &["line 2", "not finite"]),
            ("header_only.csv", "x,y,z\n\n", &["header_only.csv", "no points"]),
            ("empty.csv", "", &["no points"]),
        ];
        for (name, text, parts) in refused {
            let message = read(name, text).unwrap_err();
            assert!(parts.iter().all(|part| message.contains(part)), "{message:?} should contain {parts:?}");
        }
    }

    /// A truth file labelled as the targets are is taken by label, whatever its rows' order; one
    /// whose labels differ is refused; one without labels is taken row by row.
    #[test]
    fn truths_are_matched_to_the_targets_by_label() {
        let dir = tempfile::tempdir().unwrap();
        let truth = dir.path().join("truth.csv");
        let labels: Vec<String> = ["A", "B", "C"].map(String::from).to_vec();
        let mut input = PointInput::new(None, LengthUnit::Millimetre, LengthUnit::Millimetre);
        let mut read = |text: &str, labels: &[String]| {
            std::fs::write(&truth, text).unwrap();
            input.read_truths(&truth, 1, labels).map_err(|e| e.to_string())
        };
        let reversed = "label,x,y,z\nC,3,0,0\nB,2,0,0\nA,1,0,0\n";
        let in_order = vec![vec![[1.0, 0.0, 0.0], [2.0, 0.0, 0.0], [3.0, 0.0, 0.0]]];
        assert_eq!(read(reversed, &labels), Ok(in_order.clone()));
        let rows = vec![vec![[3.0, 0.0, 0.0], [2.0, 0.0, 0.0], [1.0, 0.0, 0.0]]];
        assert_eq!(read(reversed, &[]), Ok(rows.clone()), "unlabelled targets: row by row");
        assert_eq!(read("x,y,z\n3,0,0\n2,0,0\n1,0,0\n", &labels), Ok(rows), "unlabelled truth: row by row");
        let other = read("label,x,y,z\nQ1,3,0,0\nB,2,0,0\nA,1,0,0\n", &labels).unwrap_err();
        assert!(other.ends_with("truth.csv: `Q1` is no target's label (the targets are A, B, C)"), "{other}");
        let twice = read("label,x,y,z\nA,3,0,0\nB,2,0,0\nA,1,0,0\n", &labels).unwrap_err();
        assert!(twice.ends_with("truth.csv: the label `A` is given twice"), "{twice}");
        let missing = read("label,x,y,z\nB,2,0,0\nA,1,0,0\n", &labels).unwrap_err();
        assert!(missing.ends_with("truth.csv: no point is labelled `C`, a target's label"), "{missing}");
        // A point left unplaced in 3D Slicer is said to be so.
        let markups = dir.path().join("truth.mrk.json");
        std::fs::write(
            &markups,
            r#"{"markups": [{"controlPoints": [{"label": "A", "position": [1, 0, 0]}, {"label": "B", "position": [2, 0, 0]},
               {"label": "C", "positionStatus": "undefined", "position": [0, 0, 0]}]}]}"#,
        )
        .unwrap();
        let unplaced = input.read_truths(&markups, 1, &labels).unwrap_err().to_string();
        assert!(unplaced.contains("`C` is not placed (its positionStatus in 3D Slicer is undefined"), "{unplaced}");
        // Each pairing row by row where one file labels points is said.
        let said: Vec<&str> = input.warnings.iter().filter_map(|w| w.rsplit_once("truth.csv: ")).map(|w| w.1).collect();
        let paired = ": paired with the targets row by row, not by label (label every point of both files";
        assert_eq!(said.len(), 2, "{said:?}");
        assert!(said[0].starts_with(&format!("the truth labels 3 of its 3 points, the targets 0{paired}")), "{said:?}");
        assert!(said[1].starts_with(&format!("the truth labels 0 of its 3 points, the targets 3{paired}")), "{said:?}");
    }

    #[test]
    fn a_cloud_saved_as_a_model_comes_in_the_frame_its_header_names() {
        let dir = tempfile::tempdir().unwrap();
        let triangle = mesh::TriSurface {
            vertices: vec![[10.0, 20.0, 30.0], [11.0, 20.0, 30.0], [10.0, 21.0, 30.0]],
            triangles: vec![[0, 1, 2]],
        };
        let ras = dir.path().join("cloud.vtk");
        mesh::io::write_surface_in_frame(&ras, &triangle, Frame::Ras).unwrap();
        let mut input = PointInput::new(Some(Frame::Lps), LengthUnit::Metre, LengthUnit::Millimetre);
        assert_eq!(
            input.read_cloud(&ras).unwrap(),
            [[-0.010, -0.020, 0.030], [-0.011, -0.020, 0.030], [-0.010, -0.021, 0.030]],
            "RAS millimetres into LPS metres"
        );
        let ply = dir.path().join("cloud.ply");
        let header = "ply\nformat ascii 1.0\ncomment SPACE=RAS\nelement vertex 1\nproperty float x\n\
                      property float y\nproperty float z\nend_header\n";
        std::fs::write(&ply, format!("{header}10 20 30\n")).unwrap();
        assert_eq!(input.read_cloud(&ply).unwrap(), [[-0.010, -0.020, 0.030]], "a PLY's comment names its frame");
        let vtp = dir.path().join("cloud.vtp");
        let space = "<FieldData><Array type=\"String\" Name=\"SPACE\" NumberOfTuples=\"1\" format=\"ascii\">\
                     82 65 83 0</Array></FieldData>";
        let piece = "<Piece NumberOfPoints=\"1\" NumberOfVerts=\"0\" NumberOfPolys=\"0\"><Points>\
                     <DataArray type=\"Float64\" NumberOfComponents=\"3\" format=\"ascii\">10 20 30</DataArray>\
                     </Points></Piece>";
        let xml = format!("<VTKFile type=\"PolyData\"><PolyData>{space}{piece}</PolyData></VTKFile>");
        std::fs::write(&vtp, xml).unwrap();
        assert_eq!(input.read_cloud(&vtp).unwrap(), [[-0.010, -0.020, 0.030]], "a VTP's field data names its frame");
        // A model file without a header names no frame: the working one (or --frame).
        let obj = dir.path().join("cloud.obj");
        mesh::io::write_obj(&obj, &triangle).unwrap();
        assert_eq!(input.read_cloud(&obj).unwrap()[0], [0.010, 0.020, 0.030]);
        let mut input = input.with_given_frame(Some(Frame::Ras));
        assert_eq!(input.read_cloud(&obj).unwrap()[0], [-0.010, -0.020, 0.030]);
        // Where the organ names no frame, the model's header gives it.
        let mut input = PointInput::new(None, LengthUnit::Millimetre, LengthUnit::Millimetre);
        assert_eq!(input.read_cloud(&ras).unwrap()[0], [10.0, 20.0, 30.0]);
        assert_eq!(input.frame, Some(Frame::Ras));
        // ... unless --frame names another, the frame the results will be written in: refused.
        let mut lps =
            PointInput::new(None, LengthUnit::Millimetre, LengthUnit::Millimetre).with_given_frame(Some(Frame::Lps));
        let refused = lps.read_cloud(&ras).unwrap_err().to_string();
        assert!(refused.contains("gives the frame RAS where --frame LPS gave LPS"), "{refused}");
        let garbage = dir.path().join("cloud.stl");
        std::fs::write(&garbage, "solid x\nendsolid x\n").unwrap();
        let refused = input.read_cloud(&garbage).unwrap_err().to_string();
        assert!(refused.contains("cloud.stl"), "{refused}");
    }
}
