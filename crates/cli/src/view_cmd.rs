//! `augsim view`: a self-contained HTML 3D viewer (one file, opens in a browser without network) of a dataset
//! sample on the organ — rest shape, FEM reference, a model's prediction, coloured by the prediction error, with
//! the internal markers — or of the displacement fields of a mesh file.

use std::path::{Path, PathBuf};

use anyhow::{bail, Result};
use app::sample_view::{dataset_sample_scene, mesh_file_scene};
use plot::viewer::Scene;

use crate::bar::print_lines;

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
    /// Show a mesh file (.vtu, .vtk) instead: its 3-component point fields as displacements (m), coloured by the
    /// error when it has `reference` and `prediction` fields (as `eval` writes), else by the first one's
    /// magnitude.
    #[arg(long, conflicts_with_all = ["model", "dataset"])]
    pub vtu: Option<PathBuf>,
    /// Output HTML file.
    #[arg(short, long, default_value = "out/view.html")]
    pub out: PathBuf,
}

/// Runs `augsim view`.
pub fn run(args: &ViewArgs) -> Result<()> {
    let scene = match (&args.vtu, &args.model, &args.dataset) {
        (Some(file), _, _) => file_scene(file)?,
        (None, Some(model), Some(dataset)) => {
            let (scene, lines) =
                dataset_sample_scene(model, dataset, args.sample, args.mesh.as_deref(), args.scenario.as_deref())?;
            print_lines(&lines);
            scene
        }
        _ => bail!("give --model and --dataset (a dataset sample), or --vtu FILE (a mesh file with displacements)"),
    };
    plot::viewer::write_html(&args.out, &scene)?;
    println!("wrote      {} (open it in a browser)", args.out.display());
    Ok(())
}

/// The scene of a mesh file's displacement fields.
fn file_scene(path: &Path) -> Result<Scene> {
    let (scene, fields) = mesh_file_scene(path)?;
    println!(
        "mesh       {} nodes, {} surface triangles; displacement fields: {}",
        scene.rest.len(),
        scene.triangles.len(),
        if fields.is_empty() { "none".into() } else { fields.join(", ") }
    );
    Ok(scene)
}
