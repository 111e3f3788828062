//! A registration set up from its files, as `augsim register`, `augsim serve` and the Python
//! package build it: the FEM of a static scenario, or a learned model (U-Net or reduced-order
//! model) with the dataset scenario it was trained on; the targets from a file, from points or
//! from the mesh's regions, in their unit; the loop's settings.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use mesh::Point;
use register::{FemDeformer, Registration, RegistrationOptions};
use scenario::{CaseScenario, DatasetScenario, StaticScenario};

use crate::case::{learned_registration, network_options, organ_of, Network};

/// What deforms the organ.
#[derive(Clone, Debug)]
pub enum MethodSpec {
    /// The FEM of a static scenario (a file or a built-in name): its mesh, material, fixed nodes
    /// and solver, pulled by springs of the default stiffness.
    Fem(PathBuf),
    /// A learned model (its directory or model.json) and the dataset scenario it was trained on
    /// (a file or a built-in name), whose mesh is the organ.
    Learned {
        /// The model.
        model: PathBuf,
        /// Its dataset scenario.
        scenario: PathBuf,
    },
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

/// A registration described by its files and settings; [`RegistrationSpec::build`] makes it.
#[derive(Clone, Debug)]
pub struct RegistrationSpec {
    /// What deforms the organ.
    pub method: MethodSpec,
    /// The targets.
    pub targets: TargetsSpec,
    /// Metres per unit of the given targets (1e-3: mm); see [`register::cloud::metres_per_unit`].
    pub unit: f64,
    /// Most match-and-deform iterations from rest, in place of the method's default.
    pub iterations: Option<usize>,
    /// A rigid pre-alignment of the first cloud (trimmed ICP).
    pub rigid: bool,
}

impl RegistrationSpec {
    /// The registration: the method loaded, the targets read and located in the organ (an error
    /// for one outside it, naming the likely unit mistake), the settings checked. The default
    /// settings are the library's for a FEM; for a learned model, the real-time iteration budgets
    /// of the built-in registration case's network method.
    pub fn build(&self) -> Result<Registration> {
        let (organ, deformer, method, options): (_, Box<dyn register::Deformer + Send>, _, _) = match &self.method {
            MethodSpec::Fem(path) => {
                let (scenario, dir) = StaticScenario::load(path)?;
                let problem = scenario.build_problem(&dir)?;
                let organ = organ_of(&scenario.mesh, problem.mesh.clone())?;
                let method =
                    format!("FEM, {:?} ({:?} elements)", problem.material.law, problem.material.resolved_formulation());
                let stiffness = FemDeformer::default_stiffness(&problem);
                let deformer = FemDeformer::new(problem, stiffness, scenario.solver.clone())?;
                (organ, Box::new(deformer), method, RegistrationOptions::default())
            }
            MethodSpec::Learned { model: model_path, scenario } => {
                let (scenario, dir) = DatasetScenario::load(scenario)?;
                let model = learn::Model::load(model_path)?;
                let network = Network { model: &model, scenario: &scenario, dir: &dir };
                let learned = learned_registration(&network, &network_options(&CaseScenario::builtin())?)?;
                let method = format!("{} {}", model.method().display_name(), model_path.display());
                (learned.organ, learned.deformer, method, learned.options)
            }
        };
        let targets = match &self.targets {
            TargetsSpec::Regions => region_targets(organ.mesh()),
            TargetsSpec::File(path) => crate::points::read_targets(path, self.unit)?,
            TargetsSpec::Points(points) => scaled(points, self.unit),
        };
        if targets.is_empty() {
            anyhow::bail!("no targets: give a targets file, or a mesh with `markers` or `tumour` regions");
        }
        let options = RegistrationOptions {
            iterations: self.iterations.unwrap_or(options.iterations),
            rigid: self.rigid.then(register::RigidOptions::default),
            ..options
        };
        options.validate()?;
        let what = match &self.targets {
            TargetsSpec::File(path) => format!("the targets of {}", path.display()),
            _ => "the targets".into(),
        };
        Registration::new(organ, deformer, method, targets, options).with_context(|| what)
    }
}

/// The file of a patient's registration set-up in the directory `augsim prepare` writes.
pub const PATIENT_FILE: &str = "registration.toml";

/// How a patient's organ is registered: with its learned model or with its FEM.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Deserialize, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum PatientMethod {
    /// The learned model, on its dataset scenario.
    #[default]
    Learned,
    /// The FEM of the static scenario.
    Fem,
}

impl PatientMethod {
    /// The method asked for on a command line: the FEM with `fem`, the learned model with
    /// `learned`, otherwise (`None`) the set-up's own.
    pub fn asked(fem: bool, learned: bool) -> Option<PatientMethod> {
        match (fem, learned) {
            (true, _) => Some(PatientMethod::Fem),
            (false, true) => Some(PatientMethod::Learned),
            (false, false) => None,
        }
    }

    /// How the set-up file names it.
    pub fn name(self) -> &'static str {
        match self {
            PatientMethod::Learned => "learned",
            PatientMethod::Fem => "fem",
        }
    }
}

/// A patient's registration set-up ([`PATIENT_FILE`]): the method `augsim prepare` found the
/// better on its validation, the learned model and its dataset scenario, the FEM alternative, the
/// targets and their unit; paths relative to the file.
#[derive(Clone, Debug, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct Patient {
    #[serde(default)]
    method: PatientMethod,
    model: PathBuf,
    scenario: PathBuf,
    fem: PathBuf,
    targets: PathBuf,
    units: String,
}

impl RegistrationSpec {
    /// The registration set-up of the patient directory `dir` (written by `augsim prepare`): the
    /// method it names, or `method` when given; its targets.
    pub fn patient(
        dir: &Path,
        method: Option<PatientMethod>,
        iterations: Option<usize>,
        rigid: bool,
    ) -> Result<RegistrationSpec> {
        let path = dir.join(PATIENT_FILE);
        let text = std::fs::read_to_string(&path).with_context(|| {
            format!("reading {} (is {} a directory made by augsim prepare?)", path.display(), dir.display())
        })?;
        let p: Patient = toml::from_str(&text).with_context(|| format!("reading {}", path.display()))?;
        let unit = register::cloud::metres_per_unit(&p.units)
            .map_err(anyhow::Error::msg)
            .with_context(|| format!("{}: units", path.display()))?;
        let method = match method.unwrap_or(p.method) {
            PatientMethod::Fem => MethodSpec::Fem(dir.join(p.fem)),
            PatientMethod::Learned => MethodSpec::Learned { model: dir.join(p.model), scenario: dir.join(p.scenario) },
        };
        Ok(RegistrationSpec { method, targets: TargetsSpec::File(dir.join(p.targets)), unit, iterations, rigid })
    }
}

/// Points multiplied by `unit` (to metres).
fn scaled(points: &[Point], unit: f64) -> Vec<Point> {
    points.iter().map(|p| p.map(|x| x * unit)).collect()
}

/// Rest positions of the nodes of the `markers` and `tumour` regions, when the mesh has them.
fn region_targets(m: &mesh::Mesh) -> Vec<Point> {
    ["markers", "tumour"].iter().filter_map(|r| m.region(r).ok()).flatten().map(|&n| m.nodes[n]).collect()
}
