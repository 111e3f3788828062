//! The registration models and the loop settings each takes by default: the FEM of a static
//! scenario pulled by data springs ([`fem_model`], on the scenario's problem as a solve builds it:
//! [`solvable_problem`]); a learned model on the organ of the dataset scenario it was trained on
//! ([`learned_registration`]): a U-Net's match-and-membrane loop, a reduced-order model's shape
//! fit; and a hybrid's budgets ([`hybrid_options`]); where a model and its scenario come from
//! ([`ModelSource`], [`ScenarioSource`]).

use std::path::{Path, PathBuf};

use anyhow::{bail, Result};
use learn::data::generate::Input;
use learn::Model;
use mesh::Mesh;
use register::{
    shape, Deformer, FemDeformer, HybridDeformer, NetworkDeformer, Organ, RegistrationOptions, ShapeDeformer,
    ShapeOptions, TwoWay,
};
use scenario::{DatasetScenario, MeshSource, StaticScenario};

/// The loop's settings of a hybrid whose learned model takes the first `network_iterations` of a
/// frame from rest: `base` (the FEM's, which alone registers a stream's next frames) with
/// [`POLISH_ITERATIONS`] of the FEM after them.
pub fn hybrid_options(base: &RegistrationOptions, network_iterations: usize) -> RegistrationOptions {
    RegistrationOptions { iterations: network_iterations + POLISH_ITERATIONS, ..base.clone() }
}

/// The FEM registration model of a static scenario (paths relative to `dir`): its problem's mesh
/// (quadratic when the material asks for it) as the organ, pulled by data springs of the default
/// stiffness, with the scenario's solver; and the warning of pieces of its mesh left out
/// ([`solvable_problem`]).
pub fn fem_model(scenario: &StaticScenario, dir: &Path) -> Result<(Organ, FemDeformer, Option<String>)> {
    let (problem, left_out) = solvable_problem(scenario, dir)?;
    let organ = organ_of(&scenario.mesh, problem.mesh.clone())?;
    let stiffness = FemDeformer::default_stiffness(&problem);
    Ok((organ, FemDeformer::new(problem, stiffness, scenario.solver.clone())?, left_out))
}

/// The problem of `scenario` (paths relative to `dir`), as `augsim solve` and a FEM registration
/// build it: without the pieces of its mesh that hang on the rest by an edge or a vertex and carry
/// nothing ([`fem::Problem::idle_hanging_pieces`]: no load, hold or spring on the nodes they alone
/// have), rebuilt on the rest of the mesh (numbered as in its file), with the warning that says so.
/// Such a piece (a mesher's slip, as in a real liver's mesh) turns about its hinge at no cost of
/// energy, but carries no force: the rest deforms as with it, as CalculiX, which solves the whole
/// mesh, finds. A piece that carries something is a mechanism: the problem is left as it is, and a
/// solve refuses it, naming the piece.
pub fn solvable_problem(scenario: &StaticScenario, dir: &Path) -> Result<(fem::Problem, Option<String>)> {
    let problem = scenario.build_problem(dir)?;
    let cells: Vec<usize> = problem.idle_hanging_pieces().concat();
    let Some(&first) = cells.first() else { return Ok((problem, None)) };
    let mesh = &problem.mesh;
    let kept = mesh.without_cells(&cells)?;
    let alone = mesh.num_nodes() - kept.num_nodes();
    let rest = scenario.build_problem_on(kept)?;
    let line = format!(
        "{} element(s) hang on the rest by an edge or a vertex (the first: element {} of the file) and carry no \
         load, hold or spring: left out of the solve with the {} node(s) only they have (they carry no force, so the \
         rest deforms as with them); the fields file_node and file_cell give the file's numbers",
        cells.len(),
        mesh.file_cell(first),
        alone
    );
    Ok((rest, Some(line)))
}

/// The organ of a mesh built from `source`: the mesh, with the phantom's smooth surface when
/// it is the phantom's immersed grid (the camera sees the organ, not the grid's staircase).
pub fn organ_of(source: &MeshSource, mesh: Mesh) -> Result<Organ> {
    let surface = match source {
        MeshSource::PhantomGrid { .. } => Some(mesh::boundary_surface(&mesh::phantom::liver_phantom(5000)?)),
        _ => None,
    };
    Ok(Organ::new(mesh, surface)?)
}

/// A trained network and the dataset scenario it was trained on.
pub struct Network<'a> {
    /// The network.
    pub model: &'a Model,
    /// Its dataset scenario: the organ's mesh and the network's input nodes.
    pub scenario: &'a DatasetScenario,
    /// The scenario's directory (mesh paths are relative to it).
    pub dir: &'a Path,
}

impl<'a> Network<'a> {
    /// Each of `models`, trained on the dataset scenario `scenario` (its paths relative to `dir`).
    pub fn each(models: &'a [Model], scenario: &'a DatasetScenario, dir: &'a Path) -> Vec<Network<'a>> {
        models.iter().map(|model| Network { model, scenario, dir }).collect()
    }

    /// The model and its scenario, in memory, as a method's spec takes them.
    pub fn sources(&self) -> (ModelSource, ScenarioSource<DatasetScenario>) {
        let scenario = ScenarioSource::Given { scenario: Box::new(self.scenario.clone()), dir: self.dir.to_path_buf() };
        (ModelSource::Given(self.model.clone()), scenario)
    }
}

/// The U-Net registration model of a network: its scenario's organ, the network fed with the
/// displacement of the scenario's input nodes.
pub fn network_model(network: &Network) -> Result<(Organ, NetworkDeformer)> {
    let (scenario, model) = (network.scenario, network.model);
    // A U-Net is fed its scenario's encoding of the input nodes' motion: another scenario of the
    // same grid (other nodes, another element) feeds it inputs it never saw. (A reduced-order
    // model's shape fit works in its basis, whatever scenario gave it.)
    let trained_on = model.provenance().and_then(|p| p.own.scenario());
    if let Some(trained_on) = trained_on.filter(|&s| s != scenario.name && model.method() == learn::Method::UNet) {
        bail!(
            "the U-Net was trained on data of scenario {trained_on}, not {}: give the model's own dataset scenario \
             (--scenario {trained_on})",
            scenario.name
        );
    }
    // The mesh its samples were solved and encoded on: quadratic when the scenario's material
    // asks for T10 (the mid-edge nodes are network inputs too).
    let generator = scenario.generator(network.dir)?;
    if model.grid() != generator.grid() {
        bail!(
            "the model was trained on a {} grid, scenario {} encodes its organ on {}: give the model's own dataset \
             scenario",
            model.grid(),
            scenario.name,
            generator.grid()
        );
    }
    let mesh = generator.mesh().clone();
    let (inputs, normal) = match &scenario.dataset.input {
        Input::Displacement { nodes, normal, .. } => (nodes.select(&mesh)?, *normal),
        Input::Force => {
            bail!("scenario {}: registration needs a network of displacements, not of forces", scenario.name)
        }
    };
    let organ = organ_of(&scenario.mesh, mesh)?;
    let deformer = NetworkDeformer::new(model, &organ, &inputs, normal)?;
    Ok((organ, deformer))
}

/// The registration of a learned model on its scenario's organ, its loop's settings from
/// `options` (the case's settings for its learned models). A model with a basis (the reduced-order
/// model) fits its shape space ([`ShapeDeformer`], with its own loop budgets): from rest coarse to
/// fine, on a stream's warm-started frame [`shape::SHAPE_WARM_ITERATIONS`] iterations of all its modes under
/// the model's own prior ([`rom_stream_shape`]). On the design cases streamed (the built-in case
/// pressed at 1–2.5 N, lifted, dragged and pulled; 21 frames each) that left 2.54 mm at the peak
/// and 1.59 mm over the frames (93 % of the targets within 2σ), where one fit from the last
/// frame's posterior, then a membrane fitted to the matches where the cloud sees the surface (the
/// unseen held at the fit's) left 2.69 and 1.70 mm: the membrane went astray on a lift of the right
/// lobe (3.65 mm at the peak against 1.87 mm). The U-Net fits a membrane to the matches and
/// predicts from it ([`NetworkDeformer`]), on a stream's warm-started frames the unseen held at the
/// last frame's ([`NetworkDeformer::holding_unseen_on_warm_frames`]); given a `basis` (a
/// reduced-order model), it predicts from the shape fit of that model's shape space
/// ([`HybridDeformer`], [`NETWORK_AFTER_FIT`]), the surface unseen held at the fit's, and on a
/// warm-started frame fits once from the last posterior first: on the design cases streamed 1.42 mm
/// over the frames where the U-Net's own loop on those frames (the unseen spread by the membrane)
/// left 1.54 mm, from rest 2.08 against 2.09 mm; on a stream whose camera turns 30° a frame it left
/// 1.54 mm where the U-Net's loop diverged (17.9 mm).
pub fn learned_registration(
    network: &Network,
    basis: Option<&Model>,
    options: &RegistrationOptions,
) -> Result<LearnedRegistration> {
    let (organ, membrane) = network_model(network)?;
    let (deformer, options): (Box<dyn Deformer + Send>, _) = match (network.model, basis) {
        (Model::Reduced(_), None) => {
            let fit = shape_fit(network.model, &organ, rom_stream_shape())?;
            (Box::new(fit), shape::loop_options(options))
        }
        (Model::Reduced(_), Some(_)) => {
            bail!("a reduced-order model fits its own shape space: another model's basis is for a U-Net")
        }
        // One way from rest, both ways on a stream's frames: on the design cases streamed (21 frames
        // each), matching both ways brought the U-Net's TRE at the peak from 2.41 to 1.98 mm on
        // average (better on all 7 cases); from rest it changed little (2.48 → 2.42 mm, better on 3,
        // worse on 2).
        (Model::UNet(_), None) => {
            let membrane = Box::new(membrane.holding_unseen_on_warm_frames());
            (membrane, RegistrationOptions { two_way: TwoWay::Streamed, ..options.clone() })
        }
        (Model::UNet(_), Some(basis)) => {
            let fit = shape_fit(basis, &organ, ShapeOptions::default())?;
            let membrane = Box::new(membrane.holding_unseen());
            let hybrid = HybridDeformer::new(Box::new(fit), membrane, shape::SHAPE_ITERATIONS)?
                .first_on_warm_frames(1)
                .sigma_scaled(NETWORK_AFTER_FIT_SIGMA)?;
            let (iterations, warm_iterations) =
                (shape::SHAPE_ITERATIONS + NETWORK_AFTER_FIT, NETWORK_AFTER_FIT_WARM_ITERATIONS);
            (Box::new(hybrid), RegistrationOptions { iterations, warm_iterations, ..shape::loop_options(options) })
        }
    };
    Ok(LearnedRegistration { organ, deformer, options })
}

/// The shape fit of `model`'s shape space (a model with a basis) on `organ`, whose mesh must lie in
/// the model's grid, in the settings `shape`.
pub fn shape_fit(model: &Model, organ: &Organ, shape: ShapeOptions) -> Result<ShapeDeformer> {
    let space = register::model_shape_space(model, organ, shape.max_modes)?;
    Ok(ShapeDeformer::new(space, organ, shape)?)
}

/// A reduced-order model's shape fit in its own registration: on a stream's warm-started frame, the
/// model's own prior (`widening` 1: the last frame's posterior lends the start of the matches, not
/// the prior). On the design cases streamed, widenings 0.3, 0.7 and 1 left 2.73, 2.63 and 2.54 mm at
/// the peak (1.79, 1.66 and 1.59 mm over the frames): a prior held near the last frame lags behind a
/// press that goes on (2.5 N: 6.86 mm at 0.3 against 6.52 mm).
pub fn rom_stream_shape() -> ShapeOptions {
    ShapeOptions { widening: 1.0, ..ShapeOptions::default() }
}

/// The U-Net's iterations after the shape fit of a reduced-order model's basis, on a frame from
/// rest ([`learned_registration`]). On the design cases (the built-in case pressed at 1–2.5 N,
/// lifted, dragged and pulled), one and two gave 1.95 mm (two at 1.5× the time); the shape fit
/// alone 2.34 mm, the U-Net alone 2.48 mm, the reduced-order model's own membrane loop after the
/// fit 2.60 mm (one iteration) and 2.76 mm (two).
pub const NETWORK_AFTER_FIT: usize = 1;

/// The iterations of a warm-started frame of the U-Net after a reduced-order model's shape fit: one
/// of the fit from the last frame's posterior, then [`NETWORK_AFTER_FIT`] of the U-Net.
pub const NETWORK_AFTER_FIT_WARM_ITERATIONS: usize = 1 + NETWORK_AFTER_FIT;

/// The factor on σ of the U-Net after a reduced-order model's shape fit (the fit's posterior σ
/// widened by the U-Net's move from it, [`HybridDeformer`]), calibrated on validation
/// registrations: the design cases (the built-in case pressed at 1, 1.5, 2 and 2.5 N, a lift, a
/// drag and a pull, 30 targets each; not the held-out suite). Unscaled, that σ was 3.44 mm on
/// average from rest with 91 % of the targets within 2σ, 2.55 mm and 96 % on their streams: the
/// U-Net lands nearer the truth than the fit's spread and its move say. Factors 0.6, 0.7, 0.8 and
/// 0.9 kept 91 % from rest (the targets outside 2σ lie far outside) and left 90, 93, 95 and 96 %
/// on the streams; 0.8, the smallest that keeps a Gaussian's 95 % there, gives 2.75 mm from
/// rest and 2.04 mm on streams.
pub const NETWORK_AFTER_FIT_SIGMA: f64 = 0.8;

/// A reduced-order model's hybrid: `hybrid` (its shape fit from rest, then the FEM) with the shape
/// fit alone on a stream's next frames, in the settings the fit registers them with alone
/// ([`shape::loop_options`]); `options` otherwise. On `prepare`'s validations (streams of four
/// frames), the hybrid's next frames registered by the FEM gave SOFA's liver 2.10 mm over the
/// frames, the AMOS CT liver held within 50 mm 2.11 mm and TotalSegmentator's example liver
/// 2.18 mm; by the shape fit alone 1.06, 1.94 and 1.19 mm (the FEM's own registration 2.24, 2.05
/// and 2.22 mm).
pub fn rom_hybrid(hybrid: HybridDeformer, options: RegistrationOptions) -> (HybridDeformer, RegistrationOptions) {
    let fit = shape::loop_options(&options);
    let options = RegistrationOptions { warm_iterations: fit.warm_iterations, two_way: fit.two_way, ..options };
    (hybrid.first_alone_on_warm_frames(), options)
}

/// The FEM's iterations after a learned model's in a hybrid registration from rest, by default
/// ([`crate::registration::MethodSpec::Hybrid`]). On the design cases (the built-in case pressed
/// at 1–2.5 N, lifted, dragged and pulled; from rest), 1, 2, 3 and 4 co-rotational iterations
/// after the reduced-order model's shape fit gave a mean TRE of 2.40, 2.38, 2.40 and 2.41 mm,
/// the shape fit alone on the FEM's mesh 2.73 mm (on the model's own quadratic mesh 2.34 mm), the
/// FEM alone 2.94 mm.
pub const POLISH_ITERATIONS: usize = 2;

/// A learned model's registration method ([`learned_registration`]).
pub struct LearnedRegistration {
    /// Its scenario's organ.
    pub organ: Organ,
    /// How it deforms.
    pub deformer: Box<dyn Deformer + Send>,
    /// The loop's settings.
    pub options: RegistrationOptions,
}

/// A method's scenario: a file (or a built-in name), or a scenario already in memory.
#[derive(Clone, Debug)]
pub enum ScenarioSource<T> {
    /// A scenario file, or a built-in scenario's name.
    File(PathBuf),
    /// A scenario in memory.
    Given {
        /// The scenario.
        scenario: Box<T>,
        /// The directory its relative paths start from.
        dir: PathBuf,
    },
}

impl<T: Clone> ScenarioSource<T> {
    /// The scenario and its directory; a file is read with `load`.
    pub(crate) fn read(&self, load: impl Fn(&Path) -> scenario::Result<(T, PathBuf)>) -> Result<(T, PathBuf)> {
        Ok(match self {
            ScenarioSource::File(path) => load(path)?,
            ScenarioSource::Given { scenario, dir } => (T::clone(scenario), dir.clone()),
        })
    }
}

/// A learned model: its file, or a model in memory (e.g. just trained).
#[derive(Clone, Debug)]
pub enum ModelSource {
    /// A U-Net's or a reduced-order model's directory, or its model.json.
    File(PathBuf),
    /// A model in memory.
    Given(Model),
}

impl ModelSource {
    /// The model, and its kind and file in words.
    pub(crate) fn load(&self) -> Result<(Model, String)> {
        Ok(match self {
            ModelSource::File(path) => {
                let model = Model::load(path)?;
                let words = format!("{} {}", model.method().display_name(), path.display());
                (model, words)
            }
            ModelSource::Given(model) => (model.clone(), model.method().display_name().to_string()),
        })
    }
}
