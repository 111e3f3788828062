//! A file seen in the 3D viewer ([`plot::viewer`]), as `augsim view FILE` shows it: a volume
//! mesh moved by each of its displacement fields (as `solve`, `eval` and `register` write them),
//! a surface as it is (a segmentation's export, `register`'s `organ_deformed.vtk` for 3D Slicer),
//! or a sequence of meshes (a ParaView collection, `.pvd`, as `register` writes a stream's and
//! `assimilate` its estimates), one layer per time step.

use std::path::Path;

use anyhow::{Context, Result};
use mesh::io::{Field, FieldLocation};
use mesh::length::mm;
use mesh::{Mesh, Point};
use plot::viewer::{Layer, Scalar, Scene};

/// The scene of the file at `path` (see the [module](self) documentation), with the lines that
/// describe it. A `.vtk` or `.vtu` file is read as a volume mesh, else as a surface (poly data; of
/// another, the lines say why its volume was not read).
pub fn file_scene(path: &Path) -> Result<(Scene, Vec<String>)> {
    match mesh::io::extension(path).as_str() {
        "pvd" => sequence_scene(path),
        "msh" | "inp" => volume_scene(path),
        "vtk" | "vtu" => match volume_scene(path) {
            Ok(found) => Ok(found),
            Err(volume_error) => match surface_scene(path) {
                Ok((scene, mut lines)) => {
                    // A file of poly data is a surface; another is one only because its volume is unreadable.
                    if !matches!(volume_error.downcast_ref(), Some(mesh::MeshError::NotVolume { .. })) {
                        lines.push(format!("           shown as a surface, its volume unread: {volume_error:#}"));
                    }
                    Ok((scene, lines))
                }
                Err(_) => Err(volume_error),
            },
        },
        kind if mesh::io::SURFACE_EXTENSIONS.contains(&kind) => surface_scene(path),
        _ => anyhow::bail!(
            "{}: not a file the viewer reads (a volume mesh .vtu, .vtk, .msh, .inp; a surface .stl, .obj, .ply, \
             .vtp; a sequence .pvd)",
            path.display()
        ),
    }
}

/// The scene of a volume mesh file and its line.
fn volume_scene(path: &Path) -> Result<(Scene, Vec<String>)> {
    let (organ, fields) =
        mesh::io::read_mesh_with_fields(path).with_context(|| format!("reading {}", path.display()))?;
    Ok(with_field_names(volume_fields_scene(path, organ, &fields)))
}

/// A volume's scene with the line that names its displacement fields.
fn with_field_names((scene, fields): (Scene, Vec<String>)) -> (Scene, Vec<String>) {
    let line = format!(
        "mesh       {} nodes, {} surface triangles; displacement fields: {}",
        scene.rest.len(),
        scene.triangles.len(),
        if fields.is_empty() { "none".into() } else { fields.join(", ") }
    );
    (scene, vec![line])
}

/// The 3-component point fields of `organ` among `fields`, taken as its displacements (m): all
/// but forces (`reaction_force`, as `solve` writes it) and a learned model's `input`, which may be
/// forces (as `eval` writes it).
fn displacements<'f>(organ: &Mesh, fields: &'f [Field]) -> Vec<&'f Field> {
    let force = |name: &str| name.to_ascii_lowercase().contains("force") || name == "input";
    fields
        .iter()
        .filter(|f| f.location == FieldLocation::Point && f.components == 3 && f.num_tuples() == organ.num_nodes())
        .filter(|f| !force(&f.name))
        .collect()
}

/// The magnitude (mm) of each vector of a 3-component field (m).
fn magnitudes_mm(values: &[f64]) -> Vec<f64> {
    values.chunks_exact(3).map(|c| mm((c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt())).collect()
}

/// `nodes` moved by a 3-component field.
fn moved_by(nodes: &[Point], field: &Field) -> Vec<Point> {
    nodes
        .iter()
        .enumerate()
        .map(|(n, p)| {
            let u = field.tuple(n);
            [p[0] + u[0], p[1] + u[1], p[2] + u[2]]
        })
        .collect()
}

/// The title of a file's scene: its name.
fn title(path: &Path) -> String {
    path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default()
}

/// The triangles of `organ`'s boundary, for the page.
fn boundary_triangles(organ: &Mesh) -> Vec<[u32; 3]> {
    mesh::boundary_surface(organ).triangles.iter().map(|t| t.map(|i| i as u32)).collect()
}

/// The scene of a volume mesh and its fields: its boundary at rest and moved by each
/// 3-component point field (m), coloured by the error when it has `reference` and `prediction`
/// fields (as `eval` writes), else by the first one's magnitude (mm); with those fields' names.
fn volume_fields_scene(path: &Path, organ: Mesh, fields: &[Field]) -> (Scene, Vec<String>) {
    let vectors = displacements(&organ, fields);
    let field = |name: &str| vectors.iter().find(|f| f.name == name);
    let colour = match (field("reference"), field("prediction"), vectors.first()) {
        (Some(r), Some(p), _) => Some(Scalar {
            name: "prediction error".into(),
            unit: "mm".into(),
            values: magnitudes_mm(&p.values.iter().zip(&r.values).map(|(a, b)| a - b).collect::<Vec<_>>()),
        }),
        (_, _, Some(f)) => {
            Some(Scalar { name: format!("|{}|", f.name), unit: "mm".into(), values: magnitudes_mm(&f.values) })
        }
        _ => None,
    };
    let names = vectors.iter().map(|f| f.name.clone()).collect();
    let scene = Scene {
        title: title(path),
        notes: vec![format!("{} nodes, {} {} cells", organ.num_nodes(), organ.cells.len(), organ.cells.kind_name())],
        triangles: boundary_triangles(&organ),
        layers: vectors.iter().map(|f| Layer { name: f.name.clone(), positions: moved_by(&organ.nodes, f) }).collect(),
        rest: organ.nodes,
        colour,
        points: Vec::new(),
    };
    (scene, names)
}

/// The scene of a surface file as it is (its own coordinates and unit), with its line.
fn surface_scene(path: &Path) -> Result<(Scene, Vec<String>)> {
    let (surface, frame, warnings) =
        mesh::io::read_surface_noted(path).with_context(|| format!("reading {}", path.display()))?;
    let frame = frame.map_or_else(|| "names no frame".to_string(), |f| format!("frame {f}"));
    let line =
        format!("surface    {} vertices, {} triangles, {frame}", surface.vertices.len(), surface.triangles.len());
    let scene = Scene {
        title: title(path),
        notes: vec![format!("surface of {} triangles, {frame}", surface.triangles.len())],
        triangles: surface.triangles.iter().map(|t| t.map(|i| i as u32)).collect(),
        rest: surface.vertices,
        ..Scene::default()
    };
    Ok((scene, std::iter::once(line).chain(warnings.into_iter().map(|w| format!("warning    {w}"))).collect()))
}

/// The scene of a sequence (`.pvd`): the boundary of its first mesh at rest, one layer per step
/// (the step's nodes moved by its `displacement` field, else its first 3-component point field,
/// else as they are), coloured by the last step's displacement (mm). Every step must be a mesh of
/// the first one's nodes and cells.
fn sequence_scene(path: &Path) -> Result<(Scene, Vec<String>)> {
    let steps = mesh::io::read_pvd(path)?;
    let mut first: Option<Mesh> = None;
    let (mut layers, mut last_displacement) = (Vec::new(), None);
    for (k, (time, file)) in steps.iter().enumerate() {
        let (organ, fields) = mesh::io::read_mesh_with_fields(file)
            .with_context(|| format!("reading {} of {}", file.display(), path.display()))?;
        if let Some(reference) = &first {
            if (organ.num_nodes(), organ.cells.len()) != (reference.num_nodes(), reference.cells.len()) {
                anyhow::bail!(
                    "{}: {} has {} nodes and {} cells, the sequence's first step {} and {}: not one organ's steps",
                    path.display(),
                    file.display(),
                    organ.num_nodes(),
                    organ.cells.len(),
                    reference.num_nodes(),
                    reference.cells.len()
                );
            }
        }
        let vectors = displacements(&organ, &fields);
        let displacement = vectors.iter().find(|f| f.name == "displacement").or(vectors.first()).copied();
        let positions = displacement.map_or_else(|| organ.nodes.clone(), |f| moved_by(&organ.nodes, f));
        layers.push(Layer { name: format!("t = {time}"), positions });
        if k + 1 == steps.len() {
            last_displacement = displacement.map(|f| (f.name.clone(), magnitudes_mm(&f.values)));
        }
        first.get_or_insert(organ);
    }
    let organ = first.context("a collection without steps")?;
    let (t0, t1) = (steps[0].0, steps[steps.len() - 1].0);
    let triangles = boundary_triangles(&organ);
    let line = format!(
        "sequence   {} steps (t = {t0} to {t1}) of a mesh of {} nodes, {} surface triangles",
        steps.len(),
        organ.num_nodes(),
        triangles.len()
    );
    let scene = Scene {
        title: title(path),
        notes: vec![format!("{} steps, t = {t0} to {t1}", steps.len())],
        triangles,
        layers,
        colour: last_displacement.map(|(name, values)| Scalar {
            name: format!("|{name}| at t = {t1}"),
            unit: "mm".into(),
            values,
        }),
        rest: organ.nodes,
        points: Vec::new(),
    };
    Ok((scene, vec![line]))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cube() -> Mesh {
        mesh::box_tet([0.0; 3], [0.1, 0.1, 0.1], [1, 1, 1]).unwrap()
    }

    /// A sequence is one layer per step, moved by its displacement and coloured by the last; a
    /// step of another mesh is refused.
    #[test]
    fn a_sequence_is_a_layer_per_step() {
        let dir = tempfile::tempdir().unwrap();
        let organ = cube();
        let n = organ.num_nodes();
        for (k, dz) in [0.0, -0.002, -0.004].into_iter().enumerate() {
            let u = Field::point("displacement", 3, (0..n).flat_map(|_| [0.0, 0.0, dz]).collect());
            mesh::io::write_mesh(dir.path().join(format!("organ_{k:04}.vtu")), &organ, &[u]).unwrap();
        }
        let steps: Vec<(f64, String)> = (0..3).map(|k| (k as f64, format!("organ_{k:04}.vtu"))).collect();
        let pvd = dir.path().join("organ.pvd");
        mesh::io::write_pvd(&pvd, &steps).unwrap();
        let (scene, lines) = file_scene(&pvd).unwrap();
        scene.validate().unwrap();
        assert_eq!(scene.layers.len(), 3);
        assert_eq!(scene.layers[2].name, "t = 2");
        assert!((scene.layers[2].positions[0][2] - (organ.nodes[0][2] - 0.004)).abs() < 1e-12);
        let colour = scene.colour.unwrap();
        assert!(colour.values.iter().all(|v| (v - 4.0).abs() < 1e-9), "{:?}", colour.values);
        assert!(lines[0].contains("3 steps (t = 0 to 2)"), "{lines:?}");
        let other = mesh::box_tet([0.0; 3], [0.1, 0.1, 0.1], [2, 1, 1]).unwrap();
        mesh::io::write_mesh(dir.path().join("organ_0001.vtu"), &other, &[]).unwrap();
        let e = file_scene(&pvd).unwrap_err().to_string();
        assert!(e.contains("not one organ's steps"), "{e}");
    }

    /// A surface written for 3D Slicer (a `.vtk` of poly data) is shown as it is, its frame named
    /// and why it is not a volume said; a volume mesh is still read as one.
    #[test]
    fn a_surface_file_is_shown_as_it_is() {
        let dir = tempfile::tempdir().unwrap();
        let surface = mesh::boundary_surface(&cube());
        let path = dir.path().join("organ_deformed.vtk");
        mesh::io::write_surface_in_frame(&path, &surface, mesh::io::Frame::Lps).unwrap();
        let (scene, lines) = file_scene(&path).unwrap();
        scene.validate().unwrap();
        assert_eq!(scene.triangles.len(), surface.triangles.len());
        assert!(scene.layers.is_empty());
        assert!(lines[0].contains("frame LPS"), "{lines:?}");
        assert_eq!(lines.len(), 1, "poly data is a surface, nothing to explain: {lines:?}");
        // A grid of triangles is read as a surface, saying why not as a volume.
        let triangles = dir.path().join("organ_surface.vtu");
        mesh::io::write_surface(&triangles, &surface).unwrap();
        let (scene, lines) = file_scene(&triangles).unwrap();
        assert_eq!(scene.triangles.len(), surface.triangles.len());
        assert!(lines[1].contains("shown as a surface, its volume unread"), "{lines:?}");
        let volume = dir.path().join("organ.vtk");
        mesh::io::write_mesh(&volume, &cube(), &[]).unwrap();
        let (_, lines) = file_scene(&volume).unwrap();
        assert!(lines[0].starts_with("mesh       8 nodes"), "{lines:?}");
        let e = file_scene(&dir.path().join("organ.csv")).unwrap_err().to_string();
        assert!(e.contains("not a file the viewer reads"), "{e}");
    }
}
