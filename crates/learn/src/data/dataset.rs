//! Sharded datasets of (input, target, mask) samples on a regular grid.
//!
//! On disk a dataset is a directory:
//!
//! ```text
//! manifest.json              JSON manifest (see [`Manifest`])
//! shard_00000/inputs.npy     [N, 3, nx, ny, nz] float32  (forces in N or displacements in m)
//! shard_00000/targets.npy    [N, 3, nx, ny, nz] float32  (displacements in m)
//! shard_00000/masks.npy      [N, nx, ny, nz]    uint8    (1 inside the organ)
//! shard_00001/...
//! ```
//!
//! Python reads it with numpy alone (`json.load` + `numpy.load`). Every file is written
//! atomically; a shard is committed by rewriting the manifest after its three files are in
//! place, so a killed writer leaves a consistent dataset that [`DatasetWriter::create_or_resume`]
//! continues. Samples carry their generation index (the random seed of a sample is derived from
//! the dataset seed and this index by the generator), and a generation that failed is recorded
//! with its reason instead of a sample. A dataset with σ-chosen draws ([`crate::choosing`])
//! records how they were chosen in its manifest and keeps the models that chose them in `chosen/`.

use std::ops::Range;
use std::path::{Path, PathBuf};

use mesh::io::write_atomic_bytes;
use mesh::Point;
use serde::{Deserialize, Serialize};

use crate::data::chosen::ChosenDraws;
use crate::data::grid::{unfit_value, GridPlacement, GridShape, CHANNELS, LAYOUT, MAX_FIELD_VALUE};
use crate::{LearnError, Result};
use mesh::io::npy;

/// Value of the manifest's `format` field.
pub const FORMAT: &str = "augsim-dataset";
/// Version of the manifest layout written by this crate.
pub const VERSION: u32 = 1;
/// File name of the manifest inside a dataset directory.
pub const MANIFEST_FILE: &str = "manifest.json";

/// Which part of a dataset a worker writes when generation is split over `count` workers.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DatasetPart {
    /// This worker's number, `0..count`.
    pub index: usize,
    /// Number of workers.
    pub count: usize,
}

/// What a dataset is: everything fixed when it is created.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DatasetSpec {
    /// Scenario name.
    pub scenario: String,
    /// Base random seed of the generation (per-sample seeds derive from it and the index).
    pub seed: u64,
    /// The part written by this worker, if generation is split.
    pub part: Option<DatasetPart>,
    /// The grid.
    pub grid: GridShape,
    /// Unit of the input field: forces or imposed displacements.
    pub input_unit: FieldUnit,
    /// Unit of the target field (displacements).
    pub target_unit: FieldUnit,
    /// Samples per shard.
    pub shard_size: usize,
    /// Free-form scenario parameters recorded by the generator.
    pub metadata: serde_json::Value,
}

impl DatasetSpec {
    /// The sample count the generator was asked for (`metadata.dataset.samples`), if recorded.
    pub fn requested_samples(&self) -> Option<u64> {
        self.metadata.get("dataset")?.get("samples")?.as_u64()
    }

    /// Whether `self` asks for more samples of the same whole (unsplit) dataset as `existing`:
    /// everything else equal, so that the first samples stay those `existing` holds.
    fn grows(&self, existing: &DatasetSpec) -> bool {
        let larger = matches!((self.requested_samples(), existing.requested_samples()), (Some(a), Some(b)) if a > b);
        larger && self.same_but_count(existing)
    }

    /// Whether `self` and `other` are the same whole (unsplit) dataset but for the sample count.
    fn same_but_count(&self, other: &DatasetSpec) -> bool {
        let without_count = |spec: &DatasetSpec| {
            let mut spec = spec.clone();
            if let Some(config) = spec.metadata.get_mut("dataset").and_then(|d| d.as_object_mut()) {
                config.remove("samples");
            }
            spec
        };
        self.part.is_none() && other.part.is_none() && without_count(self) == without_count(other)
    }
}

/// Where two records (JSON: a dataset's spec, a preparation's options) differ, in words, one line
/// per differing value with its dotted path: `metadata.dataset.samples 12 there, 5 now`.
pub fn json_differences(recorded: &serde_json::Value, new: &serde_json::Value) -> Vec<String> {
    fn walk(path: &str, a: &serde_json::Value, b: &serde_json::Value, out: &mut Vec<String>) {
        use serde_json::Value::{Null, Object};
        match (a, b) {
            (Object(a), Object(b)) => {
                let mut keys: Vec<&String> = a.keys().chain(b.keys().filter(|k| !a.contains_key(*k))).collect();
                keys.sort();
                for key in keys {
                    let path = if path.is_empty() { key.clone() } else { format!("{path}.{key}") };
                    walk(&path, a.get(key).unwrap_or(&Null), b.get(key).unwrap_or(&Null), out);
                }
            }
            _ if a != b => out.push(format!("{path} {a} there, {b} now")),
            _ => {}
        }
    }
    let mut out = Vec::new();
    walk("", recorded, new, &mut out);
    out
}

impl DatasetSpec {
    /// Why a dataset created with `self` cannot take `new`'s draws, in words: what differs (see
    /// [`json_differences`]), and that a dataset grows but does not shrink.
    fn mismatch(&self, new: &DatasetSpec) -> String {
        let mut why = format!("it was created otherwise ({})", self.differences(new).join("; "));
        if let (Some(held), Some(asked)) = (self.requested_samples(), new.requested_samples()) {
            if asked < held && self.same_but_count(new) {
                why = format!(
                    "it was made for {held} draws: --samples grows a dataset but does not shrink it (train on fewer \
                     with `augsim train --train-samples`, or give another --out)"
                );
            }
        }
        why
    }

    /// What differs from `self` in `new`, one value a line ([`json_differences`]: "there" is
    /// `self`'s, "now" `new`'s), each said once.
    fn differences(&self, new: &DatasetSpec) -> Vec<String> {
        let as_json = |spec: &DatasetSpec| serde_json::to_value(spec).unwrap_or(serde_json::Value::Null);
        let differences = json_differences(&as_json(self), &as_json(new));
        // The generator records the seed and shard size in the metadata too: each is said once.
        let top_level = |d: &&String| !d.split(' ').next().unwrap_or_default().contains('.');
        let repeated = |d: &&String| {
            d.starts_with("metadata.")
                && differences.iter().filter(top_level).any(|top| d.ends_with(&format!(".{top}")))
        };
        differences.iter().filter(|d| !repeated(d)).cloned().collect()
    }
}

/// Units of the stored fields.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Units {
    /// Unit of the inputs.
    pub input: FieldUnit,
    /// Unit of the targets.
    pub target: FieldUnit,
}

/// The unit of a dataset's or a model's field: forces or displacements (written "N" and "m").
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum FieldUnit {
    /// Newtons: nodal forces.
    #[serde(rename = "N")]
    Newton,
    /// Metres: displacements.
    #[serde(rename = "m")]
    Metre,
}

impl FieldUnit {
    /// Its symbol: "N" or "m".
    pub fn symbol(self) -> &'static str {
        match self {
            FieldUnit::Newton => "N",
            FieldUnit::Metre => "m",
        }
    }

    /// Whether it is a force's (rather than a displacement's).
    pub fn is_force(self) -> bool {
        self == FieldUnit::Newton
    }
}

impl std::fmt::Display for FieldUnit {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.symbol())
    }
}

/// A generation index that produced no sample, and why.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FailedSample {
    /// The generation index.
    pub index: u64,
    /// Why it failed.
    pub reason: String,
}

/// Per-shard sums from which the statistics are derived (kept so that merges and resumed
/// writes reproduce the statistics of an uninterrupted write exactly).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StatSums {
    /// Nodes with a nonzero input vector.
    pub input_nodes: u64,
    /// Per-channel sum of the inputs over those nodes.
    pub input_sum: [f64; 3],
    /// Per-channel sum of squared inputs over those nodes.
    pub input_sum_sq: [f64; 3],
    /// Nodes inside the mask.
    pub target_nodes: u64,
    /// Per-channel sum of the targets over masked nodes.
    pub target_sum: [f64; 3],
    /// Per-channel sum of squared targets over masked nodes.
    pub target_sum_sq: [f64; 3],
}

impl StatSums {
    fn add_sample(&mut self, grid: GridShape, input: &[f32], target: &[f32], mask: &[u8]) {
        let n = grid.nodes();
        for node in 0..n {
            let v = [input[node], input[n + node], input[2 * n + node]];
            if v.iter().any(|&x| x != 0.0) {
                self.input_nodes += 1;
                for (c, &x) in v.iter().enumerate() {
                    self.input_sum[c] += f64::from(x);
                    self.input_sum_sq[c] += f64::from(x) * f64::from(x);
                }
            }
            if mask[node] != 0 {
                self.target_nodes += 1;
                for c in 0..CHANNELS {
                    let u = f64::from(target[c * n + node]);
                    self.target_sum[c] += u;
                    self.target_sum_sq[c] += u * u;
                }
            }
        }
    }

    fn add(&mut self, other: &StatSums) {
        self.input_nodes += other.input_nodes;
        self.target_nodes += other.target_nodes;
        for c in 0..CHANNELS {
            self.input_sum[c] += other.input_sum[c];
            self.input_sum_sq[c] += other.input_sum_sq[c];
            self.target_sum[c] += other.target_sum[c];
            self.target_sum_sq[c] += other.target_sum_sq[c];
        }
    }
}

/// Refuses a shard whose arrays (`samples`) do not give the sums its manifest entry (`info`, in
/// `manifest`) recorded as it was written: one changed since (a mask, a unit, files swapped)
/// would otherwise train or evaluate silently on other data.
fn check_sums(info: &ShardInfo, samples: &Samples, manifest: &Path) -> Result<()> {
    let (found, recorded) = (samples.sums(), &info.sums);
    let close = |a: &[f64; 3], b: &[f64; 3]| {
        a.iter().zip(b).all(|(x, y)| (x - y).abs() <= 1e-9 * x.abs().max(y.abs()) + f64::MIN_POSITIVE)
    };
    let differs = [
        ("nodes with an input", found.input_nodes != recorded.input_nodes, info.inputs.as_str()),
        ("sums of the inputs", !close(&found.input_sum, &recorded.input_sum), info.inputs.as_str()),
        ("sums of the squared inputs", !close(&found.input_sum_sq, &recorded.input_sum_sq), info.inputs.as_str()),
        ("masked nodes", found.target_nodes != recorded.target_nodes, info.masks.as_str()),
        ("sums of the targets", !close(&found.target_sum, &recorded.target_sum), info.targets.as_str()),
        ("sums of the squared targets", !close(&found.target_sum_sq, &recorded.target_sum_sq), info.targets.as_str()),
    ];
    match differs.iter().find(|(_, differ, _)| *differ) {
        Some((what, _, file)) => Err(LearnError::InvalidInput(format!(
            "{file}: its {what} differ from those {} recorded as it was written: the shard was changed since (a \
             mask, a unit, files swapped); generate it again",
            manifest.display()
        ))),
        None => Ok(()),
    }
}

/// Statistics of one field: per-channel mean and standard deviation, and the RMS of the vector
/// norm, over the counted nodes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ChannelStats {
    /// Number of counted nodes (inputs: nodes with a nonzero input; targets: masked nodes).
    pub nodes: u64,
    /// Per-channel mean.
    pub mean: [f64; 3],
    /// Per-channel standard deviation (population).
    pub std: [f64; 3],
    /// Root mean square of the vector norm, `sqrt(Σ_c Σ v_c² / nodes)`.
    pub rms_norm: f64,
}

impl ChannelStats {
    fn from_sums(nodes: u64, sum: &[f64; 3], sum_sq: &[f64; 3]) -> Self {
        if nodes == 0 {
            return ChannelStats::default();
        }
        let n = nodes as f64;
        let mean = [sum[0] / n, sum[1] / n, sum[2] / n];
        let std = [0, 1, 2].map(|c| (sum_sq[c] / n - mean[c] * mean[c]).max(0.0).sqrt());
        let rms_norm = ((sum_sq[0] + sum_sq[1] + sum_sq[2]) / n).sqrt();
        ChannelStats { nodes, mean, std, rms_norm }
    }
}

/// Dataset statistics: inputs over nodes with a nonzero input vector, targets over masked nodes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Statistics {
    /// Input statistics.
    pub inputs: ChannelStats,
    /// Target statistics.
    pub targets: ChannelStats,
}

impl Statistics {
    fn from_sums(s: &StatSums) -> Self {
        Statistics {
            inputs: ChannelStats::from_sums(s.input_nodes, &s.input_sum, &s.input_sum_sq),
            targets: ChannelStats::from_sums(s.target_nodes, &s.target_sum, &s.target_sum_sq),
        }
    }
}

/// Global scales applied to inputs and targets before they reach the network: the network sees
/// `input / input_scale` and predicts `target / target_scale`. One scale per field (not per
/// channel) keeps vector directions; no offset keeps "no load" and "outside the organ" at zero.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Normalization {
    /// Scale of the inputs (input unit).
    pub input_scale: f64,
    /// Scale of the targets (m).
    pub target_scale: f64,
}

impl Normalization {
    /// No scaling.
    pub fn identity() -> Self {
        Normalization { input_scale: 1.0, target_scale: 1.0 }
    }

    /// Scales from dataset statistics: the RMS norms of inputs and targets (1 where a field is
    /// all zero).
    pub fn from_statistics(stats: &Statistics) -> Self {
        let positive = |x: f64| if x > 0.0 && x.is_finite() { x } else { 1.0 };
        Normalization { input_scale: positive(stats.inputs.rms_norm), target_scale: positive(stats.targets.rms_norm) }
    }

    /// Scales from the statistics of `samples` alone (the training samples: nothing of the
    /// validation or test samples may shape the model).
    pub fn from_samples(samples: &Samples) -> Self {
        Normalization::from_statistics(&samples.statistics())
    }

    /// Checks that both scales are finite and positive.
    pub fn validate(&self) -> Result<()> {
        for (name, x) in [("input_scale", self.input_scale), ("target_scale", self.target_scale)] {
            if !(x > 0.0 && x.is_finite()) {
                return Err(LearnError::InvalidInput(format!("normalization {name} must be finite and > 0, got {x}")));
            }
        }
        Ok(())
    }
}

/// One committed shard.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ShardInfo {
    /// Shard directory name (`shard_00000`).
    pub name: String,
    /// Number of samples.
    pub num_samples: usize,
    /// Generation index of each sample, increasing.
    pub indices: Vec<u64>,
    /// Inputs file, relative to the dataset directory.
    pub inputs: String,
    /// Targets file, relative to the dataset directory.
    pub targets: String,
    /// Masks file, relative to the dataset directory.
    pub masks: String,
    /// Sums for the statistics.
    pub sums: StatSums,
}

/// The dataset manifest (`manifest.json`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Manifest {
    /// Always [`FORMAT`].
    pub format: String,
    /// Manifest layout version ([`VERSION`]).
    pub version: u32,
    /// Scenario name.
    pub scenario: String,
    /// Base random seed.
    pub seed: u64,
    /// Part written by this worker, if any.
    pub part: Option<DatasetPart>,
    /// The grid.
    pub grid: GridShape,
    /// Channels of inputs and targets (3).
    pub channels: usize,
    /// The tensor layout ([`LAYOUT`]).
    pub layout: String,
    /// Units of inputs and targets.
    pub units: Units,
    /// Samples per shard.
    pub shard_size: usize,
    /// Number of committed samples.
    pub num_samples: usize,
    /// First generation index not yet committed (samples and failures).
    pub next_index: u64,
    /// Whether the writer finished.
    pub complete: bool,
    /// Statistics over all committed samples.
    pub statistics: Statistics,
    /// Generation indices that failed.
    pub failed: Vec<FailedSample>,
    /// The shards, in index order.
    pub shards: Vec<ShardInfo>,
    /// Free-form scenario parameters.
    pub metadata: serde_json::Value,
    /// How the σ-chosen draws after the uniform ones were chosen, round by round
    /// (`augsim generate --chosen-by`); absent when every draw is uniform.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub chosen: Option<ChosenDraws>,
}

impl Manifest {
    /// Where the grid lies in space, from the generator's metadata (`grid_origin`,
    /// `grid_spacing`); `None` for datasets without them.
    pub fn placement(&self) -> Option<GridPlacement> {
        let get = |key: &str| serde_json::from_value::<[f64; 3]>(self.metadata.get(key)?.clone()).ok();
        Some(GridPlacement { origin: get("grid_origin")?, spacing: get("grid_spacing")? })
    }

    /// Internal marker positions recorded by the generator (`markers` in the metadata: the
    /// mesh's "markers" region); empty when there are none.
    pub fn markers(&self) -> Vec<Point> {
        self.metadata.get("markers").and_then(|m| serde_json::from_value(m.clone()).ok()).unwrap_or_default()
    }

    pub(crate) fn new(spec: &DatasetSpec) -> Self {
        Manifest {
            format: FORMAT.into(),
            version: VERSION,
            scenario: spec.scenario.clone(),
            seed: spec.seed,
            part: spec.part.clone(),
            grid: spec.grid,
            channels: CHANNELS,
            layout: LAYOUT.into(),
            units: Units { input: spec.input_unit, target: spec.target_unit },
            shard_size: spec.shard_size,
            num_samples: 0,
            next_index: 0,
            complete: false,
            statistics: Statistics::default(),
            failed: Vec::new(),
            shards: Vec::new(),
            metadata: spec.metadata.clone(),
            chosen: None,
        }
    }

    /// Identifies where the samples come from: the scenario, seed, grid, units and generator
    /// settings, but not the sample count, shard size or worker part. Two datasets with the same
    /// source hold the same sample under the same generation index (a smaller dataset generated
    /// with the same seed shares its first samples with a larger one).
    pub fn source_id(&self) -> String {
        let mut metadata = self.metadata.clone();
        if let Some(config) = metadata.get_mut("dataset").and_then(|d| d.as_object_mut()) {
            config.remove("samples");
            config.remove("shard_size");
        }
        let key = serde_json::json!([self.grid, self.units, metadata]).to_string();
        format!("{}/seed {}/{:016x}", self.scenario, self.seed, fnv1a(key.as_bytes()))
    }

    /// The specification this dataset was created with.
    pub fn spec(&self) -> DatasetSpec {
        DatasetSpec {
            scenario: self.scenario.clone(),
            seed: self.seed,
            part: self.part.clone(),
            grid: self.grid,
            input_unit: self.units.input,
            target_unit: self.units.target,
            shard_size: self.shard_size,
            metadata: self.metadata.clone(),
        }
    }

    /// Reads and validates a manifest file.
    pub fn read(path: &Path) -> Result<Manifest> {
        let text = std::fs::read_to_string(path).map_err(|e| LearnError::io(path, e))?;
        let manifest: Manifest = serde_json::from_str(&text)
            .map_err(|e| LearnError::manifest(path, format!("invalid manifest JSON: {e}")))?;
        manifest.validate(path)?;
        Ok(manifest)
    }

    fn write(&self, path: &Path) -> Result<()> {
        let text = serde_json::to_string_pretty(self)
            .map_err(|e| LearnError::manifest(path, format!("cannot serialize manifest: {e}")))?;
        Ok(write_atomic_bytes(path, text.as_bytes())?)
    }

    /// Checks internal consistency (not the shard files).
    fn validate(&self, path: &Path) -> Result<()> {
        let err = |m: String| Err(LearnError::manifest(path, m));
        if self.format != FORMAT {
            return err(format!("format is {:?}, expected {FORMAT:?}", self.format));
        }
        if self.version != VERSION {
            return err(format!("manifest version {} is not supported (expected {VERSION})", self.version));
        }
        if self.channels != CHANNELS {
            return err(format!("channels is {}, expected {CHANNELS}", self.channels));
        }
        if self.grid.nodes() == 0 {
            return err(format!("grid {} has no nodes", self.grid));
        }
        if self.shard_size == 0 {
            return err("shard_size is 0".into());
        }
        let mut total = 0;
        let mut last: Option<u64> = None;
        for shard in &self.shards {
            if shard.indices.len() != shard.num_samples {
                return err(format!(
                    "shard {} lists {} indices for {} samples",
                    shard.name,
                    shard.indices.len(),
                    shard.num_samples
                ));
            }
            for file in [&shard.inputs, &shard.targets, &shard.masks] {
                let p = Path::new(file);
                if p.is_absolute() || p.components().any(|c| matches!(c, std::path::Component::ParentDir)) {
                    return err(format!(
                        "shard {} file {file:?} must be a relative path inside the dataset",
                        shard.name
                    ));
                }
            }
            for &i in &shard.indices {
                if last.is_some_and(|l| i <= l) {
                    return err(format!("sample indices are not increasing at index {i} in shard {}", shard.name));
                }
                last = Some(i);
            }
            total += shard.num_samples;
        }
        if total != self.num_samples {
            return err(format!("num_samples is {} but the shards hold {total}", self.num_samples));
        }
        if let Some(chosen) = &self.chosen {
            chosen.validate().or_else(err)?;
        }
        let max_failed = self.failed.iter().map(|f| f.index).max();
        if let Some(m) = last.into_iter().chain(max_failed).max() {
            if m >= self.next_index {
                return err(format!("next_index {} is not past the last recorded index {m}", self.next_index));
            }
        }
        Ok(())
    }
}

/// The 64-bit FNV-1a hash of `bytes`.
pub(crate) fn fnv1a(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325u64, |h, &b| (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3))
}

/// One sample: input field, target field (both `[3, nx, ny, nz]`) and mask (`[nx, ny, nz]`).
#[derive(Clone, Debug, PartialEq)]
pub struct Sample {
    /// Generation index.
    pub index: u64,
    /// Input field `C` (N or m).
    pub input: Vec<f32>,
    /// Target displacement `U` (m).
    pub target: Vec<f32>,
    /// Mask, 1 inside the organ.
    pub mask: Vec<u8>,
}

impl Sample {
    /// Checks lengths, finiteness and mask values against the grid.
    pub fn validate(&self, grid: GridShape) -> Result<()> {
        let bad = |m: String| Err(LearnError::InvalidInput(format!("sample {}: {m}", self.index)));
        if self.input.len() != grid.field_len() {
            return bad(format!("input has {} values, grid {grid} needs {}", self.input.len(), grid.field_len()));
        }
        if self.target.len() != grid.field_len() {
            return bad(format!("target has {} values, grid {grid} needs {}", self.target.len(), grid.field_len()));
        }
        if self.mask.len() != grid.nodes() {
            return bad(format!("mask has {} values, grid {grid} needs {}", self.mask.len(), grid.nodes()));
        }
        if let Some(x) = self.mask.iter().find(|&&m| m > 1) {
            return bad(format!("mask value {x} is not 0 or 1"));
        }
        if self.input.iter().chain(&self.target).any(|x| !x.is_finite()) {
            return bad("input or target has a non-finite value".into());
        }
        Ok(())
    }
}

/// A set of samples in memory, stored contiguously in the shard layout.
#[derive(Clone, Debug, PartialEq)]
pub struct Samples {
    /// The grid.
    pub grid: GridShape,
    /// Generation index of each sample.
    pub indices: Vec<u64>,
    /// Inputs, `[N, 3, nx, ny, nz]`.
    pub inputs: Vec<f32>,
    /// Targets, `[N, 3, nx, ny, nz]`.
    pub targets: Vec<f32>,
    /// Masks, `[N, nx, ny, nz]`.
    pub masks: Vec<u8>,
    /// The data source of the samples ([`Manifest::source_id`]) when they come from a dataset:
    /// with the generation indices, it tells which samples a model has already seen.
    pub source: Option<String>,
}

impl Samples {
    /// An empty set on `grid`, of no known source.
    pub fn new(grid: GridShape) -> Self {
        Samples { grid, indices: Vec::new(), inputs: Vec::new(), targets: Vec::new(), masks: Vec::new(), source: None }
    }

    /// Statistics of the samples (inputs over nodes with a nonzero input, targets over masked
    /// nodes), as a manifest records them for a whole dataset.
    pub fn statistics(&self) -> Statistics {
        Statistics::from_sums(&self.sums())
    }

    /// The sums behind [`statistics`](Self::statistics), as a shard's manifest entry records them.
    pub fn sums(&self) -> StatSums {
        let mut sums = StatSums::default();
        for i in 0..self.len() {
            sums.add_sample(self.grid, self.input(i), self.target(i), self.mask(i));
        }
        sums
    }

    /// Number of samples.
    pub fn len(&self) -> usize {
        self.indices.len()
    }

    /// Whether there is no sample.
    pub fn is_empty(&self) -> bool {
        self.indices.is_empty()
    }

    /// Appends a sample after validating it.
    pub fn push(&mut self, sample: &Sample) -> Result<()> {
        sample.validate(self.grid)?;
        self.indices.push(sample.index);
        self.inputs.extend_from_slice(&sample.input);
        self.targets.extend_from_slice(&sample.target);
        self.masks.extend_from_slice(&sample.mask);
        Ok(())
    }

    /// Input field of sample `i`.
    pub fn input(&self, i: usize) -> &[f32] {
        let n = self.grid.field_len();
        &self.inputs[i * n..(i + 1) * n]
    }

    /// Target field of sample `i`.
    pub fn target(&self, i: usize) -> &[f32] {
        let n = self.grid.field_len();
        &self.targets[i * n..(i + 1) * n]
    }

    /// Mask of sample `i`.
    pub fn mask(&self, i: usize) -> &[u8] {
        let n = self.grid.nodes();
        &self.masks[i * n..(i + 1) * n]
    }

    /// Sample `i`, copied.
    pub fn get(&self, i: usize) -> Sample {
        Sample {
            index: self.indices[i],
            input: self.input(i).to_vec(),
            target: self.target(i).to_vec(),
            mask: self.mask(i).to_vec(),
        }
    }

    /// The samples at the given positions, in that order.
    pub fn select(&self, positions: &[usize]) -> Result<Samples> {
        let mut out = Samples { source: self.source.clone(), ..Samples::new(self.grid) };
        for &p in positions {
            if p >= self.len() {
                return Err(LearnError::InvalidInput(format!("sample position {p} out of range (len {})", self.len())));
            }
            out.indices.push(self.indices[p]);
            out.inputs.extend_from_slice(self.input(p));
            out.targets.extend_from_slice(self.target(p));
            out.masks.extend_from_slice(self.mask(p));
        }
        Ok(out)
    }

    /// Splits into the first `n` samples and the rest (e.g. train / test).
    pub fn split_at(mut self, n: usize) -> Result<(Samples, Samples)> {
        if n > self.len() {
            return Err(LearnError::InvalidInput(format!("cannot split {} samples at {n}", self.len())));
        }
        let (f, m) = (self.grid.field_len(), self.grid.nodes());
        let rest = Samples {
            grid: self.grid,
            indices: self.indices.split_off(n),
            inputs: self.inputs.split_off(n * f),
            targets: self.targets.split_off(n * f),
            masks: self.masks.split_off(n * m),
            source: self.source.clone(),
        };
        Ok((self, rest))
    }

    /// Appends all samples of `other` (same grid; same source, unless `self` is empty).
    pub fn append(&mut self, mut other: Samples) -> Result<()> {
        if other.grid != self.grid {
            return Err(LearnError::InvalidInput(format!(
                "cannot append samples on grid {} to grid {}",
                other.grid, self.grid
            )));
        }
        if self.is_empty() {
            self.source = other.source.take();
        } else if other.source != self.source {
            return Err(LearnError::InvalidInput(format!(
                "cannot append samples of source {:?} to samples of source {:?}",
                other.source, self.source
            )));
        }
        self.indices.append(&mut other.indices);
        self.inputs.append(&mut other.inputs);
        self.targets.append(&mut other.targets);
        self.masks.append(&mut other.masks);
        Ok(())
    }
}

/// Appends samples to shards of a dataset directory; resumable.
///
/// Samples (and failures) must come in increasing generation index. Every `shard_size` samples
/// a shard is written and committed to the manifest; [`finish`](Self::finish) commits the last,
/// partial shard and marks the dataset complete. After a crash, `create_or_resume` on the same
/// directory with the same spec continues after the last committed index
/// ([`resume_from`](Self::resume_from)); samples of the uncommitted shard are generated again.
pub struct DatasetWriter {
    dir: PathBuf,
    /// The dataset's [`WRITER_LOCK`], held while this writer lives.
    _lock: WriterLock,
    manifest: Manifest,
    pending: Samples,
    pending_failures: Vec<FailedSample>,
    last_index: Option<u64>,
}

/// Refuses a folder a new dataset would share with files of another's making (any but the
/// writer's lock and hidden temporaries): its shards could overwrite them, and they would be read
/// as its own.
fn refuse_other_files(dir: &Path) -> Result<()> {
    let entries = std::fs::read_dir(dir).map_err(|e| LearnError::io(dir, e))?;
    let mut others: Vec<String> = entries
        .filter_map(|e| e.ok().map(|e| e.file_name().to_string_lossy().into_owned()))
        .filter(|name| name != WRITER_LOCK && !name.starts_with('.'))
        .collect();
    if others.is_empty() {
        return Ok(());
    }
    others.sort();
    let more = if others.len() > 3 { ", …" } else { "" };
    Err(LearnError::InvalidInput(format!(
        "{} holds other files ({}{more}) and no dataset: give a new or empty folder",
        dir.display(),
        others[..others.len().min(3)].join(", ")
    )))
}

impl DatasetWriter {
    /// Creates a new dataset in `dir`, or resumes the unfinished one there (whose spec must equal
    /// `spec`), or grows the one there when `spec` asks for more samples of it (its samples are
    /// kept, and generation goes on after them). A complete dataset of the same spec is an error.
    pub fn create_or_resume(dir: &Path, spec: DatasetSpec) -> Result<DatasetWriter> {
        if spec.shard_size == 0 {
            return Err(LearnError::InvalidInput("shard_size must be at least 1".into()));
        }
        if spec.grid.nodes() == 0 {
            return Err(LearnError::InvalidInput(format!("grid {} has no nodes", spec.grid)));
        }
        if let Some(part) = &spec.part {
            if part.count == 0 || part.index >= part.count {
                return Err(LearnError::InvalidInput(format!("invalid part {}/{}", part.index, part.count)));
            }
        }
        mesh::io::create_folder(dir)?;
        let lock = lock_for_writing(dir, DATASET_WRITERS)?;
        if !dir.join(MANIFEST_FILE).exists() {
            refuse_other_files(dir)?;
            return DatasetWriter::from_manifest(dir, lock, Manifest::new(&spec), true);
        }
        // What a killed run left half-written goes; its shard is made again.
        mesh::io::remove_stale_temporaries(dir);
        let dataset = Dataset::open(dir)?;
        let existing = dataset.manifest.spec();
        let grows = spec.grows(&existing) && dataset.manifest.chosen.is_none();
        if existing != spec && !grows {
            return Err(refusal(&dataset, &spec, "cannot resume"));
        }
        if dataset.manifest.complete && !grows {
            return Err(LearnError::manifest(dir.join(MANIFEST_FILE), "the dataset is already complete"));
        }
        dataset.check_files()?;
        let mut manifest = dataset.manifest;
        if grows {
            manifest.metadata = spec.metadata;
            manifest.complete = false;
        }
        DatasetWriter::from_manifest(dir, lock, manifest, grows)
    }

    /// Opens the dataset in `dir`, created with `spec`, complete or not, to append draws after its
    /// last one (the σ-chosen draws after its uniform ones); it is unfinished from the first
    /// [`commit`](Self::commit) until [`finish`](Self::finish). Until that commit nothing is
    /// written: a writer dropped before it (a run refused once it has read the manifest) leaves
    /// the dataset as it was.
    pub fn append(dir: &Path, spec: &DatasetSpec) -> Result<DatasetWriter> {
        if !dir.is_dir() {
            Dataset::open(dir)?; // says what is missing
        }
        let lock = lock_for_writing(dir, DATASET_WRITERS)?;
        mesh::io::remove_stale_temporaries(dir);
        let dataset = Dataset::open(dir)?;
        if dataset.manifest.spec() != *spec {
            return Err(refusal(&dataset, spec, "cannot add draws to this dataset"));
        }
        dataset.check_files()?;
        let mut manifest = dataset.manifest;
        manifest.complete = false;
        DatasetWriter::from_manifest(dir, lock, manifest, false)
    }

    /// A writer of the dataset in `dir` (locked by `lock`) going on after the last draw of
    /// `manifest`, which is written first where `rewrite`.
    fn from_manifest(dir: &Path, lock: WriterLock, manifest: Manifest, rewrite: bool) -> Result<DatasetWriter> {
        if rewrite {
            manifest.write(&dir.join(MANIFEST_FILE))?;
        }
        let last_index = manifest.next_index.checked_sub(1);
        Ok(DatasetWriter {
            dir: dir.to_path_buf(),
            _lock: lock,
            pending: Samples::new(manifest.grid),
            manifest,
            pending_failures: Vec::new(),
            last_index,
        })
    }

    /// Records how the σ-chosen draws are chosen, and commits what is pending with it.
    pub fn set_chosen(&mut self, chosen: ChosenDraws) -> Result<()> {
        self.manifest.chosen = Some(chosen);
        self.commit()
    }

    /// First generation index not yet committed: where a resumed generation starts.
    pub fn resume_from(&self) -> u64 {
        self.manifest.next_index
    }

    /// The line that says the writer goes on after the draws the dataset held when it was opened
    /// (`resuming DIR: N draws held, ...`), if it held any.
    pub fn resumed(&self) -> Option<String> {
        let held = self.manifest.num_samples + self.manifest.failed.len();
        (held > 0)
            .then(|| format!("resuming   {}: {held} draws held, kept; drawing goes on after them", self.dir.display()))
    }

    /// The manifest as committed so far.
    pub fn manifest(&self) -> &Manifest {
        &self.manifest
    }

    fn check_order(&self, index: u64) -> Result<()> {
        if self.last_index.is_some_and(|l| index <= l) {
            return Err(LearnError::InvalidInput(format!(
                "generation index {index} is not after the previous one ({})",
                self.last_index.unwrap_or_default()
            )));
        }
        Ok(())
    }

    /// Appends a sample; writes a shard when `shard_size` samples are pending.
    pub fn push(&mut self, sample: &Sample) -> Result<()> {
        self.check_order(sample.index)?;
        self.pending.push(sample)?;
        self.last_index = Some(sample.index);
        if self.pending.len() == self.manifest.shard_size {
            self.commit()?;
        }
        Ok(())
    }

    /// Records that generation index `index` failed (committed with the next shard).
    pub fn push_failure(&mut self, index: u64, reason: impl Into<String>) -> Result<()> {
        self.check_order(index)?;
        self.pending_failures.push(FailedSample { index, reason: reason.into() });
        self.last_index = Some(index);
        Ok(())
    }

    /// Writes the pending samples as a new shard (if any) and commits the manifest: a later run
    /// resumes after them.
    pub fn commit(&mut self) -> Result<()> {
        if !self.pending.is_empty() {
            let name = format!("shard_{:05}", self.manifest.shards.len());
            let grid = self.manifest.grid;
            let n = self.pending.len();
            let [nx, ny, nz] = grid.dims();
            let info = ShardInfo {
                inputs: format!("{name}/inputs.npy"),
                targets: format!("{name}/targets.npy"),
                masks: format!("{name}/masks.npy"),
                num_samples: n,
                indices: self.pending.indices.clone(),
                sums: self.pending.sums(),
                name,
            };
            npy::write_f32(&self.dir.join(&info.inputs), &[n, CHANNELS, nx, ny, nz], &self.pending.inputs)?;
            npy::write_f32(&self.dir.join(&info.targets), &[n, CHANNELS, nx, ny, nz], &self.pending.targets)?;
            npy::write_u8(&self.dir.join(&info.masks), &[n, nx, ny, nz], &self.pending.masks)?;
            self.manifest.num_samples += n;
            self.manifest.shards.push(info);
            self.pending = Samples::new(grid);
        }
        self.manifest.failed.append(&mut self.pending_failures);
        if let Some(last) = self.last_index {
            self.manifest.next_index = last + 1;
        }
        let mut sums = StatSums::default();
        for shard in &self.manifest.shards {
            sums.add(&shard.sums);
        }
        self.manifest.statistics = Statistics::from_sums(&sums);
        self.manifest.write(&self.dir.join(MANIFEST_FILE))
    }

    /// Commits what is pending and leaves the dataset unfinished: a later run resumes after it.
    pub fn stop(mut self) -> Result<Manifest> {
        self.commit()?;
        Ok(self.manifest)
    }

    /// Commits what is pending and marks the dataset complete.
    pub fn finish(mut self) -> Result<Manifest> {
        self.manifest.complete = true;
        self.commit()?;
        Ok(self.manifest)
    }
}

/// The file of a folder (a dataset, a model's) that its writer holds locked while it writes (left
/// by a writer that was killed; removed when one ends).
pub const WRITER_LOCK: &str = "writing.lock";

/// Who writes a dataset, and why a second writer is refused (see [`lock_for_writing`]).
const DATASET_WRITERS: &str = "(`augsim generate`, a cluster's shard): two writers would mix their draws";

/// A folder held by one writer (a dataset's, [`DatasetWriter`]; a model's,
/// [`crate::take_model_folder`]); its [`WRITER_LOCK`] file goes when this is dropped (on Unix).
pub struct WriterLock {
    path: PathBuf,
    _file: std::fs::File,
}

impl Drop for WriterLock {
    fn drop(&mut self) {
        // Removed while still locked: a writer that opened it before and locks it after finds
        // the name gone or another file's, and opens anew ([`lock_for_writing`]). Elsewhere than
        // on Unix, where that cannot be told, the file stays (an unlocked file locks nothing).
        // A file left behind (unlikely: the folder is writable) only keeps its name.
        #[cfg(unix)]
        let _ = std::fs::remove_file(&self.path);
    }
}

/// Whether `path` still names the open `file` (a lock taken on a file whose name another writer
/// removed in between locks nothing anyone else sees); elsewhere than on Unix the file is never
/// removed ([`WriterLock`]), so it does.
fn names_file(path: &Path, file: &std::fs::File) -> bool {
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        match (std::fs::metadata(path), file.metadata()) {
            (Ok(a), Ok(b)) => (a.dev(), a.ino()) == (b.dev(), b.ino()),
            _ => false,
        }
    }
    #[cfg(not(unix))]
    {
        let _ = (path, file);
        true
    }
}

/// Locks the folder `dir` for one writer: a second (another `augsim generate` on the same dataset,
/// a cluster's shard run again while the first still runs, another `augsim train` into the same
/// model folder) is refused at once rather than mixing its files with the first's; `writers` says
/// who writes there and why a second is refused. The lock ends with the writer's process.
pub(crate) fn lock_for_writing(dir: &Path, writers: &str) -> Result<WriterLock> {
    let path = dir.join(WRITER_LOCK);
    // A writer ending between this open and this lock removes the name: the lock then holds a
    // file no one else opens, and is taken again on the file now named so.
    for _ in 0..100 {
        let file = std::fs::OpenOptions::new()
            .create(true)
            .truncate(false)
            .write(true)
            .open(&path)
            .map_err(|e| LearnError::io(&path, e))?;
        match file.try_lock() {
            Ok(()) if names_file(&path, &file) => return Ok(WriterLock { path, _file: file }),
            Ok(()) => continue,
            Err(std::fs::TryLockError::WouldBlock) => {
                return Err(LearnError::InvalidInput(format!(
                    "{} is being written by another run {writers}; wait for it to end, or stop it",
                    dir.display()
                )))
            }
            Err(std::fs::TryLockError::Error(e)) => return Err(LearnError::io(&path, e)),
        }
    }
    Err(LearnError::InvalidInput(format!(
        "{}: its {WRITER_LOCK} is removed as fast as it is made; is another program clearing the folder?",
        dir.display()
    )))
}

/// Why `dataset` does not take the draws of `spec` (`refused`: what is refused), as an error on its
/// manifest: the σ-chosen draws it holds keep its uniform draws from growing, or it was created
/// otherwise.
fn refusal(dataset: &Dataset, spec: &DatasetSpec, refused: &str) -> LearnError {
    let existing = dataset.manifest.spec();
    let why = if dataset.manifest.chosen.is_some() && spec.grows(&existing) {
        "it holds σ-chosen draws after its uniform ones, which cannot grow (generate a larger uniform dataset, \
         then choose draws again)"
            .to_string()
    } else {
        existing.mismatch(spec)
    };
    LearnError::manifest(dataset.dir.join(MANIFEST_FILE), format!("{refused}: {why}"))
}

/// A dataset directory opened for reading.
#[derive(Clone, Debug)]
pub struct Dataset {
    dir: PathBuf,
    manifest: Manifest,
}

impl Dataset {
    /// Opens the dataset in `dir` (reads and validates the manifest).
    pub fn open(dir: &Path) -> Result<Dataset> {
        let path = dir.join(MANIFEST_FILE);
        if !path.exists() {
            let what = match (dir.is_dir(), dir.is_file()) {
                (true, _) => "not a dataset",
                (_, true) => "a file, not a dataset's folder",
                _ => "no such folder",
            };
            return Err(LearnError::manifest(
                dir,
                format!("{what} (a dataset holds a {MANIFEST_FILE}; `augsim generate` writes one)"),
            ));
        }
        let manifest = Manifest::read(&path)?;
        Ok(Dataset { dir: dir.to_path_buf(), manifest })
    }

    /// [`Dataset::open`], refusing a dataset that holds no sample (every draw failed, or none
    /// made), as a model is trained or measured on one.
    pub fn open_with_samples(dir: &Path) -> Result<Dataset> {
        let dataset = Dataset::open(dir)?;
        let m = dataset.manifest();
        if m.num_samples == 0 {
            let failed = match m.failed.len() {
                0 => "no draw made".to_string(),
                n => format!("its {n} draws all failed: reasons in its manifest"),
            };
            return Err(LearnError::InvalidInput(format!("{} holds no sample ({failed})", dir.display())));
        }
        Ok(dataset)
    }

    /// The manifest.
    pub fn manifest(&self) -> &Manifest {
        &self.manifest
    }

    /// The dataset directory.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// Number of samples.
    pub fn len(&self) -> usize {
        self.manifest.num_samples
    }

    /// Whether the dataset holds no sample.
    pub fn is_empty(&self) -> bool {
        self.manifest.num_samples == 0
    }

    /// Checks that every shard file exists with the shape the manifest gives (headers only).
    pub fn check_files(&self) -> Result<()> {
        for shard in &self.manifest.shards {
            for (file, shape) in self.expected_shapes(shard) {
                let path = self.dir.join(file);
                let found = npy::read_shape(&path)?;
                if found != shape {
                    return Err(shape_error(&path, &shape, &found));
                }
            }
        }
        Ok(())
    }

    fn expected_shapes<'a>(&self, shard: &'a ShardInfo) -> [(&'a str, Vec<usize>); 3] {
        let [nx, ny, nz] = self.manifest.grid.dims();
        let n = shard.num_samples;
        [
            (shard.inputs.as_str(), vec![n, CHANNELS, nx, ny, nz]),
            (shard.targets.as_str(), vec![n, CHANNELS, nx, ny, nz]),
            (shard.masks.as_str(), vec![n, nx, ny, nz]),
        ]
    }

    /// Loads shard `shard` (its position in the manifest).
    pub fn load_shard(&self, shard: usize) -> Result<Samples> {
        let info = self.manifest.shards.get(shard).ok_or_else(|| {
            LearnError::InvalidInput(format!("shard {shard} out of range ({} shards)", self.manifest.shards.len()))
        })?;
        let [inputs, targets, masks] = self.expected_shapes(info).map(|(file, shape)| {
            let path = self.dir.join(file);
            npy::read_npy(&path).map_err(LearnError::from).and_then(|a| {
                if a.shape != shape {
                    Err(shape_error(&path, &shape, &a.shape))
                } else {
                    Ok((path, a))
                }
            })
        });
        let (input_path, inputs) = inputs?;
        let (target_path, targets) = targets?;
        let (mask_path, masks) = masks?;
        let samples = Samples {
            grid: self.manifest.grid,
            indices: info.indices.clone(),
            inputs: inputs.into_f32(),
            targets: targets.into_f32(),
            masks: masks.into_mask(&mask_path)?,
            source: Some(self.manifest.source_id()),
        };
        let per = self.manifest.grid.field_len();
        check_values(&input_path, &samples.inputs, per, &samples.indices)?;
        check_values(&target_path, &samples.targets, per, &samples.indices)?;
        check_sums(info, &samples, &self.dir.join(MANIFEST_FILE))?;
        Ok(samples)
    }

    /// Loads every sample, in index order.
    pub fn load_all(&self) -> Result<Samples> {
        self.load_range(0..self.len())
    }

    /// Loads the samples at positions `range` (0-based over the whole dataset, in index order),
    /// reading only the shards that overlap it.
    pub fn load_range(&self, range: Range<usize>) -> Result<Samples> {
        if range.start > range.end || range.end > self.len() {
            return Err(LearnError::InvalidInput(format!(
                "sample range {range:?} is out of the dataset's {} samples ({})",
                self.len(),
                self.dir.display()
            )));
        }
        let mut out = Samples { source: Some(self.manifest.source_id()), ..Samples::new(self.manifest.grid) };
        let mut start = 0;
        for (s, shard) in self.manifest.shards.iter().enumerate() {
            let end = start + shard.num_samples;
            let lo = range.start.max(start);
            let hi = range.end.min(end);
            if lo < hi {
                let loaded = self.load_shard(s)?;
                let part = if lo == start && hi == end {
                    loaded
                } else {
                    loaded.select(&((lo - start)..(hi - start)).collect::<Vec<_>>())?
                };
                out.append(part)?;
            }
            start = end;
        }
        Ok(out)
    }
}

/// Refuses the first of a shard's `values` (`per` of them a sample, drawn as `indices`) that no
/// dataset holds ([`unfit_value`]), named by file, sample and place.
fn check_values(path: &Path, values: &[f32], per: usize, indices: &[u64]) -> Result<()> {
    match unfit_value(values) {
        Some(i) => Err(LearnError::manifest(
            path,
            format!(
                "sample {} (draw {}), value {} is {:e}: a dataset holds finite displacements (m) and forces (N) \
                 within {MAX_FIELD_VALUE:e}: is the file damaged?",
                i / per,
                indices[i / per],
                i % per,
                values[i]
            ),
        )),
        None => Ok(()),
    }
}

fn shape_error(path: &Path, expected: &[usize], found: &[usize]) -> LearnError {
    LearnError::manifest(path, format!("array shape {found:?} does not match the manifest, which gives {expected:?}"))
}

/// Streams the samples and failures of one complete dataset in index order.
struct MergeCursor {
    dataset: Dataset,
    next_shard: usize,
    loaded: Option<Samples>,
    position: usize,
    failures: std::vec::IntoIter<FailedSample>,
    next_failure: Option<FailedSample>,
}

enum MergeItem {
    Sample(Sample),
    Failure(FailedSample),
}

impl MergeCursor {
    fn new(dataset: Dataset) -> Self {
        let mut failures = dataset.manifest.failed.clone();
        failures.sort_by_key(|f| f.index);
        let mut failures = failures.into_iter();
        let next_failure = failures.next();
        MergeCursor { dataset, next_shard: 0, loaded: None, position: 0, failures, next_failure }
    }

    /// Index of the next pending sample, loading shards as needed.
    fn peek_sample(&mut self) -> Result<Option<u64>> {
        loop {
            if let Some(s) = &self.loaded {
                if self.position < s.len() {
                    return Ok(Some(s.indices[self.position]));
                }
            }
            if self.next_shard >= self.dataset.manifest.shards.len() {
                return Ok(None);
            }
            self.loaded = Some(self.dataset.load_shard(self.next_shard)?);
            self.next_shard += 1;
            self.position = 0;
        }
    }

    fn peek(&mut self) -> Result<Option<u64>> {
        let sample = self.peek_sample()?;
        let failure = self.next_failure.as_ref().map(|f| f.index);
        Ok(match (sample, failure) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        })
    }

    fn pop(&mut self) -> Result<Option<MergeItem>> {
        let sample = self.peek_sample()?;
        let failure = self.next_failure.as_ref().map(|f| f.index);
        match (sample, failure) {
            (Some(s), f) if f.is_none_or(|f| s < f) => {
                let loaded = self.loaded.as_ref().expect("peek_sample loaded a shard");
                let item = loaded.get(self.position);
                self.position += 1;
                Ok(Some(MergeItem::Sample(item)))
            }
            (_, Some(_)) => {
                let f = self.next_failure.take().expect("failure present");
                self.next_failure = self.failures.next();
                Ok(Some(MergeItem::Failure(f)))
            }
            _ => Ok(None),
        }
    }
}

/// Refuses parts of a split generation (`--shard i/n`) that are not every part once: a missing
/// part would leave its draws out of a dataset marked complete.
fn check_parts_cover(paths: &[PathBuf], datasets: &[Dataset]) -> Result<()> {
    let parts: Vec<Option<&DatasetPart>> = datasets.iter().map(|d| d.manifest.part.as_ref()).collect();
    let Some(count) = parts.iter().flatten().map(|p| p.count).next() else { return Ok(()) };
    let fail = |message: String| Err(LearnError::InvalidInput(format!("merge: {message}")));
    if let Some(k) = parts.iter().position(|p| p.is_none_or(|p| p.count != count)) {
        return fail(format!(
            "{} is not one of the {count} parts of a split generation (--shard i/{count}) as {} is",
            paths[k].display(),
            paths[parts.iter().position(Option::is_some).unwrap_or(0)].display()
        ));
    }
    let mut given = vec![0usize; count];
    parts.iter().flatten().for_each(|p| given[p.index.min(count - 1)] += 1);
    let missing: Vec<String> = (0..count).filter(|&i| given[i] == 0).map(|i| format!("{i}/{count}")).collect();
    let twice: Vec<String> = (0..count).filter(|&i| given[i] > 1).map(|i| format!("{i}/{count}")).collect();
    match (missing.is_empty(), twice.is_empty()) {
        (true, true) => Ok(()),
        (false, _) => fail(format!(
            "part(s) {} of the split generation are missing: merge every part written with --shard i/{count}",
            missing.join(", ")
        )),
        (true, false) => fail(format!("part(s) {} are given more than once", twice.join(", "))),
    }
}

/// Merges complete datasets written by parallel workers (`--shard i/n`) into a new dataset
/// `out`, in generation-index order, re-sharded with `shard_size` (default: the first part's).
/// The parts must agree on scenario, seed, grid, units and metadata, be every part of the split
/// once, and no generation index may appear twice. The result equals what a single worker would have written.
/// An interrupted merge into `out` (an unfinished dataset of the same spec) goes on after what it committed.
pub fn merge_datasets(parts: &[PathBuf], out: &Path, shard_size: Option<usize>) -> Result<Manifest> {
    if parts.is_empty() {
        return Err(LearnError::InvalidInput("merge needs at least one dataset".into()));
    }
    if Dataset::open(out).is_ok_and(|d| d.manifest.complete) {
        return Err(LearnError::manifest(out.join(MANIFEST_FILE), "merge output already holds a dataset"));
    }
    let datasets = parts.iter().map(|p| Dataset::open(p)).collect::<Result<Vec<_>>>()?;
    let first = datasets[0].manifest.spec();
    for (path, d) in parts.iter().zip(&datasets) {
        let m = &d.manifest;
        let manifest_path = path.join(MANIFEST_FILE);
        if !m.complete {
            return Err(LearnError::manifest(
                &manifest_path,
                "dataset is not complete; finish or resume its generation first",
            ));
        }
        if m.chosen.is_some() {
            return Err(LearnError::manifest(
                &manifest_path,
                "dataset holds σ-chosen draws, which are chosen one round after another and not merged",
            ));
        }
        // Parts differ in which part they are and may in their shards' size, in nothing else.
        let whole = |spec: DatasetSpec| DatasetSpec { part: None, shard_size: 0, ..spec };
        let differences = whole(first.clone()).differences(&whole(m.spec()));
        if !differences.is_empty() {
            return Err(LearnError::manifest(
                &manifest_path,
                format!(
                    "dataset does not match the first one ({}; \"there\" below, this one \"now\"): {}; scenario, \
                     seed, grid, units and metadata must agree",
                    parts[0].display(),
                    differences.join("; ")
                ),
            ));
        }
    }
    check_parts_cover(parts, &datasets)?;
    let spec = DatasetSpec { part: None, shard_size: shard_size.unwrap_or(first.shard_size), ..first };
    let mut writer = DatasetWriter::create_or_resume(out, spec)?;
    let committed = writer.resume_from();
    let mut cursors: Vec<MergeCursor> = datasets.into_iter().map(MergeCursor::new).collect();
    let mut last: Option<(u64, usize)> = None;
    loop {
        let mut best: Option<(u64, usize)> = None;
        for (c, cursor) in cursors.iter_mut().enumerate() {
            if let Some(i) = cursor.peek()? {
                if best.is_none_or(|(b, _)| i < b) {
                    best = Some((i, c));
                }
            }
        }
        let Some((index, c)) = best else { break };
        if let Some((prev, pc)) = last {
            if prev == index {
                return Err(LearnError::manifest(
                    parts[c].join(MANIFEST_FILE),
                    format!("generation index {index} also appears in {}", parts[pc].display()),
                ));
            }
        }
        last = Some((index, c));
        match cursors[c].pop()? {
            // In the output already: committed by an interrupted merge.
            Some(_) if index < committed => {}
            Some(MergeItem::Sample(s)) => writer.push(&s)?,
            Some(MergeItem::Failure(f)) => writer.push_failure(f.index, f.reason)?,
            None => break,
        }
    }
    writer.finish()
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::{AtomicUsize, Ordering};

    /// Writers taking and ending the lock as fast as they can never hold it two at a time: one
    /// that locked a file whose name the writer before it removed takes the lock again (without
    /// that, two writers held the folder at once in each of two runs, within a second).
    #[test]
    fn one_writer_holds_a_folder_at_a_time() {
        let dir = tempfile::tempdir().unwrap();
        let holders = AtomicUsize::new(0);
        let (taken, most) = (AtomicUsize::new(0), AtomicUsize::new(0));
        std::thread::scope(|scope| {
            for _ in 0..4 {
                scope.spawn(|| {
                    for _ in 0..20000 {
                        if let Ok(lock) = lock_for_writing(dir.path(), "(a test)") {
                            let now = holders.fetch_add(1, Ordering::SeqCst) + 1;
                            most.fetch_max(now, Ordering::SeqCst);
                            taken.fetch_add(1, Ordering::SeqCst);
                            std::thread::yield_now();
                            holders.fetch_sub(1, Ordering::SeqCst);
                            drop(lock);
                        }
                    }
                });
            }
        });
        assert!(taken.load(Ordering::SeqCst) > 0, "no writer ever took the lock");
        assert_eq!(most.load(Ordering::SeqCst), 1, "two writers held the folder at once");
    }

    /// A lock file opened before its name was removed is no longer the one the name gives.
    #[cfg(unix)]
    #[test]
    fn a_removed_lock_file_is_not_the_folder_s() {
        let dir = tempfile::tempdir().unwrap();
        let lock = lock_for_writing(dir.path(), "(a test)").unwrap();
        let opened = std::fs::File::open(dir.path().join(WRITER_LOCK)).unwrap();
        assert!(names_file(&dir.path().join(WRITER_LOCK), &opened));
        drop(lock);
        assert!(!names_file(&dir.path().join(WRITER_LOCK), &opened), "the name is gone");
        let _again = lock_for_writing(dir.path(), "(a test)").unwrap();
        assert!(!names_file(&dir.path().join(WRITER_LOCK), &opened), "the name is another file's");
    }
}
