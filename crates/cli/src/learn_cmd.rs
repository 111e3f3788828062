//! Learning commands: `generate`, `merge`, `train`, `eval`, `predict`.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use fem::{Material, SolverOptions};
use indicatif::{ProgressBar, ProgressStyle};
use learn::generate::{DatasetConfig, Generator};
use learn::{
    Corruption, Dataset, DatasetPart, Initialization, Samples, Sparsity, Split, TrainConfig, TrainOptions,
    TrainedModel, UNetConfig,
};
use mesh::io::Field;
use serde::Deserialize;

use crate::scenario::MeshSource;

/// A dataset scenario file: the FEM model and how samples are drawn.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DatasetScenario {
    /// Short name (the default output directory is `out/<name>`).
    pub name: String,
    /// Free text.
    #[serde(default)]
    pub description: String,
    /// The organ or beam.
    pub mesh: MeshSource,
    /// The material.
    pub material: Material,
    /// Newton-Raphson settings.
    #[serde(default)]
    pub solver: SolverOptions,
    /// Sampling of loads and encoding on the grid.
    pub dataset: DatasetConfig,
}

/// `augsim generate`.
pub fn generate(path: &Path, out: Option<&Path>, part: Option<&str>, samples: Option<usize>) -> Result<()> {
    let text = std::fs::read_to_string(path).with_context(|| format!("cannot read scenario {}", path.display()))?;
    let mut scenario: DatasetScenario =
        toml::from_str(&text).with_context(|| format!("invalid scenario {}", path.display()))?;
    if let Some(n) = samples {
        scenario.dataset.samples = n;
    }
    let part = part.map(parse_part).transpose()?;
    let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
    let mesh = crate::scenario::build_mesh(&scenario.mesh, &dir).context("building the mesh")?;
    println!("scenario   {}: {}", scenario.name, scenario.description);
    println!("mesh       {} nodes, {} {} cells", mesh.num_nodes(), mesh.cells.len(), mesh.cells.kind_name());
    let generator = Generator::new(mesh, scenario.material, scenario.solver.clone(), scenario.dataset.clone())?;
    let grid = generator.grid();
    println!(
        "grid       {} × {} × {} ({} nodes inside)",
        grid.nx,
        grid.ny,
        grid.nz,
        generator.mask().iter().filter(|&&m| m == 1).count()
    );
    let out = out.map(Path::to_path_buf).unwrap_or_else(|| match &part {
        None => PathBuf::from(format!("out/{}", scenario.name)),
        Some(p) => PathBuf::from(format!("out/{}.part{}of{}", scenario.name, p.index, p.count)),
    });
    let bar = ProgressBar::new(0).with_style(
        ProgressStyle::with_template("{spinner} {bar:40} {pos}/{len} samples, {per_sec}, eta {eta}")
            .expect("valid template"),
    );
    let start = std::time::Instant::now();
    let manifest = generator.run(&out, &scenario.name, part, &|done, total| {
        bar.set_length(total);
        bar.set_position(done);
    })?;
    bar.finish_and_clear();
    let secs = start.elapsed().as_secs_f64();
    println!("samples    {} written, {} failed (reasons in the manifest)", manifest.num_samples, manifest.failed.len());
    println!("time       {:.1} s ({:.1} ms per sample)", secs, 1e3 * secs / manifest.num_samples.max(1) as f64);
    println!("wrote      {}", out.display());
    Ok(())
}

fn parse_part(s: &str) -> Result<DatasetPart> {
    let (i, n) = s.split_once('/').with_context(|| format!("--shard expects i/n, got '{s}'"))?;
    let part = DatasetPart {
        index: i.trim().parse().context("shard index")?,
        count: n.trim().parse().context("shard count")?,
    };
    if part.count == 0 || part.index >= part.count {
        bail!("--shard {s}: need 0 ≤ i < n");
    }
    Ok(part)
}

/// `augsim merge`.
pub fn merge(out: &Path, parts: &[PathBuf]) -> Result<()> {
    let manifest = learn::merge_datasets(parts, out, None)?;
    println!(
        "merged {} parts: {} samples, {} failed → {}",
        parts.len(),
        manifest.num_samples,
        manifest.failed.len(),
        out.display()
    );
    Ok(())
}

/// Input corruption, shared by `train` (training and validation inputs) and `eval`.
#[derive(Debug, Clone, clap::Args)]
pub struct CorruptionArgs {
    /// Keep a random visible patch of between MIN and MAX input nodes (e.g. 13,114).
    #[arg(long, value_delimiter = ',', num_args = 2)]
    pub sparse: Option<Vec<usize>>,
    /// Additive Gaussian noise on the visible input nodes: standard deviation in the input unit.
    #[arg(long, default_value_t = 0.0)]
    pub noise: f64,
}

impl CorruptionArgs {
    fn corruption(&self) -> Corruption {
        Corruption {
            sparsity: self.sparse.as_ref().map(|v| Sparsity::Patch { min_nodes: v[0], max_nodes: v[1] }),
            noise_std: self.noise,
        }
    }
}

/// How `train` splits the dataset (by generation index: the last samples are the test set, the
/// ones before them the validation set, the rest the training set).
#[derive(Debug, Clone, clap::Args)]
pub struct SplitArgs {
    /// Fraction of the dataset held out as the test set (its last samples).
    #[arg(long, default_value_t = 0.2)]
    pub test_fraction: f64,
    /// Number of test samples; overrides --test-fraction.
    #[arg(long)]
    pub test_samples: Option<usize>,
    /// Fraction of the dataset used for validation (checkpoint selection): the samples before the
    /// test set.
    #[arg(long, default_value_t = 0.1)]
    pub validation_fraction: f64,
    /// Number of validation samples; overrides --validation-fraction.
    #[arg(long)]
    pub validation_samples: Option<usize>,
}

impl SplitArgs {
    fn split(&self, all: &Samples) -> Result<Split> {
        let count = |fraction: f64, given: Option<usize>, flag: &str| -> Result<usize> {
            if !(0.0..1.0).contains(&fraction) {
                bail!("--{flag}-fraction must lie in [0, 1), got {fraction}");
            }
            Ok(given.unwrap_or((all.len() as f64 * fraction).round() as usize))
        };
        let test = count(self.test_fraction, self.test_samples, "test")?;
        let validation = count(self.validation_fraction, self.validation_samples, "validation")?;
        Ok(Split::last(all, validation, test)?)
    }
}

/// Options of `augsim train`.
#[derive(Debug, clap::Args)]
pub struct TrainArgs {
    /// Dataset directory (from `augsim generate`).
    pub dataset: PathBuf,
    /// Output directory (model.json, model.safetensors, checkpoint.bin, curve.csv, curve.png).
    #[arg(short, long)]
    pub out: PathBuf,
    /// Optimiser steps.
    #[arg(long, default_value_t = 2000)]
    pub iterations: usize,
    /// Samples per step.
    #[arg(long, default_value_t = 4)]
    pub batch: usize,
    /// Adam learning rate.
    #[arg(long, default_value_t = 1e-3)]
    pub lr: f64,
    /// Let the learning rate fall to this value along a half cosine over the iterations.
    #[arg(long)]
    pub final_lr: Option<f64>,
    /// Channels of the first U-Net level.
    #[arg(long, default_value_t = 16)]
    pub channels: usize,
    /// Down-sampling steps of the U-Net.
    #[arg(long, default_value_t = 3)]
    pub depth: usize,
    /// Use only the first N training samples (e.g. 100 for transfer learning).
    #[arg(long)]
    pub train_samples: Option<usize>,
    /// Fine-tune this pre-trained model (model.json) instead of starting from scratch.
    #[arg(long)]
    pub init: Option<PathBuf>,
    /// With --init: keep the encoder fixed.
    #[arg(long)]
    pub freeze_encoder: bool,
    /// Validate (and keep the best model) every K steps.
    #[arg(long, default_value_t = 100)]
    pub validate_every: usize,
    /// Seed of weights, batches and corruption.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Start afresh instead of resuming from out/checkpoint.bin.
    #[arg(long)]
    pub restart: bool,
    /// Train / validation / test split.
    #[command(flatten)]
    pub split: SplitArgs,
    /// Input corruption.
    #[command(flatten)]
    pub corruption: CorruptionArgs,
}

/// `augsim train`.
pub fn train(args: &TrainArgs) -> Result<()> {
    let dataset = Dataset::open(&args.dataset)?;
    let all = dataset.load_all()?;
    let split = args.split.split(&all)?;
    let [mut train, validation, test] = split.apply(&all)?;
    if let Some(n) = args.train_samples {
        if n == 0 || n > train.len() {
            bail!("--train-samples {n}: the training split has {} samples", train.len());
        }
        train = train.split_at(n)?.0;
    }
    let init = match &args.init {
        Some(model) => Initialization::FineTune { model: model.clone(), freeze_encoder: args.freeze_encoder },
        None => Initialization::Scratch {
            unet: UNetConfig { base_channels: args.channels, depth: args.depth, ..UNetConfig::default() },
            normalization: learn::Normalization::from_samples(&train),
            input_unit: dataset.manifest().units.input.clone(),
        },
    };
    let config = TrainConfig {
        iterations: args.iterations,
        batch_size: args.batch,
        learning_rate: args.lr,
        final_learning_rate: args.final_lr,
        seed: args.seed,
        validate_every: args.validate_every,
        checkpoint_every: args.validate_every,
        train_corruption: args.corruption.corruption(),
        val_corruption: args.corruption.corruption(),
    };
    let options = TrainOptions {
        out_dir: args.out.clone(),
        resume: !args.restart,
        progress: true,
        stop_after: None,
        placement: dataset.manifest().placement(),
        test: split.test,
    };
    println!(
        "split      {} training, {} validation, {} test samples (held out, recorded in the model); grid {}",
        train.len(),
        validation.len(),
        test.len(),
        dataset.manifest().grid
    );
    let outcome = learn::train(&train, &validation, &init, &config, &options)?;
    let best =
        outcome.curve.iter().filter_map(|r| r.val.map(|v| (r.iteration, v.mean))).min_by(|a, b| a.1.total_cmp(&b.1));
    println!("steps      {} ({:.3} s per step)", outcome.iterations_done, outcome.mean_step_seconds);
    if let Some((it, e)) = best {
        println!("best       validation mean e = {:.4} mm at iteration {it}", e * 1e3);
    }
    println!("wrote      {}", outcome.model_path.display());
    Ok(())
}

/// `augsim eval`: errors on the samples held out from the model (its recorded test split of
/// the dataset it was trained on, or every unseen sample of another dataset), per-sample CSV and
/// the worst sample as VTK.
pub fn eval(model_path: &Path, dataset_dir: &Path, corruption: &CorruptionArgs, out: &Path) -> Result<()> {
    let model = TrainedModel::load(model_path, &learn::inference_device())?;
    let dataset = Dataset::open(dataset_dir)?;
    if dataset.manifest().grid != model.grid {
        bail!("the model was trained on grid {} but the dataset is on grid {}", model.grid, dataset.manifest().grid);
    }
    let all = dataset.load_all()?;
    let test = model.held_out(&all)?;
    if test.is_empty() {
        bail!("{} holds no sample held out from this model (no test split recorded for it)", dataset_dir.display());
    }
    println!(
        "held out   {} of {} samples ({})",
        test.len(),
        all.len(),
        if model.trained_on(&all) {
            "the test split recorded in the model"
        } else {
            "those no run behind the model trained or validated on"
        }
    );
    let markers = dataset.manifest().markers();
    let placement = dataset.manifest().placement();
    let (report, tre) = match placement {
        Some(placement) if !markers.is_empty() => {
            let grid = placement.grid(model.grid)?;
            let (report, tre) = learn::evaluate_at_points(&model, &test, &corruption.corruption(), 0, &grid, &markers)?;
            (report, Some(tre))
        }
        _ => (learn::evaluate(&model, &test, &corruption.corruption(), 0)?, None),
    };
    let s = &report.stats;
    println!("samples    {}", test.len());
    println!("mean e     {:.4e} m ({:.3} mm)", s.mean, s.mean * 1e3);
    println!("std e      {:.4e} m ({:.3} mm)", s.std, s.std * 1e3);
    println!("max e      {:.4e} m ({:.3} mm), sample index {}", s.max, s.max * 1e3, report.worst_index());
    if let Some(t) = &tre {
        println!(
            "TRE        {} markers: mean {:.3} mm, std {:.3} mm, max {:.3} mm (no-motion baseline: mean {:.3} mm, max {:.3} mm)",
            markers.len(),
            t.errors.mean * 1e3,
            t.errors.std * 1e3,
            t.errors.max * 1e3,
            t.no_motion.mean * 1e3,
            t.no_motion.max * 1e3
        );
    }
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let mut csv = String::from("index,error_m\n");
    for (i, e) in report.indices.iter().zip(&report.errors) {
        csv.push_str(&format!("{i},{e:e}\n"));
    }
    write_atomic(&out.join("errors.csv"), csv.as_bytes())?;
    let summary = serde_json::json!({
        "model": model_path, "dataset": dataset_dir, "samples": test.len(),
        "mean_m": s.mean, "std_m": s.std, "max_m": s.max, "worst_index": report.worst_index(),
        "corruption": corruption.corruption(), "marker_errors": tre,
    });
    write_atomic(&out.join("summary.json"), serde_json::to_string_pretty(&summary)?.as_bytes())?;
    let worst = test.get(s.worst);
    let input = learn::evaluation_input(&test, s.worst, &corruption.corruption(), 0)?;
    let prediction = model.predict(&input)?;
    let vtu = out.join("worst.vtu");
    write_grid_sample(&vtu, dataset.manifest(), &input, &worst.target, &prediction, &worst.mask)?;
    println!(
        "wrote      {}, {}, {}",
        out.join("errors.csv").display(),
        out.join("summary.json").display(),
        vtu.display()
    );
    Ok(())
}

/// The grid as an H8 mesh with input, reference and predicted displacement and the mask.
fn write_grid_sample(
    path: &Path,
    manifest: &learn::Manifest,
    input: &[f32],
    target: &[f32],
    pred: &[f32],
    mask: &[u8],
) -> Result<()> {
    let g = manifest.grid;
    let placement = manifest.placement().context("the dataset manifest has no grid_origin/grid_spacing")?;
    let grid = placement.grid(g)?;
    let grid_mesh = mesh::box_hex(grid.origin, grid.upper(), [g.nx - 1, g.ny - 1, g.nz - 1])?;
    // box_hex numbers nodes x fastest; the tensors are z fastest.
    let n = g.nodes();
    let to_points = |field: &[f32]| -> Vec<f64> {
        let mut out = vec![0.0; 3 * n];
        for k in 0..g.nz {
            for j in 0..g.ny {
                for i in 0..g.nx {
                    let node = i + g.nx * (j + g.ny * k);
                    for c in 0..3 {
                        out[3 * node + c] = field[c * n + g.node_index(i, j, k)] as f64;
                    }
                }
            }
        }
        out
    };
    let mask3: Vec<f32> = (0..3).flat_map(|_| mask.iter().map(|&m| m as f32)).collect();
    let mask_points: Vec<f64> = to_points(&mask3).chunks(3).map(|c| c[0]).collect();
    let fields = [
        Field::point("input", 3, to_points(input)),
        Field::point("reference", 3, to_points(target)),
        Field::point("prediction", 3, to_points(pred)),
        Field::point("mask", 1, mask_points),
    ];
    mesh::io::write_mesh(path, &grid_mesh, &fields).with_context(|| format!("writing {}", path.display()))
}

/// `augsim predict`: a grid tensor (.npy `[3, nx, ny, nz]`) or a point cloud (.csv or .npy
/// `[N, 6]`: x, y, z and the vector in the model's input unit) to a displacement tensor, timed;
/// with `mesh`, the displacement interpolated to that mesh's nodes is written beside the tensor.
pub fn predict(model_path: &Path, input: &Path, output: &Path, mesh_path: Option<&Path>, runs: usize) -> Result<()> {
    let model = TrainedModel::load(model_path, &learn::inference_device())?;
    let g = model.grid;
    let placed = || -> Result<mesh::embedding::Grid> {
        let placement = model.placement.with_context(|| {
            format!(
                "{} does not record where its grid lies (trained before grid placement was stored)",
                model_path.display()
            )
        })?;
        Ok(placement.grid(g)?)
    };
    let data = match read_predict_input(input)? {
        PredictInput::Grid(array) => {
            if array.shape != [3, g.nx, g.ny, g.nz] {
                bail!(
                    "{}: shape {:?}, but the model expects [3, {}, {}, {}] (or a point cloud [N, 6])",
                    input.display(),
                    array.shape,
                    g.nx,
                    g.ny,
                    g.nz
                );
            }
            array.into_f32()
        }
        PredictInput::Points(points, vectors) => {
            let force = match model.input_unit.as_str() {
                "N" => true,
                "m" => false,
                other => bail!("model input unit {other:?} is neither N (forces) nor m (displacements)"),
            };
            let t0 = std::time::Instant::now();
            let data = learn::encode_points(&placed()?, &points, &vectors, force)
                .with_context(|| format!("mapping {} onto the model grid", input.display()))?;
            let what = if force { "forces spread to the grid" } else { "displacements on their nearest grid nodes" };
            println!("points     {} ({what}, {:.2} ms)", points.len(), t0.elapsed().as_secs_f64() * 1e3);
            data
        }
    };
    let predictor = learn::Predictor::new(&model)?;
    let prediction = predictor.predict(&data)?;
    learn::npy::write_f32(output, &[3, g.nx, g.ny, g.nz], &prediction)?;
    let t = learn::time_prediction(&predictor, &data, 3, runs.max(1))?;
    println!(
        "prediction {} runs: median {:.2} ms, mean {:.2} ± {:.2} ms, min {:.2}, max {:.2}",
        t.runs,
        t.median * 1e3,
        t.mean * 1e3,
        t.std * 1e3,
        t.min * 1e3,
        t.max * 1e3
    );
    println!("wrote      {}", output.display());
    if let Some(mesh_path) = mesh_path {
        let organ = mesh::io::read_mesh(mesh_path).with_context(|| format!("reading {}", mesh_path.display()))?;
        let u = learn::GridToMesh::new(&organ, &placed()?)?.apply(&prediction)?;
        let max = u.chunks(3).map(|v| (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()).fold(0.0, f64::max);
        let vtu = output.with_extension("vtu");
        mesh::io::write_mesh(&vtu, &organ, &[Field::point("displacement", 3, u)])
            .with_context(|| format!("writing {}", vtu.display()))?;
        println!("mesh       {} nodes, max |u| {:.3} mm", organ.num_nodes(), max * 1e3);
        println!("wrote      {}", vtu.display());
    }
    Ok(())
}

/// What `augsim predict` reads.
enum PredictInput {
    /// A grid tensor.
    Grid(learn::npy::NpyArray),
    /// Points and their vectors.
    Points(Vec<mesh::Point>, Vec<[f64; 3]>),
}

/// Reads a grid tensor or a point cloud (`.npy` `[N, 6]`, or `.csv` with six numbers per line
/// and an optional header line).
fn read_predict_input(path: &Path) -> Result<PredictInput> {
    let rows: Vec<[f64; 6]> = if path.extension().is_some_and(|e| e.eq_ignore_ascii_case("csv")) {
        let text = std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
        let mut rows = Vec::new();
        for (l, line) in text.lines().enumerate() {
            let fields: Vec<&str> = line.split([',', ';']).map(str::trim).filter(|f| !f.is_empty()).collect();
            if fields.is_empty() {
                continue;
            }
            let numbers: Result<Vec<f64>, _> = fields.iter().map(|f| f.parse::<f64>()).collect();
            match numbers {
                Ok(v) if v.len() == 6 => rows.push([v[0], v[1], v[2], v[3], v[4], v[5]]),
                Ok(v) => bail!("{}:{}: {} numbers, expected 6 (x, y, z, vx, vy, vz)", path.display(), l + 1, v.len()),
                Err(_) if l == 0 => {} // header
                Err(e) => bail!("{}:{}: {e}", path.display(), l + 1),
            }
        }
        rows
    } else {
        let array = learn::npy::read_npy(path)?;
        match array.shape.as_slice() {
            [_, 6] => array.into_f64().chunks_exact(6).map(|r| std::array::from_fn(|i| r[i])).collect(),
            _ => return Ok(PredictInput::Grid(array)),
        }
    };
    if rows.is_empty() {
        bail!("{}: no points", path.display());
    }
    Ok(PredictInput::Points(
        rows.iter().map(|r| [r[0], r[1], r[2]]).collect(),
        rows.iter().map(|r| [r[3], r[4], r[5]]).collect(),
    ))
}

/// Writes a file atomically (temporary file in the same directory, then rename).
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    use std::io::Write;
    mesh::io::write_file_atomic(path, |f| f.write_all(bytes)).with_context(|| format!("writing {}", path.display()))
}
