//! One dataset sample seen on the organ's mesh: the reference displacement (the FEM solution stored as the
//! sample's target) and a model's prediction at the mesh nodes and at the dataset's internal markers, and the
//! 3D viewer scene that shows them ([`plot::viewer`]).
//!
//! And `augsim view`, which writes that scene or a file's ([`crate::file_view`]) as a page ([`view`]).
//!
//! Both fields come from the grid the same way ([`GridToMesh`] at the nodes, trilinear interpolation at the
//! markers), so their difference is the network's error alone, not that of the grid encoding.

use std::path::PathBuf;

use mesh::embedding::Grid;
use mesh::length::mm;
use mesh::{stats, Mesh, Point};
use plot::viewer::{Layer, PointLayer, Scalar, Scene};

use learn::{Dataset, GridToMesh, LearnError, LearnedModel, Manifest, Model, Result, CHANNELS};

pub use learn::data::split::SampleRole;

/// A sample's reference and predicted displacement (m) at the nodes of the organ's mesh and at the markers.
#[derive(Clone, Debug, PartialEq)]
pub struct SampleOnMesh {
    /// Generation index of the sample.
    pub index: u64,
    /// What the sample was to the model.
    pub role: SampleRole,
    /// Reference displacement of each mesh node.
    pub reference: Vec<[f64; 3]>,
    /// Predicted displacement of each mesh node.
    pub prediction: Vec<[f64; 3]>,
    /// Internal markers at rest (the dataset's `markers`; empty when it records none).
    pub markers: Vec<Point>,
    /// Reference displacement of each marker.
    pub marker_reference: Vec<[f64; 3]>,
    /// Predicted displacement of each marker.
    pub marker_prediction: Vec<[f64; 3]>,
}

/// The sample of generation index `index` of `dataset` on `organ` (the volume mesh the dataset was generated on),
/// with `model`'s prediction from the sample's uncorrupted input. The model must be on the dataset's grid, placed
/// at the same place; the mesh must have the node and cell counts the dataset records and lie in the grid.
pub fn sample_on_mesh(model: &Model, dataset: &Dataset, index: u64, organ: &Mesh) -> Result<SampleOnMesh> {
    let invalid = |m: String| LearnError::InvalidInput(m);
    let manifest = dataset.manifest();
    if manifest.grid != model.grid() {
        return Err(invalid(format!("the model is on grid {}, the dataset on grid {}", model.grid(), manifest.grid)));
    }
    let placement = manifest.placement().ok_or_else(|| {
        invalid(format!("{} does not record where its grid lies (grid_origin, grid_spacing)", dataset.dir().display()))
    })?;
    if let Some(p) = model.placement() {
        p.check_matches(&placement)?;
    }
    let recorded = |key: &str| manifest.metadata.get(key).and_then(|v| v.as_u64());
    for (what, count, given) in
        [("nodes", recorded("mesh_nodes"), organ.num_nodes()), ("cells", recorded("mesh_cells"), organ.cells.len())]
    {
        if count.is_some_and(|c| c != given as u64) {
            return Err(invalid(format!(
                "the dataset was generated on a mesh of {} {what}, the given mesh has {given}",
                count.unwrap_or_default()
            )));
        }
    }
    let mut indices = manifest.shards.iter().flat_map(|s| &s.indices);
    let Some(position) = indices.position(|&i| i == index) else {
        let failed = manifest.failed.iter().find(|f| f.index == index);
        let all: Vec<u64> = manifest.shards.iter().flat_map(|s| s.indices.iter().copied()).collect();
        return Err(invalid(match failed {
            Some(f) => format!("sample {index} failed at generation: {}", f.reason),
            None => format!(
                "{} has no sample of index {index} (indices {}..={})",
                dataset.dir().display(),
                all.first().copied().unwrap_or_default(),
                all.last().copied().unwrap_or_default()
            ),
        }));
    };
    let samples = dataset.load_range(position..position + 1)?;
    let prediction = model.predictor(learn::Compute::Cpu)?.predict(samples.input(0))?;
    let target = samples.target(0);
    let grid = placement.grid(manifest.grid)?;
    let to_mesh = GridToMesh::new(organ, &grid)?;
    let triples = |v: Vec<f64>| v.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect::<Vec<_>>();
    let markers = manifest.markers();
    let at_markers = |field: &[f32]| -> Result<Vec<[f64; 3]>> {
        if markers.is_empty() {
            return Ok(Vec::new());
        }
        let f: Vec<f64> = field.iter().map(|&x| f64::from(x)).collect();
        Ok(triples(interpolate(&grid, &f, &markers)?))
    };
    Ok(SampleOnMesh {
        index,
        role: model.role(samples.source.as_deref(), index),
        reference: triples(to_mesh.apply(target)?),
        prediction: triples(to_mesh.apply(&prediction)?),
        marker_reference: at_markers(target)?,
        marker_prediction: at_markers(&prediction)?,
        markers,
    })
}

/// The generation index of the first sample of the dataset of `manifest` held out from `model` (a test sample
/// of the model's recorded split, or one it never saw); `None` when all were trained or validated on.
fn first_held_out(model: &Model, manifest: &Manifest) -> Option<u64> {
    let source = manifest.source_id();
    manifest
        .shards
        .iter()
        .flat_map(|s| s.indices.iter().copied())
        .find(|&i| matches!(model.role(Some(&source), i), SampleRole::Test | SampleRole::Unseen))
}

fn interpolate(grid: &Grid, field: &[f64], points: &[Point]) -> Result<Vec<f64>> {
    grid.interpolate(field, CHANNELS, points).map_err(|e| LearnError::InvalidInput(format!("markers: {e}")))
}

fn moved(rest: &[Point], u: &[[f64; 3]]) -> Vec<[f64; 3]> {
    rest.iter().zip(u).map(|(p, u)| [p[0] + u[0], p[1] + u[1], p[2] + u[2]]).collect()
}

impl SampleOnMesh {
    /// Prediction error `|u_pred − u_ref|` at each mesh node (m).
    pub fn errors(&self) -> Vec<f64> {
        mesh::distances(&self.prediction, &self.reference)
    }

    /// Prediction error at each marker (m): the target registration error.
    pub fn marker_errors(&self) -> Vec<f64> {
        mesh::distances(&self.marker_prediction, &self.marker_reference)
    }

    /// The viewer scene: the boundary surface of `organ` at rest, moved by the reference and by the prediction,
    /// coloured by the prediction error (mm), with the markers at rest, moved by the reference and by the
    /// prediction; notes give the sample, its role and the error statistics.
    pub fn scene(&self, organ: &Mesh, title: &str) -> Scene {
        let surface = mesh::boundary_surface(organ);
        let errors = self.errors();
        let (mean, max) = (stats::mean(&errors), stats::max(&errors));
        let largest = self.reference.iter().copied().map(mesh::norm).fold(0.0, f64::max);
        let mut notes = vec![
            format!("sample {} ({} sample of this model)", self.index, self.role),
            format!("error at the {} nodes: mean {:.2} mm, max {:.2} mm", errors.len(), mm(mean), mm(max)),
            format!("reference displacement up to {:.1} mm", mm(largest)),
        ];
        let mut points = Vec::new();
        if !self.markers.is_empty() {
            let marker_errors = self.marker_errors();
            let (m, x) = (stats::mean(&marker_errors), stats::max(&marker_errors));
            notes.push(format!("{} markers: error mean {:.2} mm, max {:.2} mm", self.markers.len(), mm(m), mm(x)));
            points = vec![
                PointLayer { name: "markers at rest".into(), positions: self.markers.clone(), colour: [170, 170, 170] },
                PointLayer {
                    name: "markers, reference".into(),
                    positions: moved(&self.markers, &self.marker_reference),
                    colour: [40, 110, 230],
                },
                PointLayer {
                    name: "markers, predicted".into(),
                    positions: moved(&self.markers, &self.marker_prediction),
                    colour: [30, 170, 70],
                },
            ];
        }
        Scene {
            title: title.into(),
            notes,
            triangles: surface.triangles.iter().map(|t| t.map(|i| i as u32)).collect(),
            rest: organ.nodes.clone(),
            layers: vec![
                Layer { name: "reference".into(), positions: moved(&organ.nodes, &self.reference) },
                Layer { name: "prediction".into(), positions: moved(&organ.nodes, &self.prediction) },
            ],
            colour: Some(Scalar {
                name: "prediction error".into(),
                unit: "mm".into(),
                values: errors.iter().map(|&e| mm(e)).collect(),
            }),
            points,
        }
    }
}

/// The organ's volume mesh of the dataset in `dataset_dir`: read from `mesh` when given, otherwise
/// built from the dataset scenario `scenario`; by default the `dataset.toml` beside the dataset
/// (where `augsim prepare` writes it) when it names the dataset's scenario, else the scenario the
/// manifest names (a built-in one). With the path it came from.
pub fn organ_mesh(
    mesh: Option<&std::path::Path>,
    scenario: Option<&std::path::Path>,
    dataset_dir: &std::path::Path,
    manifest: &Manifest,
) -> anyhow::Result<(Mesh, std::path::PathBuf)> {
    use anyhow::Context;
    if let Some(path) = mesh {
        return Ok((
            mesh::io::read_mesh(path).with_context(|| format!("reading {}", path.display()))?,
            path.to_path_buf(),
        ));
    }
    let load = |path: &std::path::Path| {
        scenario::DatasetScenario::load(path)
            .context("the organ's mesh: give the dataset's scenario (--scenario) or its mesh (--mesh)")
    };
    // The scenario `augsim prepare` writes beside its dataset, read once, when it is this one's.
    let prepared = dataset_dir.parent().map(|d| d.join("dataset.toml")).and_then(|path| {
        let loaded = scenario::DatasetScenario::load(&path).ok()?;
        (loaded.0.name == manifest.scenario).then_some((loaded, path))
    });
    let ((scenario, dir), path) = match (scenario, prepared) {
        (Some(path), _) => (load(path)?, path.to_path_buf()),
        (None, Some(found)) => found,
        (None, None) => {
            let path = std::path::PathBuf::from(&manifest.scenario);
            (load(&path)?, path)
        }
    };
    Ok((scenario.mesh(&dir)?, path))
}

/// Options of `augsim view`.
#[derive(Debug, clap::Args)]
pub struct ViewArgs {
    /// Trained model: its directory or its model.json.
    #[arg(long, requires = "dataset")]
    pub model: Option<PathBuf>,
    /// Dataset directory the sample is taken from.
    #[arg(long, requires = "model")]
    pub dataset: Option<PathBuf>,
    /// Generation index of the sample (as `eval` reports them); default: the first sample held out from the
    /// model.
    #[arg(long, requires = "model")]
    pub sample: Option<u64>,
    /// Dataset scenario the dataset was generated from, to rebuild the organ's mesh; default: the
    /// `dataset.toml` beside the dataset when it names the dataset's scenario (as `augsim prepare`
    /// writes it), else the built-in scenario of the dataset's name.
    #[arg(long, requires = "model", conflicts_with = "mesh")]
    pub scenario: Option<PathBuf>,
    /// The organ's volume mesh (.vtu, .vtk, .msh) instead of rebuilding it from the scenario.
    #[arg(long, requires = "model")]
    pub mesh: Option<PathBuf>,
    /// Show a file instead: a volume mesh (.vtu, .vtk, .msh, .inp) moved by its 3-component point fields as
    /// displacements (m), coloured by the error when it has `reference` and `prediction` fields (as `eval`
    /// writes), else by the first one's magnitude; a surface (.stl, .obj, .ply, .vtp, a .vtk or .vtu of
    /// poly data, as `register` writes organ_deformed.vtk) as it is; a sequence (.pvd, as `register` writes a
    /// stream's) one step per layer.
    #[arg(long, alias = "vtu", conflicts_with_all = ["model", "dataset"])]
    pub file: Option<PathBuf>,
    /// Output HTML file (.html).
    #[arg(short, long, default_value = "out/view.html")]
    pub out: PathBuf,
}

/// `augsim view`: the scene of [`ViewArgs`] (a dataset sample, or a file: a mesh's displacement
/// fields, a surface, a sequence) written as a self-contained HTML viewer; the lines that describe it.
pub fn view(args: &ViewArgs) -> anyhow::Result<Vec<String>> {
    // A page only: any other name could be one of the files it shows (a mesh, a model, a manifest).
    if !matches!(mesh::io::extension(&args.out).as_str(), "html" | "htm") {
        anyhow::bail!("-o {}: the viewer writes an HTML page: give a .html file", args.out.display());
    }
    let (scene, mut lines) = match (&args.file, &args.model, &args.dataset) {
        (Some(file), _, _) => crate::file_view::file_scene(file)?,
        (None, Some(model), Some(dataset)) => {
            dataset_sample_scene(model, dataset, args.sample, args.mesh.as_deref(), args.scenario.as_deref())?
        }
        _ => anyhow::bail!(
            "give --model and --dataset (a dataset sample), or --file FILE (a mesh with displacements, a surface, \
             a sequence .pvd)"
        ),
    };
    plot::viewer::write_html(&args.out, &scene)?;
    lines.push(format!("wrote      {} (open it in a browser)", args.out.display()));
    Ok(lines)
}

/// The viewer's scene of sample `index` (default: the first held out from the model) of the
/// dataset in `dataset_dir` on the organ ([`organ_mesh`] of `mesh` or `scenario`), the model of
/// `model_path` predicting it; with the lines that describe it.
fn dataset_sample_scene(
    model_path: &std::path::Path,
    dataset_dir: &std::path::Path,
    index: Option<u64>,
    mesh: Option<&std::path::Path>,
    scenario: Option<&std::path::Path>,
) -> anyhow::Result<(Scene, Vec<String>)> {
    use anyhow::Context;
    let model = Model::load(model_path)?;
    let dataset = Dataset::open(dataset_dir)?;
    let manifest = dataset.manifest();
    let (organ, from) = organ_mesh(mesh, scenario, dataset_dir, manifest)?;
    let index = match index {
        Some(i) => i,
        None => first_held_out(&model, manifest)
            .with_context(|| format!("{} holds no sample held out from the model", dataset_dir.display()))?,
    };
    let sample = sample_on_mesh(&model, &dataset, index, &organ)?;
    let method = model.method().display_name();
    let scene =
        sample.scene(&organ, &format!("{}, sample {index}: {method} prediction vs FEM reference", manifest.scenario));
    let mut lines = vec![
        format!("sample     {index} of {} ({} sample of this model)", dataset_dir.display(), sample.role),
        format!(
            "mesh       {} nodes, {} surface triangles ({})",
            organ.num_nodes(),
            scene.triangles.len(),
            from.display()
        ),
    ];
    lines.extend(scene.notes.iter().skip(1).map(|note| format!("           {note}")));
    Ok((scene, lines))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scene_shows_the_surface_moved_and_coloured_by_the_error_in_mm() {
        let organ = mesh::box_tet([0.0; 3], [0.1, 0.1, 0.1], [2, 2, 2]).unwrap();
        let n = organ.num_nodes();
        let reference: Vec<[f64; 3]> = organ.nodes.iter().map(|p| [0.0, 0.0, -0.2 * p[0]]).collect();
        let prediction = reference.iter().map(|u| [u[0] + 0.003, u[1], u[2] + 0.004]).collect();
        let sample = SampleOnMesh {
            index: 7,
            role: SampleRole::Test,
            reference,
            prediction,
            markers: vec![[0.05; 3]],
            marker_reference: vec![[0.0, 0.0, -0.01]],
            marker_prediction: vec![[0.0, 0.001, -0.01]],
        };
        assert!(sample.errors().iter().all(|e| (e - 0.005).abs() < 1e-12));
        assert!((sample.marker_errors()[0] - 0.001).abs() < 1e-12);
        let scene = sample.scene(&organ, "box");
        scene.validate().unwrap();
        assert_eq!(scene.triangles.len(), 6 * 4 * 2, "6 faces of 4 quads, two triangles each");
        assert_eq!(scene.rest.len(), n);
        let names: Vec<&str> = scene.layers.iter().map(|l| l.name.as_str()).collect();
        assert_eq!(names, ["reference", "prediction"]);
        let corner = organ.nodes.iter().position(|p| *p == [0.1, 0.1, 0.1]).unwrap();
        assert_eq!(scene.layers[0].positions[corner], [0.1, 0.1, 0.1 - 0.02]);
        let colour = scene.colour.as_ref().unwrap();
        assert_eq!(colour.unit, "mm");
        assert!(colour.values.iter().all(|v| (v - 5.0).abs() < 1e-9));
        assert_eq!(scene.points.len(), 3);
        let predicted = scene.points[2].positions[0];
        assert!(predicted.iter().zip([0.05, 0.051, 0.04]).all(|(a, b)| (a - b).abs() < 1e-12), "{predicted:?}");
        assert!(scene.notes[0].contains("sample 7 (test sample"), "{:?}", scene.notes);
        assert!(scene.notes[1].contains("mean 5.00 mm, max 5.00 mm"), "{:?}", scene.notes);
        assert!(scene.notes[3].contains("1 markers: error mean 1.00 mm"), "{:?}", scene.notes);
    }
}
