//! Point clouds as network input: vectors given at points (`[N, 6]`: x, y, z and the vector in the model's input
//! unit), read from `.csv` or `.npy`, and what a prediction reads ([`PredictInput`]: such a cloud, or a tensor
//! already on the model's grid) turned into the network's input.

use std::path::Path;

use mesh::io::csv::{number, Dialect, Header, Table};
use mesh::io::points::{column_unit, coordinate_unit};
use mesh::length::LengthUnit;
use mesh::Point;

use crate::data::grid::{encode_points, unfit_input, MAX_FIELD_VALUE};
use crate::model::LearnedModel;
use crate::{LearnError, Result};
use mesh::io::npy::{read_npy, NpyArray, NpyData};

/// Vectors at points (m; the vectors in the model's input unit: forces in N or displacements in m).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PointCloud {
    /// Positions.
    pub points: Vec<Point>,
    /// One vector per point.
    pub vectors: Vec<[f64; 3]>,
    /// The length unit a file named its vectors in (then displacements, read in m); `None`: not named.
    pub vector_unit: Option<LengthUnit>,
    /// What the file's header names its vectors: `Some(true)` forces (`fx, fy, fz`), `Some(false)`
    /// displacements (`ux, uy, uz` or `dx, dy, dz`, with or without a unit); `None`: neither.
    pub named_forces: Option<bool>,
}

/// A column's name without its unit (`ux_mm`, `fx_N`), lower case.
fn stem(name: &str) -> String {
    let unit = |u: &str| u.eq_ignore_ascii_case("n") || u.parse::<LengthUnit>().is_ok();
    name.rsplit_once('_').filter(|(_, u)| unit(u)).map_or(name, |(stem, _)| stem).to_ascii_lowercase()
}

/// Where a header's six columns hold x, y, z and the vector's x, y, z components, in that order:
/// the positions are the columns named `x`, `y`, `z` (with a unit or not), the vector's the other
/// three, by the axis their names end with (`fz`, `uy_mm`) where each names one (`u, v, w`: in
/// their order). `None` for a header that names no column `x`, `y` or `z` (its columns are taken in
/// order); an error for one that names an axis twice.
fn column_order(names: &[String]) -> std::result::Result<Option<[usize; 6]>, String> {
    let stems: Vec<String> = names.iter().map(|n| stem(n)).collect();
    let axis = |s: &str| ["x", "y", "z"].iter().position(|a| s.ends_with(a));
    let position = |s: &String| if s.len() == 1 { axis(s) } else { None };
    if names.len() != 6 || !stems.iter().any(|s| position(s).is_some()) {
        return Ok(None);
    }
    let twice = || {
        "the header names an axis twice: name the columns x, y, z and the vector's x, y and z components \
                    (fx, fy, fz for forces; ux, uy, uz for displacements)"
    };
    let mut order = [None; 6];
    let vectors: Vec<usize> = (0..6).filter(|&c| position(&stems[c]).is_none()).collect();
    for (column, s) in stems.iter().enumerate() {
        if let Some(a) = position(s) {
            if order[a].replace(column).is_some() {
                return Err(twice().into());
            }
        }
    }
    let by_axis = vectors.iter().all(|&c| axis(&stems[c]).is_some());
    for (k, &column) in vectors.iter().enumerate() {
        let slot = 3 + if by_axis { axis(&stems[column]).unwrap_or(k) } else { k };
        if vectors.len() != 3 || order[slot].is_some() {
            return Err(twice().into());
        }
        order[slot] = Some(column);
    }
    Ok(Some(order.map(|c| c.unwrap_or_default())))
}

/// Whether vector columns `names` name forces (`Some(true)`: fx, fy, fz), displacements
/// (`Some(false)`: ux, uy, uz or dx, dy, dz), each with or without a unit suffix, or neither.
fn vector_kind(names: &[String]) -> Option<bool> {
    let is = |prefix: &str| names.iter().zip(["x", "y", "z"]).all(|(n, axis)| stem(n) == format!("{prefix}{axis}"));
    match (is("f"), is("u") || is("d")) {
        (true, _) => Some(true),
        (_, true) => Some(false),
        _ => None,
    }
}

impl PointCloud {
    /// Parses CSV text ([`mesh::io::csv`]) with six numbers per line (x, y, z, vx, vy, vz), separated by commas
    /// or semicolons; blank lines and empty fields are skipped and a first line that is not numbers is a header.
    /// A header that names its columns `x`, `y`, `z` and the vector's by their axes (`fz`, `uy_mm`) puts them
    /// in order whatever their places; one that names no column `x`, `y` or `z` leaves them in theirs.
    /// A header whose first three columns are `x_mm, y_mm, z_mm` gives the positions in mm, and one whose
    /// last three end in `_mm` the vectors (displacements) too (`_m`: m); otherwise they are in m. Columns of
    /// one kind naming different units are an error. `path` names the text in errors, with the line number.
    pub fn parse_csv(text: &str, path: &Path) -> Result<PointCloud> {
        let bad = |line: Option<usize>, message: String| LearnError::Input { path: path.to_path_buf(), line, message };
        let dialect = Dialect { separators: &[',', ';'], header: Header::Optional };
        let table = Table::parse(text, &dialect).map_err(|e| bad(e.line, e.message))?;
        let header = |message: String| bad(table.header_line, format!("{message} in {:?}", table.names.join(",")));
        // The header's names put the columns in order: x, y, z, then the vector's.
        let order = column_order(&table.names).map_err(header)?.unwrap_or([0, 1, 2, 3, 4, 5]);
        let names: Vec<String> = match table.names.len() {
            6 => order.iter().map(|&c| table.names[c].clone()).collect(),
            _ => table.names.clone(),
        };
        let named = |columns: &[String]| columns.iter().any(|n| column_unit(n).is_some());
        let position_scale = match names.get(..3).map(|xyz| (coordinate_unit(xyz), named(xyz))) {
            Some((Ok(Some(unit)), _)) => unit.metres(),
            Some((Err(message), true)) => return Err(header(message)),
            _ => 1.0,
        };
        let vector_unit = match names.get(3..6).map(|v| v.iter().map(|n| column_unit(n)).collect::<Vec<_>>()) {
            Some(units) if units.iter().all(|u| *u == units[0]) => units[0],
            Some(_) => return Err(header("the vector columns name different units".into())),
            None => None,
        };
        let vector_scale = vector_unit.map_or(1.0, LengthUnit::metres);
        // A field is named in errors as the header names its column (`uy`, `fz_N`), if it names six.
        let columns: Vec<&str> = match names.len() {
            6 => names.iter().map(String::as_str).collect(),
            _ => vec!["x", "y", "z", "vx", "vy", "vz"],
        };
        let mut rows = Vec::new();
        for row in &table.rows {
            let fields: Vec<&String> = row.fields.iter().filter(|f| !f.is_empty()).collect();
            if fields.is_empty() {
                continue;
            }
            if fields.len() != 6 {
                let message = format!("{} numbers, expected 6 (x, y, z, vx, vy, vz)", fields.len());
                return Err(bad(Some(row.line), message));
            }
            let mut values = [0.0; 6];
            for (value, (&column, name)) in values.iter_mut().zip(order.iter().zip(&columns)) {
                *value = number(fields[column]).map_err(|m| bad(Some(row.line), format!("{name} {m}")))?;
            }
            values[..3].iter_mut().for_each(|v| *v *= position_scale);
            values[3..].iter_mut().for_each(|v| *v *= vector_scale);
            rows.push(values);
        }
        let named_forces = names.get(3..6).and_then(vector_kind);
        Ok(PointCloud { vector_unit, named_forces, ..PointCloud::from_rows(&rows) })
    }

    /// The cloud of `[x, y, z, vx, vy, vz]` rows.
    pub fn from_rows(rows: &[[f64; 6]]) -> PointCloud {
        PointCloud {
            points: rows.iter().map(|r| [r[0], r[1], r[2]]).collect(),
            vectors: rows.iter().map(|r| [r[3], r[4], r[5]]).collect(),
            vector_unit: None,
            named_forces: None,
        }
    }

    /// Number of points.
    pub fn len(&self) -> usize {
        self.points.len()
    }

    /// Whether there is no point.
    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }
}

/// A model's input field ([`PredictInput::into_network_input`]), with how much of it the model reads.
#[derive(Clone, Debug)]
pub struct NetworkInput {
    /// The field, `[3, nx, ny, nz]` in the model's input unit.
    pub field: Vec<f32>,
    /// Its non-zero grid nodes.
    pub given_nodes: usize,
    /// Those of them the model reads no input at (the reduced-order model reads the surface it was
    /// trained to see): left out of its prediction.
    pub unread_nodes: usize,
}

/// What a prediction reads.
#[derive(Clone, Debug)]
pub enum PredictInput {
    /// A tensor on the model's grid (`[3, nx, ny, nz]`).
    Grid(NpyArray),
    /// Vectors at points, to be put on the model's grid.
    Points(PointCloud),
}

impl PredictInput {
    /// Reads a point cloud (`.csv`, see [`PointCloud::parse_csv`], or `.npy` of shape `[N, 6]`) or a grid tensor
    /// (any other `.npy`). A cloud without points, or a file of another extension, is an error.
    pub fn read(path: &Path) -> Result<PredictInput> {
        let extension = mesh::io::extension(path);
        let cloud = if extension == "csv" {
            let text = std::fs::read_to_string(path).map_err(|e| LearnError::io(path, e))?;
            PointCloud::parse_csv(&text, path)?
        } else if extension != "npy" {
            return Err(LearnError::Input {
                path: path.to_path_buf(),
                line: None,
                message:
                    "a prediction reads a grid tensor (.npy) or vectors at points (.csv, or .npy of [N, 6]: x, y, \
                          z and the vector)"
                        .into(),
            });
        } else {
            let array = read_npy(path)?;
            match array.shape.as_slice() {
                [_, 6] => PointCloud::from_rows(&array.into_rows(path, "x, y, z and the vector")?),
                _ => return Ok(PredictInput::Grid(array)),
            }
        };
        if cloud.is_empty() {
            return Err(LearnError::Input { path: path.to_path_buf(), line: None, message: "no points".into() });
        }
        Ok(PredictInput::Points(cloud))
    }

    /// The network input of `model` (`[3, nx, ny, nz]` in its input unit): a grid tensor as it is, once its shape
    /// is checked; a point cloud put on the model's grid where it lies ([`encode_points`]: forces spread to the
    /// corners of their cell, displacements on their nearest grid node, by the model's input unit), with
    /// how much of it the model reads; one it reads nothing of is refused.
    pub fn into_network_input(self, model: &impl LearnedModel) -> Result<NetworkInput> {
        let field = self.into_field(model)?;
        check_input_scale(&field, model)?;
        let (unread_nodes, given_nodes) = unread_input_nodes(&field, model);
        if given_nodes > 0 && unread_nodes == given_nodes {
            return Err(LearnError::InvalidInput(format!(
                "none of the input's {given_nodes} non-zero grid nodes lies where the model reads its input (the \
                 surface it was trained to see): its prediction would be the one for no input"
            )));
        }
        Ok(NetworkInput { field, given_nodes, unread_nodes })
    }

    /// [`into_network_input`](Self::into_network_input) before the check of its scale.
    fn into_field(self, model: &impl LearnedModel) -> Result<Vec<f32>> {
        let g = model.grid_shape();
        match self {
            PredictInput::Grid(array) if array.shape == [3, g.nx, g.ny, g.nz] => {
                // Checked before the rounding to f32 would turn a large value into infinity.
                if let NpyData::F64(values) = &array.data {
                    let unfit = values.iter().position(|v| !(v.is_finite() && v.abs() <= f64::from(MAX_FIELD_VALUE)));
                    if let Some(i) = unfit {
                        return Err(unfit_input(i, values[i]));
                    }
                }
                Ok(array.into_f32())
            }
            PredictInput::Grid(array) => Err(LearnError::InvalidInput(format!(
                "a tensor of shape {:?}, but the model expects [3, {}, {}, {}] (or a point cloud [N, 6])",
                array.shape, g.nx, g.ny, g.nz
            ))),
            PredictInput::Points(cloud) => {
                let forces = model.takes_forces();
                if let (true, Some(unit)) = (forces, cloud.vector_unit) {
                    return Err(LearnError::InvalidInput(format!(
                        "the points' vectors are named in {unit}, but the model takes forces (N)"
                    )));
                }
                if let Some(named) = cloud.named_forces.filter(|&named| named != forces) {
                    let (given, taken) = match named {
                        true => ("forces (fx, fy, fz)", "displacements (m)"),
                        false => ("displacements", "forces (N)"),
                    };
                    return Err(LearnError::InvalidInput(format!(
                        "the points' vectors are named {given}, but the model takes {taken}"
                    )));
                }
                encode_points(&model.placed_grid()?, &cloud.points, &cloud.vectors, forces)
            }
        }
    }
}

/// The non-zero grid nodes of an input `field` that `model` reads no input at (the reduced-order
/// model reads the surface it was trained to see, and nothing else), and the non-zero nodes.
fn unread_input_nodes(field: &[f32], model: &impl LearnedModel) -> (usize, usize) {
    let g = model.grid_shape();
    let nodes = crate::data::corrupt::nonzero_nodes(field, g);
    let Some(entries) = model.input_entries() else { return (0, nodes.len()) };
    let mut read = vec![false; g.nodes()];
    entries.iter().for_each(|&e| read[e % g.nodes()] = true);
    (nodes.iter().filter(|&&v| !read[v]).count(), nodes.len())
}

/// How many times the RMS norm of a model's training inputs an input may reach: beyond, it is
/// taken for one in another unit (a thousand times for millimetres given as metres).
const MAX_INPUT_SCALE_RATIO: f64 = 100.0;

/// Refuses an input field whose RMS norm over its non-zero nodes is more than
/// [`MAX_INPUT_SCALE_RATIO`] times that of `model`'s training inputs, where it records one, or
/// whose features lie that many times as far out as its training inputs' (a reduced-order
/// model's): a model asked so far outside what it learned predicts nonsense.
fn check_input_scale(field: &[f32], model: &impl LearnedModel) -> Result<()> {
    if let Some(ratio) = model.input_feature_ratio(field)?.filter(|&r| r > MAX_INPUT_SCALE_RATIO) {
        return Err(LearnError::InvalidInput(format!(
            "the input lies {ratio:.0} times as far from the model's mean input as its training inputs do (by \
             the features its regression compares): is it in another unit (millimetres given as metres)?"
        )));
    }
    let Some(scale) = model.training_input_scale() else { return Ok(()) };
    let g = model.grid_shape();
    let nodes = crate::data::corrupt::nonzero_nodes(field, g);
    let sum: f64 = field.iter().map(|&v| f64::from(v).powi(2)).sum();
    let rms = (sum / nodes.len().max(1) as f64).sqrt();
    if rms > MAX_INPUT_SCALE_RATIO * scale {
        let unit = if model.takes_forces() { "N" } else { "m" };
        return Err(LearnError::InvalidInput(format!(
            "the input's RMS norm is {rms:.3e} {unit}, {:.0} times that of the inputs the model was trained on \
             ({scale:.3e} {unit}): is it in another unit (millimetres given as metres)?",
            rms / scale
        )));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn csv_point_clouds_take_a_header_blank_lines_and_both_separators() {
        let path = Path::new("cloud.csv");
        let text = "x,y,z,fx,fy,fz\n0.1, 0.2, 0.3, 1, 2, 3\n\n-1e-3;0;5;0.5;-0.5;0\n";
        let cloud = PointCloud::parse_csv(text, path).unwrap();
        assert_eq!(cloud.points, [[0.1, 0.2, 0.3], [-1e-3, 0.0, 5.0]]);
        assert_eq!(cloud.vectors, [[1.0, 2.0, 3.0], [0.5, -0.5, 0.0]]);
        let e = PointCloud::parse_csv("1,2,3,4,5,6\n1,2,3,4,5\n", path).unwrap_err().to_string();
        assert!(e.starts_with("cloud.csv:2: 5 numbers"), "{e}");
        // Only the first line may be a header.
        let e = PointCloud::parse_csv("1,2,3,4,5,6\nx,y,z,a,b,c\n", path).unwrap_err().to_string();
        assert!(e.starts_with("cloud.csv:2: "), "{e}");
        assert!(PointCloud::parse_csv("x,y,z,a,b,c\n", path).unwrap().is_empty());
        // What the header names the vectors: forces, displacements (with or without a unit), or neither.
        let kind =
            |header: &str| PointCloud::parse_csv(&format!("{header}\n0,0,0,0,0,1\n"), path).unwrap().named_forces;
        assert_eq!(kind("x,y,z,fx,fy,fz"), Some(true));
        assert_eq!(kind("x,y,z,Fx_N,Fy_N,Fz_N"), Some(true));
        assert_eq!(kind("x,y,z,ux,uy,uz"), Some(false));
        assert_eq!(kind("x_mm,y_mm,z_mm,dx_mm,dy_mm,dz_mm"), Some(false));
        assert_eq!(kind("x,y,z,vx,vy,vz"), None);
        // A header naming millimetres: positions (and displacements named so) in metres.
        let mm = PointCloud::parse_csv("x_mm,y_mm,z_mm,fx,fy,fz\n-50,10,30,0,0,-0.2\n", path).unwrap();
        assert_eq!((mm.points[0], mm.vectors[0]), ([-0.05, 0.01, 0.03], [0.0, 0.0, -0.2]));
        let mm = PointCloud::parse_csv("x_mm,y_mm,z_mm,ux_mm,uy_mm,uz_mm\n-50,10,30,0,0,-2\n", path).unwrap();
        assert_eq!(mm.vectors[0], [0.0, 0.0, -0.002]);
        // Columns of one kind naming different units are refused, not read as metres.
        let e = PointCloud::parse_csv("x_mm,y,z_mm,fx,fy,fz\n-50,10,30,0,0,-0.2\n", path).unwrap_err().to_string();
        assert!(e.starts_with("cloud.csv:1: the x, y and z columns name different units"), "{e}");
        let e = PointCloud::parse_csv("x,y,z,ux_mm,uy_mm,uz\n0,0,0,0,0,1\n", path).unwrap_err().to_string();
        assert!(e.starts_with("cloud.csv:1: the vector columns name different units"), "{e}");
        // A field that is no number is named as the header names its column.
        let e = PointCloud::parse_csv("x,y,z,ux,uy,uz\n0,0,0,0,nan,0\n", path).unwrap_err().to_string();
        assert!(e.starts_with("cloud.csv:2: uy ") && e.contains("not finite"), "{e}");
        let e = PointCloud::parse_csv("0,0,0,0,nan,0\n", path).unwrap_err().to_string();
        assert!(e.starts_with("cloud.csv:1: vy "), "{e}");
        let m = PointCloud::parse_csv("x,y,z,ux_m,uy_m,uz_m\n0,0,0,0,0,0.001\n", path).unwrap();
        assert_eq!((m.vectors[0], m.vector_unit), ([0.0, 0.0, 0.001], Some(LengthUnit::Metre)));
    }

    /// A header that names its columns puts them in order, wherever they stand; one naming an axis
    /// twice is refused; one naming no column x, y or z is read in its columns' order.
    #[test]
    fn a_csv_header_names_its_columns_in_any_order() {
        let path = Path::new("cloud.csv");
        let read = |text: &str| PointCloud::parse_csv(text, path).unwrap();
        let expected = ([[0.01, 0.02, 0.03]].to_vec(), [[1.0, 0.0, -2.0]].to_vec());
        for text in [
            "x,y,z,fx,fy,fz\n0.01,0.02,0.03,1,0,-2\n",
            "z,y,x,fz,fy,fx\n0.03,0.02,0.01,-2,0,1\n",
            "fx,fy,fz,x,y,z\n1,0,-2,0.01,0.02,0.03\n",
            "Fz_N;X_mm;fy;Y_mm;fx;Z_mm\n-2;10;0;20;1;30\n",
        ] {
            let cloud = read(text);
            let close = |a: &[[f64; 3]], b: &[[f64; 3]]| {
                a.iter().flatten().zip(b.iter().flatten()).all(|(p, q)| (p - q).abs() < 1e-12)
            };
            assert!(close(&cloud.points, &expected.0) && close(&cloud.vectors, &expected.1), "{text}: {cloud:?}");
            assert_eq!(cloud.named_forces, Some(true), "{text}");
        }
        // Vectors named without axes keep their order; the units still come from the names.
        assert_eq!(read("u,v,w,z_mm,y_mm,x_mm\n1,2,3,30,20,10\n").points, [[0.01, 0.02, 0.03]]);
        assert_eq!(read("a,b,c,d,e,f\n1,2,3,4,5,6\n").vectors, [[4.0, 5.0, 6.0]]);
        for header in ["x,y,z,ux,uy,uy", "x,x,z,ux,uy,uz", "x,y,z,z,uy,uz"] {
            let e = PointCloud::parse_csv(&format!("{header}\n0,0,0,0,0,0\n"), path).unwrap_err().to_string();
            assert!(e.starts_with("cloud.csv:1: the header names an axis twice"), "{header}: {e}");
        }
    }

    #[test]
    fn clouds_and_grid_tensors_are_told_apart_by_shape_and_extension() {
        let dir = tempfile::tempdir().unwrap();
        let npy = dir.path().join("cloud.npy");
        mesh::io::npy::write_f32(&npy, &[2, 6], &[0.0, 0.1, 0.2, 1.0, 0.0, 0.0, 0.5, 0.5, 0.5, 0.0, 0.0, 2.0]).unwrap();
        match PredictInput::read(&npy).unwrap() {
            PredictInput::Points(c) => {
                assert_eq!(c.len(), 2);
                assert_eq!(c.vectors[1], [0.0, 0.0, 2.0]);
            }
            PredictInput::Grid(_) => panic!("a [2, 6] array is a point cloud"),
        }
        let grid = dir.path().join("grid.npy");
        mesh::io::npy::write_f32(&grid, &[3, 2, 2, 2], &[0.0; 24]).unwrap();
        assert!(matches!(PredictInput::read(&grid).unwrap(), PredictInput::Grid(a) if a.shape == [3, 2, 2, 2]));
        let empty = dir.path().join("empty.CSV");
        std::fs::write(&empty, "x,y,z,u,v,w\n").unwrap();
        let e = PredictInput::read(&empty).unwrap_err().to_string();
        assert!(e.ends_with("empty.CSV: no points"), "{e}");
        // A model file given for a cloud is refused by its extension, not read as a broken .npy.
        let e = PredictInput::read(&dir.path().join("cloud.vtk")).unwrap_err().to_string();
        assert!(e.contains("cloud.vtk") && e.contains("reads a grid tensor (.npy) or vectors at points"), "{e}");
    }
}
