//! A registration set up from the user's choices, the one way `augsim register`, `augsim serve`,
//! the Python package and the comparisons ([`crate::case::compare`]) build it:
//! [`RegistrationChoice`] (what the user asks for: a patient's set-up, a FEM or a learned model,
//! targets, unit, settings) gives a [`RegistrationSpec`] (the FEM of a static scenario, a learned
//! model (U-Net or reduced-order model) with the dataset scenario it was trained on, or a hybrid
//! of the two, each from files or in memory; the targets from a file, from points or from the
//! mesh's regions, in their unit; the loop's settings), which builds the registration.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use learn::Model;
use mesh::io::points::LabelledPoints;
use mesh::io::{Frame, FrameChange, GivenCoordinates};
use mesh::isosurface::ExtractOptions;
use mesh::labelmap::is_labelmap;
use mesh::length::LengthUnit;
use mesh::{Point, TriSurface};
use register::{shape, Deformer, HybridDeformer, NetworkDeformer, Organ, Registration, RegistrationOptions};
use scenario::{DatasetScenario, MeshSource, StaticScenario};

use crate::meshing::OrganInput;
use crate::models::{
    fem_model, hybrid_options, learned_registration, network_model, rom_hybrid, rom_stream_shape, shape_fit,
    LearnedRegistration, ModelSource, Network, ScenarioSource,
};
use crate::setup::{
    read_organ_surface, steps_before_validation, Patient, PatientMethod, PATIENT_FILE, SET_UP_FRAME, STRUCTURES_UNIT,
    SURFACE_FILE,
};

/// What deforms the organ.
#[derive(Clone, Debug)]
pub enum MethodSpec {
    /// The FEM of a static scenario: its mesh, material, fixed nodes and solver, pulled by
    /// springs of the default stiffness.
    Fem(ScenarioSource<StaticScenario>),
    /// A learned model and the dataset scenario it was trained on, whose mesh is the organ.
    Learned {
        /// The model.
        model: ModelSource,
        /// Its dataset scenario.
        scenario: ScenarioSource<DatasetScenario>,
        /// How it registers.
        way: LearnedWay,
    },
    /// A learned model for the first `network_iterations` of a frame from rest, then the FEM from
    /// its estimate ([`HybridDeformer`]), on the FEM's organ: a reduced-order model's shape fit
    /// there (its modes interpolated from its grid), alone on a stream's next frames
    /// ([`rom_hybrid`]); a U-Net's match-and-membrane loop (its organ must be the FEM's mesh),
    /// the FEM alone on a stream's next frames.
    Hybrid {
        /// The model.
        model: ModelSource,
        /// Its dataset scenario (a U-Net's organ and input nodes).
        scenario: ScenarioSource<DatasetScenario>,
        /// The FEM's static scenario.
        fem: ScenarioSource<StaticScenario>,
        /// The learned model's iterations of a frame from rest before the FEM's (at least 1;
        /// `None`: a reduced-order model's shape fit, [`shape::SHAPE_ITERATIONS`], or a U-Net's
        /// first iteration).
        network_iterations: Option<usize>,
    },
}

/// How a learned model registers.
#[derive(Clone, Debug)]
pub enum LearnedWay {
    /// As the model does ([`learned_registration`]): a reduced-order model fits its shape space
    /// from rest, a U-Net fits a membrane to the matches and predicts from it.
    Own,
    /// The match-and-membrane loop alone (what a U-Net does), for a reduced-order model too.
    Membrane,
    /// A U-Net predicting from the shape fit of another model's basis (a reduced-order model's
    /// shape space) on a frame from rest, from its own loop on a stream's frames.
    AfterShapeFit(ModelSource),
}

impl MethodSpec {
    /// The FEM of the static scenario `path` (a file or a built-in name).
    pub fn fem(path: impl Into<PathBuf>) -> MethodSpec {
        MethodSpec::Fem(ScenarioSource::File(path.into()))
    }

    /// The learned model `model` (its directory or model.json) with the dataset scenario
    /// `scenario` (a file or a built-in name), registering as the model does.
    pub fn learned(model: impl Into<PathBuf>, scenario: impl Into<PathBuf>) -> MethodSpec {
        MethodSpec::Learned {
            model: ModelSource::File(model.into()),
            scenario: ScenarioSource::File(scenario.into()),
            way: LearnedWay::Own,
        }
    }

    /// The U-Net `model` with the dataset scenario `scenario`, predicting from the shape fit of the
    /// reduced-order model `basis` on a frame from rest ([`LearnedWay::AfterShapeFit`]).
    pub fn learned_after_shape_fit(
        model: impl Into<PathBuf>,
        scenario: impl Into<PathBuf>,
        basis: impl Into<PathBuf>,
    ) -> MethodSpec {
        MethodSpec::Learned {
            model: ModelSource::File(model.into()),
            scenario: ScenarioSource::File(scenario.into()),
            way: LearnedWay::AfterShapeFit(ModelSource::File(basis.into())),
        }
    }

    /// The learned model `model` (with its dataset scenario `scenario`) from rest, then the FEM of
    /// the static scenario `fem` from its estimate, as [`MethodSpec::Hybrid`] does by default.
    pub fn hybrid(model: impl Into<PathBuf>, scenario: impl Into<PathBuf>, fem: impl Into<PathBuf>) -> MethodSpec {
        MethodSpec::Hybrid {
            model: ModelSource::File(model.into()),
            scenario: ScenarioSource::File(scenario.into()),
            fem: ScenarioSource::File(fem.into()),
            network_iterations: None,
        }
    }
}

/// A method loaded: its organ and the frame its mesh file names, how it deforms, the method in
/// words, the loop's settings, and what the set-up should know of its mesh (pieces left out).
struct Loaded {
    organ: Organ,
    frame: Option<Frame>,
    deformer: Box<dyn Deformer + Send>,
    method: String,
    options: RegistrationOptions,
    warnings: Vec<String>,
}

impl MethodSpec {
    /// The method loaded, with the loop's settings `options` (the method's defaults when `None`).
    fn load(&self, options: Option<&RegistrationOptions>) -> Result<Loaded> {
        let defaults = || options.cloned().unwrap_or_default();
        Ok(match self {
            MethodSpec::Fem(source) => {
                let (scenario, dir) = source.read(StaticScenario::load)?;
                let (organ, deformer, left_out) = fem_model(&scenario, &dir)?;
                let m = scenario.material;
                let method =
                    format!("FEM, {} ({} elements)", m.law.display_name(), m.resolved_formulation().display_name());
                let frame = scenario.mesh.frame(&dir)?;
                let (deformer, warnings) = (Box::new(deformer), left_out.into_iter().collect());
                Loaded { organ, frame, deformer, method, options: defaults(), warnings }
            }
            MethodSpec::Learned { model, scenario, way } => {
                let (model, words) = model.load()?;
                let (scenario, dir) = scenario.read(DatasetScenario::load)?;
                let network = Network { model: &model, scenario: &scenario, dir: &dir };
                let frame = scenario.mesh.frame(&dir)?;
                let options = options.cloned().unwrap_or_else(|| NetworkDeformer::loop_options(&Default::default()));
                match way {
                    LearnedWay::Membrane => {
                        let (organ, deformer) = network_model(&network)?;
                        let method = format!("{words}, membrane loop");
                        Loaded { organ, frame, deformer: Box::new(deformer), method, options, warnings: Vec::new() }
                    }
                    LearnedWay::Own => {
                        let LearnedRegistration { organ, deformer, options } =
                            learned_registration(&network, None, &options)?;
                        Loaded { organ, frame, deformer, method: words, options, warnings: Vec::new() }
                    }
                    LearnedWay::AfterShapeFit(basis) => {
                        let (basis, basis_words) = basis.load()?;
                        let LearnedRegistration { organ, deformer, options } =
                            learned_registration(&network, Some(&basis), &options)?;
                        Loaded {
                            organ,
                            frame,
                            deformer,
                            method: format!("{words} after the shape fit of {basis_words}"),
                            options,
                            warnings: Vec::new(),
                        }
                    }
                }
            }
            MethodSpec::Hybrid { model, scenario, fem, network_iterations } => {
                let (model, words) = model.load()?;
                let network_iterations = network_iterations.unwrap_or(match model {
                    Model::Reduced(_) => shape::SHAPE_ITERATIONS,
                    Model::UNet(_) => 1,
                });
                let (fem, fem_dir) = fem.read(StaticScenario::load)?;
                let (organ, deformer, left_out) = fem_model(&fem, &fem_dir)?;
                let frame = fem.mesh.frame(&fem_dir)?;
                let learned: Box<dyn Deformer + Send> = match &model {
                    // The shape space holds on any mesh inside the model's grid: the FEM's own.
                    Model::Reduced(_) => Box::new(shape_fit(&model, &organ, rom_stream_shape())?),
                    Model::UNet(_) => {
                        let (scenario, dir) = scenario.read(DatasetScenario::load)?;
                        let (network_organ, network) =
                            network_model(&Network { model: &model, scenario: &scenario, dir: &dir })?;
                        if network_organ.mesh().nodes != organ.mesh().nodes {
                            anyhow::bail!(
                                "the network's organ ({} nodes) is not the FEM model's mesh ({}, {} nodes): a hybrid \
                                 needs a network trained on the model's own mesh",
                                network_organ.mesh().num_nodes(),
                                mesh_words(&fem),
                                organ.mesh().num_nodes()
                            );
                        }
                        Box::new(network)
                    }
                };
                let deformer = HybridDeformer::new(learned, Box::new(deformer), network_iterations)?;
                let method = format!(
                    "{words} for {network_iterations} iterations, then FEM, {}",
                    fem.material.law.display_name()
                );
                // By default the FEM polishes the learned estimate for a few iterations.
                let options =
                    options.cloned().unwrap_or_else(|| hybrid_options(&Default::default(), network_iterations));
                let (deformer, options) = match model {
                    Model::Reduced(_) => rom_hybrid(deformer, options),
                    Model::UNet(_) => (deformer, options),
                };
                let warnings = left_out.into_iter().collect();
                Loaded { organ, frame, deformer: Box::new(deformer), method, options, warnings }
            }
        })
    }
}

/// The mesh of a FEM's scenario in words: the phantom's size, or the scenario's name.
fn mesh_words(scenario: &StaticScenario) -> String {
    match scenario.mesh {
        MeshSource::Phantom { tets } => format!("the phantom of {tets} T4"),
        _ => format!("the mesh of {}", scenario.name),
    }
}

/// Where the targets come from.
#[derive(Clone, Debug)]
pub enum TargetsSpec {
    /// The rest positions of the mesh's `markers` and `tumour` nodes.
    Regions,
    /// A points file (CSV, `.fcsv`, `.mrk.json`) of rest positions, in the unit it names or else
    /// in the spec's.
    File(PathBuf),
    /// Rest positions, in the spec's unit.
    Points(Vec<Point>),
}

/// The user's choices of a registration: the arguments of `augsim register` and `augsim serve`
/// (flattened into each) and the keywords of Python's `augsim.Registration`, with the same
/// names. [`RegistrationChoice::spec`] turns them into a [`RegistrationSpec`].
#[derive(Clone, Debug, Default, clap::Args)]
pub struct RegistrationChoice {
    /// The registration set-up of a patient's organ, written by `augsim prepare`: its learned
    /// model, its FEM or the two in turn, whichever it found the best on its validation, and its
    /// targets.
    #[arg(long, conflicts_with_all = ["fem", "model", "scenario", "targets", "shape_model"])]
    pub patient: Option<PathBuf>,
    /// With --patient: register with the patient's FEM, whichever its set-up names.
    #[arg(long, requires = "patient")]
    pub use_fem: bool,
    /// With --patient: register with the patient's learned model, whichever its set-up names.
    #[arg(long, requires = "patient", conflicts_with = "use_fem")]
    pub use_model: bool,
    /// With --patient: register with the patient's learned model from rest, then its FEM from that
    /// estimate (on a stream's next clouds, a reduced-order model's shape fit alone; a U-Net's
    /// FEM alone), whichever its set-up names.
    #[arg(long, requires = "patient", conflicts_with_all = ["use_fem", "use_model"])]
    pub use_hybrid: bool,
    /// FEM registration on this static scenario (a file or a built-in name): its mesh, material
    /// (law, formulation), fixed nodes and solver.
    #[arg(long, conflicts_with = "model")]
    pub fem: Option<PathBuf>,
    /// Registration with this learned model (a U-Net's or a reduced-order model's directory, or
    /// its model.json); the organ comes from --scenario.
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// The dataset scenario the model was trained on (a file or a built-in name, e.g.
    /// liver_ar_t10): its mesh is the organ, its observed nodes the model's input.
    #[arg(long)]
    pub scenario: Option<PathBuf>,
    /// With --model a U-Net: a reduced-order model (its directory or model.json) whose shape space
    /// is fitted to a cloud registered from rest first; the U-Net then predicts from the surface
    /// that fit found (a stream's next clouds: the U-Net's own loop).
    #[arg(long, requires = "model")]
    pub shape_model: Option<PathBuf>,
    /// Targets at rest: a points file (CSV x,y,z in --units, .fcsv or .mrk.json); default: the
    /// mesh's `markers` and `tumour` regions.
    #[arg(long, value_name = "TARGETS", value_parser = targets_file)]
    pub targets: Option<TargetsSpec>,
    /// Unit of the coordinates given and given back whose files name none (clouds, targets,
    /// truth, results): m, cm, mm or um. Default: a patient's own (the unit of the files `augsim prepare`
    /// was given), else m (augsim's unit) on every front. Files that name their unit (.fcsv,
    /// .mrk.json, CSV columns x_mm) are read in it.
    #[arg(long)]
    pub units: Option<LengthUnit>,
    /// Frame (RAS or LPS) of the points given whose files name none (clouds, truth; a stream's
    /// coordinates), converted into the organ's frame and results converted back (every file
    /// `register` writes, which name it). Default: a patient's own (the frame of the files
    /// `augsim prepare` was given), else the organ's; `serve`: RAS, the frame OpenIGTLink streams in.
    #[arg(long)]
    pub frame: Option<Frame>,
    /// Most match-and-deform iterations of the first cloud, from rest (default: 30 for a FEM, a
    /// U-Net's real-time budget, 4, and 10 for a reduced-order model's shape fit); a stream's next
    /// clouds take at most 4 (a FEM), 2 (a U-Net) or 3 (a reduced-order model's shape fit).
    #[arg(long)]
    pub iterations: Option<usize>,
    /// Rigid pre-alignment: the first cloud is aligned to the organ's rest surface (trimmed
    /// point-to-plane ICP) before the deformable iterations and the pose kept for the next
    /// clouds; targets and organ are then given back in the cloud's frame.
    #[arg(long)]
    pub rigid: bool,
    /// A structure inside the organ given back deformed with it (a tumour, vessels): a surface 3D
    /// Slicer exports (.stl, .obj, .ply, .vtk, .vtp; in --units and the frame its header names,
    /// else the targets'), named by its file's stem; or LABELMAP:LABEL, a label of a labelmap
    /// (seg.seg.nrrd:tumour, seg.nii.gz:2), named by the label; NAME=SOURCE names it NAME
    /// (tumour=seg.nii.gz:2). Repeat for several.
    #[arg(long = "structure", value_name = "SURFACE")]
    pub structures: Vec<PathBuf>,
}

/// A targets file argument.
fn targets_file(path: &str) -> Result<TargetsSpec, String> {
    Ok(TargetsSpec::File(PathBuf::from(path)))
}

/// The choices of a patient's method, as both fronts name them.
const PATIENT_METHODS: &str = "--use-fem, --use-model and --use-hybrid (use_fem=True, use_fem=False and \
                               use_hybrid=True in Python)";

/// What a registration needs when no way of deforming the organ is given.
const NO_METHOD: &str = "give --patient DIR, --fem SCENARIO, or --model MODEL with --scenario SCENARIO (in Python: \
                         patient=, fem=, or model= with scenario=)";

/// Choices as both fronts name them: `--shape-model (shape_model= in Python)`.
fn options_named(names: &[&str]) -> String {
    let flags: Vec<String> = names.iter().map(|n| format!("--{}", n.replace('_', "-"))).collect();
    let keywords: Vec<String> = names.iter().map(|n| format!("{n}=")).collect();
    format!("{} ({} in Python)", flags.join(", "), keywords.join(", "))
}

impl RegistrationChoice {
    /// Whether the choices fit together (the command line's parser checks the same): one way of
    /// deforming the organ (a patient's set-up, a FEM, or a learned model with its scenario),
    /// nothing else beside a patient's set-up, which holds its method and targets.
    pub fn check(&self) -> Result<(), String> {
        let given = |name: &str, yes: bool| yes.then(|| name.to_string());
        if self.patient.is_some() {
            let others: Vec<String> = [
                given("fem", self.fem.is_some()),
                given("model", self.model.is_some()),
                given("scenario", self.scenario.is_some()),
                given("targets", self.targets.is_some()),
                given("shape_model", self.shape_model.is_some()),
            ]
            .into_iter()
            .flatten()
            .collect();
            if !others.is_empty() {
                let others: Vec<&str> = others.iter().map(String::as_str).collect();
                return Err(format!(
                    "--patient DIR holds its method and targets: leave out {}",
                    options_named(&others)
                ));
            }
            if self.uses() > 1 {
                return Err(format!("{PATIENT_METHODS} ask for different methods: give one"));
            }
            return Ok(());
        }
        if self.uses() > 0 {
            return Err(format!(
                "{PATIENT_METHODS} choose a patient's method: give --patient DIR (patient= in Python)"
            ));
        }
        self.method().map(|_| ())
    }

    /// How many of a patient's methods are asked for.
    fn uses(&self) -> usize {
        [self.use_fem, self.use_model, self.use_hybrid].into_iter().filter(|&u| u).count()
    }

    /// The method given without a patient's set-up.
    fn method(&self) -> Result<MethodSpec, String> {
        if self.shape_model.is_some() && self.model.is_none() {
            return Err(format!(
                "{} is the basis of a model's registration: give --model MODEL (a U-Net) too",
                options_named(&["shape_model"])
            ));
        }
        match (&self.fem, &self.model, &self.scenario) {
            (Some(_), None, Some(_)) => Err(format!(
                "{} is a learned model's dataset scenario: a FEM (--fem) takes none",
                options_named(&["scenario"])
            )),
            (Some(fem), None, None) => Ok(MethodSpec::fem(fem)),
            (None, Some(model), Some(scenario)) => Ok(match &self.shape_model {
                None => MethodSpec::learned(model, scenario),
                Some(basis) => MethodSpec::learned_after_shape_fit(model, scenario, basis),
            }),
            (Some(_), Some(_), _) => Err("give --fem or --model, not both (fem= or model= in Python)".into()),
            _ => Err(NO_METHOD.into()),
        }
    }

    /// The registration's spec: a patient's set-up read (the method it names, or the one asked
    /// for with `use_fem` / `use_model` / `use_hybrid`), or the method and targets given; an error, as
    /// [`RegistrationChoice::check`] gives, when the choices do not fit together.
    pub fn spec(&self) -> Result<RegistrationSpec> {
        self.check().map_err(anyhow::Error::msg)?;
        if let Some(dir) = &self.patient {
            let method = PatientMethod::asked(self.use_fem, self.use_model, self.use_hybrid);
            let mut spec = RegistrationSpec::patient(dir, method, self.iterations, self.rigid)?;
            spec.given_units = self.units.unwrap_or(spec.given_units);
            spec.given_frame = self.frame.or(spec.given_frame);
            spec.structures.extend(self.structures.iter().map(StructureFile::given));
            return Ok(spec);
        }
        let units = self.units.unwrap_or(LengthUnit::DEFAULT);
        let (method, targets) = (self.method().map_err(anyhow::Error::msg)?, self.targets.clone());
        Ok(RegistrationSpec {
            units,
            given_units: units,
            given_frame: self.frame,
            iterations: self.iterations,
            rigid: self.rigid,
            structures: self.structures.iter().map(StructureFile::given).collect(),
            ..RegistrationSpec::new(method, targets.unwrap_or(TargetsSpec::Regions))
        })
    }
}

/// A registration described by its files and settings; [`RegistrationSpec::build`] makes it.
#[derive(Clone, Debug)]
pub struct RegistrationSpec {
    /// What deforms the organ.
    pub method: MethodSpec,
    /// The targets.
    pub targets: TargetsSpec,
    /// The unit of the given targets (of a file's when it names none).
    pub units: LengthUnit,
    /// The unit of the points given and given back whose files name none: clouds, truth, results
    /// (a patient's: the unit of the files it was prepared from).
    pub given_units: LengthUnit,
    /// The frame of the points given whose files name none (`None`: the organ's; a patient's: the
    /// frame of the files it was prepared from).
    pub given_frame: Option<Frame>,
    /// Most match-and-deform iterations from rest, in place of the method's default.
    pub iterations: Option<usize>,
    /// A rigid pre-alignment of the first cloud (trimmed ICP), where the loop's settings have none.
    pub rigid: bool,
    /// Most wall time of a frame (ms), in place of the loop's
    /// ([`RegistrationOptions::time_budget_ms`]).
    pub time_budget_ms: Option<f64>,
    /// The loop's settings, in place of the method's defaults (a comparison's: its case's, with
    /// the method's iteration budgets): a FEM's [`RegistrationOptions::default`], a U-Net's
    /// [`NetworkDeformer::loop_options`], a hybrid's [`hybrid_options`]. A reduced-order model's
    /// shape fit (alone or before a U-Net) takes its own budgets and points over them
    /// ([`register::shape::loop_options`]); in a hybrid it takes the hybrid's.
    pub options: Option<RegistrationOptions>,
    /// Structures inside the organ, given back deformed with it
    /// ([`RegistrationChoice::structures`]; a patient's own).
    pub structures: Vec<StructureFile>,
    /// The organ's own surface (a patient's `surface.stl`, in mm or m as its size tells), given
    /// back registered in place of its mesh's boundary ([`Registration::set_surface`]).
    pub surface: Option<PathBuf>,
    /// The factor on the method's σ at the targets (a patient's, calibrated by its validation:
    /// [`Registration::calibrate_sigma`]).
    pub sigma_factor: f64,
}

/// Where a structure comes from: a surface file or `LABELMAP:LABEL` ([`read_structure`]), with
/// the unit of a surface file when known (a patient's own structures: mm).
#[derive(Clone, Debug, PartialEq)]
pub struct StructureFile {
    /// The file, or `LABELMAP:LABEL`.
    pub path: PathBuf,
    /// The unit of a surface file; `None`: the unit of the points given.
    pub unit: Option<LengthUnit>,
}

impl StructureFile {
    /// A structure given on the command line or in Python, in the unit of the points given.
    fn given(path: impl AsRef<Path>) -> StructureFile {
        StructureFile { path: path.as_ref().to_path_buf(), unit: None }
    }
}

/// The name of the structure `source` holds: the `NAME` of `NAME=SOURCE`; else a surface file's
/// stem, or the label of `LABELMAP:LABEL` (for a number, the name 3D Slicer gives its segment in a
/// `.seg.nrrd`, else `label_N`); white space turned into `_`.
pub fn structure_name(source: &Path) -> String {
    let (named, source) = named_source(source);
    let name = match (named, labelmap_label(source)) {
        (Some(name), _) => name.to_string(),
        (None, Some((path, label))) if let Ok(value) = label.parse::<i32>() => {
            mesh::labelmap::nrrd_segment_name(Path::new(path), value).unwrap_or_else(|| format!("label_{label}"))
        }
        (None, Some((_, label))) => label.to_string(),
        (None, None) => source.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default(),
    };
    name.replace(char::is_whitespace, "_")
}

/// `NAME=SOURCE` split into the name and the source; a `source` with no `=` before its path (or a
/// file that is there under that whole name) has none.
fn named_source(source: &Path) -> (Option<&str>, &Path) {
    let split = source.to_str().and_then(|s| s.split_once('='));
    match split {
        Some((name, rest))
            if !name.is_empty() && !rest.is_empty() && !name.contains(['/', '\\']) && !source.exists() =>
        {
            (Some(name), Path::new(rest))
        }
        _ => (None, source),
    }
}

/// `LABELMAP:LABEL` split, when `source` is one (at the first `:` after a labelmap's name, so that
/// a segment's name may hold one: `seg.seg.nrrd:Tu: S8`).
fn labelmap_label(source: &Path) -> Option<(&str, &str)> {
    let text = source.to_str()?;
    text.match_indices(':').map(|(at, _)| (&text[..at], &text[at + 1..])).find(|(path, _)| is_labelmap(Path::new(path)))
}

/// `source` ([`read_structure`]'s) with its file's path made absolute, its name (`NAME=`) and
/// label (`:LABEL`) kept.
pub fn absolute_structure(source: &Path) -> Result<PathBuf> {
    let (name, file) = named_source(source);
    let absolute = std::path::absolute(file).with_context(|| format!("resolving {}", file.display()))?;
    Ok(match name {
        Some(name) => PathBuf::from(format!("{name}={}", absolute.display())),
        None => absolute,
    })
}

/// The structure `source` holds ([`structure_name`], its surface in m in the frame `to`), read as
/// an organ's segmentation is ([`OrganInput`]): a surface file in `unit`, in the frame its header
/// names (else `frame`); or `LABELMAP:LABEL`, a label's surface extracted from a labelmap (mm,
/// its scanner frame). The name must fit an OpenIGTLink device name
/// ([`register::registration::STRUCTURE_NAME_BYTES`]). With the
/// warning of a label whose cavities were filled (a hollow structure: its inner wall is not given
/// back), and whether its file names its frame (a labelmap placing its voxels, a surface's header).
pub fn read_structure(
    source: &Path,
    unit: LengthUnit,
    frame: Option<Frame>,
    to: Option<Frame>,
) -> Result<ReadStructure> {
    let name = structure_name(source);
    let source = named_source(source).1;
    // Its name is checked before its file is read.
    register::registration::check_structure_name(&name, &[])?;
    let mut input = match labelmap_label(source) {
        Some((path, label)) => OrganInput::read_with(Path::new(path), Some(label), None, &ExtractOptions::structure())?,
        None if is_labelmap(source) => anyhow::bail!(
            "a labelmap's structure is one of its labels: give {}:LABEL (a number or a segment name)",
            source.display()
        ),
        None => OrganInput::read(source, None, Some(unit))?,
    };
    let unit = input.unit()?;
    let (mut surface, named, frame) = (input.surface, input.frame.is_some(), input.frame.or(frame));
    let change = FrameChange::between(frame, to);
    surface.vertices.iter_mut().for_each(|p| *p = unit.point_to_metres(change.point(*p)));
    // (The organ's reading warnings, of an organ's size and border, are not a structure's.)
    let mut warnings = Vec::new();
    if let Some(filled) = input.extract.filter(|e| e.filled_voxels > 0) {
        warnings.push(format!(
            "`{name}` is hollow: {} of its {} voxels are a cavity it encloses, filled; its outer surface is given \
             back, not its inner wall",
            filled.filled_voxels, filled.voxels
        ));
    }
    Ok(ReadStructure { name, surface, warnings, names_frame: named })
}

/// A structure as [`read_structure`] reads it.
pub struct ReadStructure {
    /// Its name ([`structure_name`]).
    pub name: String,
    /// Its surface (m, in the frame asked).
    pub surface: TriSurface,
    /// What a user should know of it.
    pub warnings: Vec<String>,
    /// Whether its file names its frame.
    pub names_frame: bool,
}

impl ReadStructure {
    /// Whether it was brought into the organ's frame: both its file and the organ's name their
    /// frames (`organ_names_frame`).
    pub fn in_organ_frame(&self, organ_names_frame: bool) -> bool {
        self.names_frame && organ_names_frame
    }
}

/// The labelmap file of a structure `LABELMAP:LABEL` ([`read_structure`]'s); `None` for a surface
/// file.
pub fn structure_labelmap(source: &Path) -> Option<&Path> {
    labelmap_label(named_source(source).1).map(|(path, _)| Path::new(path))
}

impl RegistrationSpec {
    /// The registration of `method` with `targets` (in metres, the files' own unit where they name
    /// one), in the method's default settings, given points in metres and in the organ's frame.
    pub fn new(method: MethodSpec, targets: TargetsSpec) -> RegistrationSpec {
        let units = LengthUnit::Metre;
        RegistrationSpec {
            method,
            targets,
            units,
            given_units: units,
            given_frame: None,
            iterations: None,
            rigid: false,
            time_budget_ms: None,
            options: None,
            structures: Vec::new(),
            surface: None,
            sigma_factor: 1.0,
        }
    }

    /// The registration: the method loaded, the targets read and located in the organ (an error
    /// for one outside it, naming the likely unit mistake), the settings checked (the method's
    /// defaults where none are given: [`RegistrationSpec::options`]).
    pub fn build(&self) -> Result<Registration> {
        let Loaded { organ, frame: organ_frame, deformer, method, options, warnings } =
            self.method.load(self.options.as_ref())?;
        let (targets, read_warnings) = match &self.targets {
            TargetsSpec::Regions => (LabelledPoints::new(region_targets(organ.mesh())), Vec::new()),
            TargetsSpec::File(path) => crate::points::read_targets(path, self.units)?,
            TargetsSpec::Points(points) => {
                (LabelledPoints::new(points.iter().map(|&p| self.units.point_to_metres(p)).collect()), Vec::new())
            }
        };
        // (A file without any is refused as it is read.)
        if targets.points.is_empty() {
            anyhow::bail!("no targets: give a targets file, or a mesh with `markers` or `tumour` regions");
        }
        let options = RegistrationOptions {
            iterations: self.iterations.unwrap_or(options.iterations),
            rigid: options.rigid.or_else(|| self.rigid.then(register::RigidOptions::default)),
            time_budget_ms: self.time_budget_ms.or(options.time_budget_ms),
            ..options
        };
        options.validate()?;
        let what = match &self.targets {
            TargetsSpec::File(path) => format!("the targets of {}", path.display()),
            _ => "the targets".into(),
        };
        // The organ's mesh names the frame it works in, where it names one: targets in the other
        // are brought into it.
        let LabelledPoints { mut points, labels, frame, .. } = targets;
        if let (Some(organ), Some(named)) = (organ_frame, frame) {
            named.convert_all(organ, &mut points);
        }
        let mut registration = Registration::new(organ, deformer, method, points, labels, options)
            .with_context(|| what)?
            .in_frame(organ_frame.or(frame));
        warnings.into_iter().chain(read_warnings).for_each(|w| registration.warn(w));
        for source in &self.structures {
            let context = || format!("the structure {}", source.path.display());
            let unit = source.unit.unwrap_or(self.given_units);
            let read =
                read_structure(&source.path, unit, self.given_frame, registration.frame()).with_context(context)?;
            let added = match read.in_organ_frame(organ_frame.is_some()) {
                true => registration.add_structure_in_organ_frame(&read.name, read.surface),
                false => registration.add_structure(&read.name, read.surface),
            };
            added.with_context(context)?;
            read.warnings.into_iter().for_each(|w| registration.warn(w));
        }
        registration.calibrate_sigma(self.sigma_factor)?;
        if let Some(path) = &self.surface {
            let surface = read_organ_surface(path, registration.organ().mesh())?;
            registration.set_surface(surface).with_context(|| format!("the organ's surface {}", path.display()))?;
        }
        Ok(registration)
    }

    /// The coordinates clouds are given in to `organ` and its results given back in: in the
    /// unit given, from the frame given (else the organ's) to the organ's, the frame its
    /// registration works in ([`Registration::frame`]).
    pub fn coordinates(&self, organ: &Registration) -> GivenCoordinates {
        GivenCoordinates { unit: self.given_units, change: FrameChange::between(self.given_frame, organ.frame()) }
    }

    /// What [`RegistrationSpec::coordinates`] does with frames, in words; `named`: the frame a
    /// points file read so far named, and the file, where neither `--frame` nor the organ does.
    pub fn frame_line(&self, organ: &Registration, named: Option<(Frame, &str)>) -> String {
        match (self.given_frame, organ.frame()) {
            (Some(given), Some(organ)) if given != organ => format!(
                "{given}: clouds naming no frame are taken in it and results given in it; the organ's {organ} (x and y \
                 negated)"
            ),
            (given, Some(organ)) => {
                format!(
                    "{}, the organ's: clouds naming no frame are taken in it and results given in it",
                    given.unwrap_or(organ)
                )
            }
            (Some(given), None) => format!("{given}, given; the organ names none, so nothing is converted"),
            (None, None) => match named {
                Some((frame, by)) => format!(
                    "{frame}, named by {by}: coordinates are taken as given and the results named in it (the organ \
                     names none, so nothing is converted)"
                ),
                None => "none named by the organ or --frame: coordinates are taken as given, the results named in \
                         the frame a cloud's file names, if one does (else 3D Slicer's files, displacement.nrrd and \
                         targets.mrk.json, take them as LPS, Slicer's default; --frame RAS says otherwise)"
                    .into(),
            },
        }
    }

    /// The frame of a stream's coordinates: the one given, else RAS (3D Slicer's).
    pub fn stream_frame(&self) -> Frame {
        self.given_frame.unwrap_or(Frame::Ras)
    }

    /// [`RegistrationSpec::coordinates`] of a stream, whose frame is RAS (the frame OpenIGTLink
    /// sends) unless given; with a line that says what is done.
    pub fn stream_coordinates(&self, organ: &Registration) -> (GivenCoordinates, String) {
        let stream = self.stream_frame();
        let organ = organ.frame();
        let line = match organ {
            Some(organ) if organ != stream => {
                format!("the stream's {stream} converted to the organ's {organ} (x and y negated), and back")
            }
            Some(organ) => format!("{organ}, the stream's and the organ's"),
            None => format!("the organ names none: the stream's coordinates ({stream}) taken as the organ's"),
        };
        let change = FrameChange::between(Some(stream), organ);
        (GivenCoordinates { unit: self.given_units, change }, line)
    }
}

impl RegistrationSpec {
    /// The registration set-up of the patient directory `dir` (written by `augsim prepare`): the
    /// method it names, or `method` when given, with the σ its validation calibrated; its targets;
    /// the unit and frame of its inputs for the points given and given back.
    pub fn patient(
        dir: &Path,
        method: Option<PatientMethod>,
        iterations: Option<usize>,
        rigid: bool,
    ) -> Result<RegistrationSpec> {
        let p = Patient::read(dir)?;
        if let (None, Some(done)) = (method, steps_before_validation(dir)?) {
            anyhow::bail!(
                "{} is not prepared to the end: its validation, which chooses the method {PATIENT_FILE} names, has not \
                 run (steps done: {}); run the same `augsim prepare` again to resume it, or name the method (the \
                 FEM's is ready)",
                dir.display(),
                if done.is_empty() { "none".to_string() } else { done.join(", ") }
            );
        }
        let chosen = method.unwrap_or(p.method);
        let method = match chosen {
            PatientMethod::Fem => MethodSpec::fem(dir.join(p.fem)),
            PatientMethod::Learned => MethodSpec::learned(dir.join(p.model), dir.join(p.scenario)),
            PatientMethod::Hybrid => MethodSpec::hybrid(dir.join(p.model), dir.join(p.scenario), dir.join(p.fem)),
        };
        Ok(RegistrationSpec {
            units: p.units,
            given_units: p.input_units.unwrap_or(LengthUnit::DEFAULT),
            // Where the inputs were in the set-up's own frame, none: clouds are then in the organ's
            // frame, and a stream in OpenIGTLink's RAS.
            given_frame: p.input_frame.filter(|&f| f != SET_UP_FRAME),
            iterations,
            rigid,
            structures: p
                .structures
                .iter()
                .map(|path| StructureFile { path: dir.join(path), unit: Some(STRUCTURES_UNIT) })
                .collect(),
            surface: Some(dir.join(SURFACE_FILE)).filter(|path| path.is_file()),
            sigma_factor: p.sigma.of(chosen),
            ..RegistrationSpec::new(method, TargetsSpec::File(dir.join(p.targets)))
        })
    }
}

/// Rest positions of the nodes of the `markers` and `tumour` regions, when the mesh has them.
fn region_targets(m: &mesh::Mesh) -> Vec<Point> {
    ["markers", "tumour"].iter().filter_map(|r| m.region(r).ok()).flatten().map(|&n| m.nodes[n]).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A structure is named by `NAME=` where given, else by its file's stem or its label; a path
    /// with `=` in a folder's name, or a file there under the whole name, is a path.
    #[test]
    fn structures_are_named_as_given() {
        let name = |s: &str| structure_name(Path::new(s));
        assert_eq!((name("seg.nii.gz:2"), name("tumour=seg.nii.gz:2")), ("label_2".into(), "tumour".into()));
        assert_eq!((name("left lobe=a/b.stl"), name("a/b.stl")), ("left_lobe".into(), "b".into()));
        assert_eq!((name("runs/x=1/b.stl"), name("seg.seg.nrrd:liver vessels")), ("b".into(), "liver_vessels".into()));
        let dir = tempfile::tempdir().unwrap();
        let odd = dir.path().join("a=b.stl");
        std::fs::write(&odd, "").unwrap();
        assert_eq!(structure_name(&odd), "a=b");
        // A segment's name may hold a colon.
        assert_eq!(name("seg.seg.nrrd:Tu: S8"), "Tu:_S8");
        // Made absolute (as a set-up records them), the name and label are kept.
        let cwd = std::env::current_dir().unwrap();
        let absolute = |s: &str| absolute_structure(Path::new(s)).unwrap();
        assert_eq!(
            absolute("tumour=seg.nii.gz:2"),
            PathBuf::from(format!("tumour={}", cwd.join("seg.nii.gz:2").display()))
        );
        assert_eq!(absolute("b.stl"), cwd.join("b.stl"));
        assert_eq!(structure_name(&absolute("tumour=seg.nii.gz:2")), "tumour");
        // 3D Slicer's segmentation names its segments: a label's number gives its segment's name,
        // where one segment alone has it.
        let seg = dir.path().join("Segmentation.seg.nrrd");
        let affine = [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]];
        let mut map = mesh::labelmap::Labelmap::single([2, 2, 2], vec![0, 1, 1, 2, 0, 0, 3, 3], affine, Frame::Ras);
        map.segments = vec![("liver".into(), 0, 1), ("tumour S8".into(), 0, 2), ("cyst".into(), 0, 3)];
        map.segments.push(("another cyst".into(), 0, 3));
        mesh::labelmap::write_nrrd(&seg, &map).unwrap();
        let label = |n: i32| structure_name(Path::new(&format!("{}:{n}", seg.display())));
        assert_eq!([label(2), label(3), label(4)], ["tumour_S8", "label_3", "label_4"]);
    }

    /// A structure's labelmap is found behind its name and label; whether a structure's file names
    /// its frame (which then cannot be mixed up with the organ's) is told.
    #[test]
    fn a_structure_says_whether_its_file_names_its_frame() {
        assert_eq!(structure_labelmap(Path::new("tumour=seg.nii.gz:2")), Some(Path::new("seg.nii.gz")));
        assert_eq!(structure_labelmap(Path::new("b.stl")), None);
        let dir = tempfile::tempdir().unwrap();
        let ball = mesh::generate::icosphere(10.0, 2);
        let (named, plain) = (dir.path().join("named.stl"), dir.path().join("plain.stl"));
        mesh::io::write_surface_in_frame(&named, &ball, Frame::Lps).unwrap();
        mesh::io::write_surface(&plain, &ball).unwrap();
        let read =
            |path: &Path| read_structure(path, LengthUnit::Millimetre, None, Some(Frame::Lps)).unwrap().names_frame;
        assert!(read(&named) && !read(&plain));
    }

    /// A set-up whose preparation stopped before its validation chose a method is refused for its
    /// own method (registration.toml names one all the same), not for a method named.
    #[test]
    fn a_set_up_not_validated_is_refused_its_own_method() {
        use crate::prepare::{PrepareOptions, PrepareState, StepRecord};
        use crate::setup::STATE_FILE;
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        let set_up = "method = \"learned\"\nmodel = \"model\"\nscenario = \"dataset.toml\"\nfem = \"static.toml\"\n\
                      targets = \"targets.csv\"\nunits = \"mm\"\n";
        std::fs::write(d.join(PATIENT_FILE), set_up).unwrap();
        let steps = |names: &[&str]| {
            let steps = names.iter().map(|n| StepRecord { name: n.to_string(), seconds: 1.0, lines: Vec::new() });
            let options = PrepareOptions::new("s.stl".into(), [0.0; 3], "a.csv".into(), "t.csv".into());
            let state = PrepareState {
                format: "augsim-prepare".into(),
                options,
                steps: steps.collect(),
                input_frame: None,
                input_unit: None,
                input_digests: Default::default(),
            };
            std::fs::write(d.join(STATE_FILE), serde_json::to_string(&state).unwrap()).unwrap();
        };
        steps(&["organ", "scenarios", "dataset", "model", "evaluation"]);
        let e = RegistrationSpec::patient(d, None, None, false).unwrap_err().to_string();
        assert!(
            e.contains("is not prepared to the end")
                && e.contains("(steps done: organ, scenarios, dataset, model, evaluation)"),
            "{e}"
        );
        assert!(RegistrationSpec::patient(d, Some(PatientMethod::Fem), None, false).is_ok());
        steps(&["organ", "scenarios", "dataset", "model", "evaluation", "validation"]);
        assert!(RegistrationSpec::patient(d, None, None, false).is_ok());
        // A σ factor that is no factor is refused as the set-up is read, naming its key, whichever
        // method the run takes.
        std::fs::write(d.join(PATIENT_FILE), format!("{set_up}[sigma]\nhybrid = -2.0\n")).unwrap();
        let e = RegistrationSpec::patient(d, Some(PatientMethod::Fem), None, false).unwrap_err().to_string();
        assert!(e.ends_with("registration.toml: [sigma] hybrid = -2 must be positive and finite"), "{e}");
    }

    fn fem() -> RegistrationChoice {
        RegistrationChoice { fem: Some("beam".into()), ..RegistrationChoice::default() }
    }

    #[test]
    fn a_targets_file_names_the_working_frame_and_the_targets() {
        let dir = tempfile::tempdir().unwrap();
        let ras = dir.path().join("targets.mrk.json");
        std::fs::write(
            &ras,
            r#"{"markups": [{"coordinateSystem": "RAS", "controlPoints": [{"label": "t", "position": [2500, 500, 500]}]}]}"#,
        )
        .unwrap();
        let spec = |targets, given_frame| RegistrationSpec {
            given_frame,
            ..RegistrationSpec::new(MethodSpec::fem("beam"), targets)
        };
        let named = spec(TargetsSpec::File(ras.clone()), None).build().unwrap();
        assert_eq!((named.frame(), named.target_labels()), (Some(Frame::Ras), &["t".to_string()][..]));
        let points = spec(TargetsSpec::Points(vec![[2.5, 0.5, 0.5]]), None).build().unwrap();
        assert_eq!((points.frame(), points.target_labels()), (None, &[String::new()][..]));
        // A stream is RAS unless given otherwise; converted only where the organ names another.
        let flips =
            |given, organ: &Registration| spec(TargetsSpec::Regions, given).stream_coordinates(organ).0.change.flips();
        assert!(!flips(None, &named));
        assert!(flips(Some(Frame::Lps), &named));
        assert!(!flips(Some(Frame::Lps), &points), "the organ names no frame");
        assert!(spec(TargetsSpec::File(dir.path().join("missing.csv")), None).build().is_err());
    }

    /// An organ whose mesh file names its frame works in it: targets in the other frame are
    /// brought into it (x and y negated), not taken as they are.
    #[test]
    fn the_organ_s_mesh_names_the_working_frame() {
        let dir = tempfile::tempdir().unwrap();
        let mesh = mesh::box_tet([-0.1, -0.06, 0.0], [-0.02, 0.0, 0.05], [4, 3, 2]).unwrap();
        mesh::io::write_vtu_in_frame(dir.path().join("organ.vtu"), &mesh, &[], Frame::Lps).unwrap();
        let scenario = dir.path().join("static.toml");
        std::fs::write(
            &scenario,
            "kind = \"static\"\nname = \"lps\"\n[mesh.file]\npath = \"organ.vtu\"\n[material]\nlaw = \"linear\"\n\
             young = 5000.0\npoisson = 0.45\n[[fixed]]\nselect = { box = { min = [-0.2, -0.2, -0.001], max = [0.2, 0.2, \
             0.001] } }\n",
        )
        .unwrap();
        let ras = dir.path().join("targets.mrk.json");
        let json = r#"{"markups": [{"coordinateSystem": "RAS", "controlPoints": [{"label": "t", "position": [50, 30, 20]}]}]}"#;
        std::fs::write(&ras, json).unwrap();
        let registration =
            RegistrationSpec::new(MethodSpec::fem(&scenario), TargetsSpec::File(ras)).build().expect("inside in LPS");
        assert_eq!(registration.frame(), Some(Frame::Lps));
        let t = registration.targets()[0];
        assert!(mesh::norm(mesh::sub(t, [-0.05, -0.03, 0.02])) < 1e-12, "{t:?}");
    }

    /// The spec's time budget reaches the loop's settings, checked there; none by default.
    #[test]
    fn a_time_budget_given_reaches_the_loop() {
        let spec = |budget| RegistrationSpec {
            time_budget_ms: budget,
            ..RegistrationSpec::new(MethodSpec::fem("beam"), TargetsSpec::Points(vec![[2.5, 0.5, 0.5]]))
        };
        assert_eq!(spec(None).build().unwrap().options().time_budget_ms, None);
        assert_eq!(spec(Some(50.0)).build().unwrap().options().time_budget_ms, Some(50.0));
        let e = spec(Some(0.0)).build().err().unwrap().to_string();
        assert!(e.contains("time_budget_ms"), "{e}");
    }

    #[test]
    fn control_points_left_out_as_not_placed_are_said_among_the_registrations_warnings() {
        let dir = tempfile::tempdir().unwrap();
        let targets = dir.path().join("targets.mrk.json");
        std::fs::write(
            &targets,
            r#"{"markups": [{"coordinateUnits": "mm", "controlPoints": [{"label": "T-1", "position": [2500, 500, 500]},
                {"label": "T-2", "position": [0, 0, 0], "positionStatus": "undefined"}]}]}"#,
        )
        .unwrap();
        let registration =
            RegistrationSpec::new(MethodSpec::fem("beam"), TargetsSpec::File(targets.clone())).build().unwrap();
        assert_eq!(registration.targets(), [[2.5, 0.5, 0.5]]);
        let empty = dir.path().join("empty.csv");
        std::fs::write(&empty, "x,y,z\n").unwrap();
        let error =
            RegistrationSpec::new(MethodSpec::fem("beam"), TargetsSpec::File(empty.clone())).build().err().unwrap();
        assert_eq!(error.to_string(), format!("{} holds no targets", empty.display()));
        let said = format!("{}: 1 control point not placed in 3D Slicer", targets.display());
        assert!(
            registration.warnings().iter().any(|w| w.starts_with(&said) && w.ends_with(": T-2")),
            "{:?}",
            registration.warnings()
        );
    }

    #[test]
    fn choices_give_the_spec_of_their_method_targets_and_unit() {
        let choice = RegistrationChoice {
            targets: Some(TargetsSpec::Points(vec![[1.0, 2.0, 3.0]])),
            units: Some(LengthUnit::Millimetre),
            frame: Some(Frame::Ras),
            iterations: Some(7),
            rigid: true,
            ..fem()
        };
        let spec = choice.spec().unwrap();
        assert!(matches!(&spec.method, MethodSpec::Fem(ScenarioSource::File(p)) if p == Path::new("beam")));
        assert!(matches!(&spec.targets, TargetsSpec::Points(p) if p == &[[1.0, 2.0, 3.0]]));
        assert_eq!((spec.units, spec.iterations, spec.rigid), (LengthUnit::Millimetre, Some(7), true));
        assert_eq!((spec.given_units, spec.given_frame), (LengthUnit::Millimetre, Some(Frame::Ras)));
        let learned =
            RegistrationChoice { model: Some("m".into()), scenario: Some("s".into()), ..RegistrationChoice::default() };
        let spec = learned.spec().unwrap();
        assert!(matches!(&spec.method, MethodSpec::Learned {
            model: ModelSource::File(model), scenario: ScenarioSource::File(scenario), way: LearnedWay::Own }
            if model == Path::new("m") && scenario == Path::new("s")));
        assert!(matches!(spec.targets, TargetsSpec::Regions));
        assert_eq!((spec.units, spec.given_units), (LengthUnit::DEFAULT, LengthUnit::DEFAULT));
        let after_fit = RegistrationChoice { shape_model: Some("rom".into()), ..learned };
        assert!(matches!(&after_fit.spec().unwrap().method, MethodSpec::Learned {
            way: LearnedWay::AfterShapeFit(ModelSource::File(basis)), .. } if basis == Path::new("rom")));
    }

    /// A patient prepared from RAS files takes clouds naming no frame in RAS (its set-up works in
    /// LPS); one prepared from LPS files, or from files naming none, in the organ's own frame.
    #[test]
    fn a_patient_s_clouds_are_in_the_frame_of_the_files_it_was_prepared_from() {
        let dir = tempfile::tempdir().unwrap();
        let set_up =
            "model = \"model\"\nscenario = \"dataset.toml\"\nfem = \"static.toml\"\ntargets = \"targets.csv\"\n\
                      units = \"m\"\ninput_units = \"mm\"\n";
        for (frame, given) in
            [("input_frame = \"RAS\"\n", Some(Frame::Ras)), ("input_frame = \"LPS\"\n", None), ("", None)]
        {
            std::fs::write(dir.path().join(PATIENT_FILE), format!("{set_up}{frame}")).unwrap();
            let spec = RegistrationSpec::patient(dir.path(), None, None, false).unwrap();
            assert_eq!((spec.given_units, spec.given_frame), (LengthUnit::Millimetre, given), "{frame}");
            let choice = RegistrationChoice { patient: Some(dir.path().into()), ..RegistrationChoice::default() };
            assert_eq!(choice.spec().unwrap().given_frame, given, "{frame}");
            let asked = RegistrationChoice { frame: Some(Frame::Lps), ..choice };
            assert_eq!(asked.spec().unwrap().given_frame, Some(Frame::Lps), "the frame asked for wins");
        }
        std::fs::write(dir.path().join(PATIENT_FILE), format!("{set_up}input_shape = \"ball\"\n")).unwrap();
        let newer = RegistrationSpec::patient(dir.path(), None, None, false).unwrap_err().to_string();
        assert!(
            newer.contains("(prepared by a newer augsim? update it)") && newer.contains("unknown field `input_shape`")
        );
    }

    #[test]
    fn choices_that_do_not_fit_together_are_refused_by_name() {
        let none = RegistrationChoice::default();
        assert_eq!(none.check().unwrap_err(), NO_METHOD);
        let model_alone = RegistrationChoice { model: Some("m".into()), ..RegistrationChoice::default() };
        assert!(model_alone.spec().unwrap_err().to_string().contains("--model MODEL with --scenario SCENARIO"));
        let scenario_for_fem = RegistrationChoice { scenario: Some("liver_ar_t10".into()), ..fem() };
        let error = scenario_for_fem.check().unwrap_err();
        assert!(error.starts_with("--scenario (scenario= in Python) is a learned model's dataset scenario"), "{error}");
        let both = RegistrationChoice { model: Some("m".into()), ..fem() };
        assert_eq!(both.check().unwrap_err(), "give --fem or --model, not both (fem= or model= in Python)");
        let basis_alone = RegistrationChoice { shape_model: Some("rom".into()), ..fem() };
        let error = basis_alone.check().unwrap_err();
        assert!(error.starts_with("--shape-model (shape_model= in Python) is the basis"), "{error}");
        assert!(error.ends_with("give --model MODEL (a U-Net) too"), "{error}");
        let patient_and_more =
            RegistrationChoice { patient: Some("p".into()), targets: Some(TargetsSpec::Regions), ..fem() };
        assert_eq!(
            patient_and_more.check().unwrap_err(),
            "--patient DIR holds its method and targets: leave out --fem, --targets (fem=, targets= in Python)"
        );
        let use_hybrid_alone = RegistrationChoice { use_hybrid: true, ..fem() };
        assert!(use_hybrid_alone.check().unwrap_err().contains("give --patient DIR (patient= in Python)"));
        let patient = || RegistrationChoice { patient: Some("p".into()), ..RegistrationChoice::default() };
        let two_methods = RegistrationChoice { use_fem: true, use_hybrid: true, ..patient() };
        let error = two_methods.check().unwrap_err();
        assert!(
            error.contains("use_fem=True, use_fem=False and use_hybrid=True in Python") && error.ends_with("give one")
        );
        assert_eq!(PatientMethod::asked(false, false, true), Some(PatientMethod::Hybrid));
        assert_eq!(PatientMethod::asked(false, false, false), None);
        let missing = RegistrationChoice { patient: Some("no/such/dir".into()), ..RegistrationChoice::default() };
        assert!(missing.spec().unwrap_err().to_string().contains("augsim prepare"));
    }
}
