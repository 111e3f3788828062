//! A synthetic intraoperative case on the built-in phantom: the ground truth
//! comes from a finer mesh and another law than the registration model (no
//! inverse crime), the cloud from a camera looking at its deformed surface.
//! The case and its methods are described by a [`CaseScenario`]
//! (the built-in `register_case` scenario is the built-in one).

use std::path::{Path, PathBuf};

use fem::{Material, Problem, SolverOptions, StaticSolver};
use mesh::phantom::PhantomSpec;
use mesh::{Mesh, NodeSelection, Point};

use learn::data::generate::Input;
use learn::Model;

use anyhow::{anyhow, bail, Context, Result};
use register::{
    shape, Deformer, FemDeformer, FrameOutcome, HybridDeformer, NetworkDeformer, Organ, RegisterError,
    RegistrationOptions, RestAndStream, RigidTransform, ShapeDeformer, ShapeOptions, Summary, TwoWay,
};
use scenario::registration::{CameraSpec, MethodKind, Misalignment};
use scenario::{CaseScenario, DatasetScenario, Fixed, MeshSource, StaticScenario};

use crate::registration::{LearnedWay, MethodSpec, ModelSource, RegistrationSpec, ScenarioSource, TargetsSpec};
use crate::simulate::{simulate_cloud, CameraModel};

/// Tetrahedra of the ground-truth phantom of the built-in case.
pub const TRUTH_TETS: usize = 9000;

/// What the operating room gives (the clouds) and what it hides (the truth).
#[derive(Clone, Debug)]
pub struct SyntheticCase {
    /// The frames, in order: one, or a press and release ([`scenario::registration::TruthSpec::frames`]).
    pub frames: Vec<CaseFrame>,
    /// Internal targets at rest (the phantom's `markers`), in the model's frame.
    pub targets: Vec<Point>,
    /// Model frame → camera frame: the scenario's misalignment (the identity when none).
    pub pose: RigidTransform,
    /// The truth's organ (its finer mesh), in the model's frame.
    pub truth_organ: Organ,
}

/// One frame of a [`SyntheticCase`].
#[derive(Clone, Debug)]
pub struct CaseFrame {
    /// The force pushing the truth (N).
    pub force: f64,
    /// The intraoperative cloud, in the camera's frame.
    pub cloud: Vec<Point>,
    /// The targets' true deformed positions, in the camera's frame.
    pub truth: Vec<Point>,
    /// The truth's displacement (m, 3 per node of [`SyntheticCase::truth_organ`]).
    pub truth_u: Vec<f64>,
}

impl SyntheticCase {
    /// The index of the frame of the largest force (the first of them).
    pub fn peak_index(&self) -> usize {
        let mut best = 0;
        for (k, f) in self.frames.iter().enumerate() {
            if f.force.abs() > self.frames[best].force.abs() {
                best = k;
            }
        }
        best
    }

    /// The frame of the largest force: the case of a single frame.
    pub fn peak(&self) -> &CaseFrame {
        &self.frames[self.peak_index()]
    }

    /// The targets' truth of the frames, in order.
    pub fn truths(&self) -> Vec<Vec<Point>> {
        self.frames.iter().map(|f| f.truth.clone()).collect()
    }

    /// The same truth seen by `camera`: each frame's cloud drawn anew from its deformed surface
    /// (frame `k` from `seed + k`) and moved by the case's pose. Another view of a case costs no
    /// solve of its truth.
    pub fn seen_by(mut self, camera: &CameraModel, seed: u64) -> Result<SyntheticCase> {
        for (k, frame) in self.frames.iter_mut().enumerate() {
            let surface = self.truth_organ.deformed_surface(&frame.truth_u);
            frame.cloud = simulate_cloud(&surface, camera, seed + k as u64)?;
            frame.cloud.iter_mut().for_each(|x| *x = self.pose.apply(*x));
        }
        Ok(self)
    }
}

/// The case of `scenario`: the phantom of `truth.tets` tetrahedra and `truth.material`, fixed on
/// `truth.fixed`, pushed along `truth.direction` by each frame's force spread over `truth.load`
/// (each frame's solve starts from the previous one); the camera's view of each deformed
/// surface, reproducible from its seed; clouds and truths moved by the misalignment.
pub fn synthetic_case(scenario: &CaseScenario) -> Result<SyntheticCase> {
    scenario.validate().map_err(|m| anyhow!("case {}: {m}", scenario.name))?;
    let t = &scenario.truth;
    let mut spec = PhantomSpec::default();
    if let Some(patch) = t.patch {
        spec.push = patch;
    }
    let m = spec.mesh(t.tets)?;
    let mut p = Problem::new(m, t.material);
    let fixed = p.mesh.region(&t.fixed)?.to_vec();
    let load = p.mesh.region(&t.load)?.to_vec();
    p.fix(&fixed);
    let len = mesh::dot(t.direction, t.direction).sqrt();
    let markers = p.mesh.region(&t.targets)?.to_vec();
    let targets: Vec<Point> = markers.iter().map(|&n| p.mesh.nodes[n]).collect();
    let organ = Organ::new(p.mesh.clone(), None)?;
    let pose = scenario.misalignment.transform().map_err(|m| anyhow!(m))?;
    let camera = &scenario.camera;
    let mut solver = StaticSolver::new(p)?;
    let mut frames: Vec<CaseFrame> = Vec::with_capacity(t.frames);
    for force in t.frame_forces() {
        let problem = solver.problem_mut();
        problem.f_ext.iter_mut().for_each(|f| *f = 0.0);
        problem.add_force(&load, t.direction.map(|d| d / len * force));
        let start = frames.last().map(|f| f.truth_u.as_slice());
        let u = solver.solve_from(start, &SolverOptions::default())?.u;
        let nodes = &solver.problem().mesh.nodes;
        let truth: Vec<Point> =
            markers.iter().map(|&n| pose.apply(std::array::from_fn(|d| nodes[n][d] + u[3 * n + d]))).collect();
        frames.push(CaseFrame { force, cloud: Vec::new(), truth, truth_u: u });
    }
    SyntheticCase { frames, targets, pose, truth_organ: organ }.seen_by(&camera_model(camera), camera.seed)
}

/// The built-in case ([`CaseScenario::builtin`]: the Neo-Hookean phantom, E = 5 kPa, ν = 0.48,
/// on quadratic tetrahedra built from about [`TRUTH_TETS`] tetrahedra, fixed between the lobes) with its `push` patch
/// pressed down by `force` N, seen by `camera` from `seed`, without misalignment.
pub fn phantom_push(force: f64, camera: &CameraModel, seed: u64) -> Result<SyntheticCase> {
    let mut scenario = CaseScenario::builtin();
    scenario.truth.force = force;
    scenario.camera =
        CameraSpec { view: camera.view, points: camera.points, noise: camera.noise, outliers: camera.outliers, seed };
    scenario.misalignment = Misalignment::default();
    synthetic_case(&scenario)
}

/// Tetrahedra of the registration models (the FEM models and the network's training mesh).
pub const MODEL_TETS: usize = 3000;

/// The phantom of about [`MODEL_TETS`] tetrahedra that the registration models deform
/// (another mesh than the truth's).
pub fn model_mesh() -> Result<Mesh> {
    Ok(mesh::phantom::liver_phantom(MODEL_TETS)?)
}

/// The FEM registration model of a static scenario (paths relative to `dir`): its problem's mesh
/// (quadratic when the material asks for it) as the organ, pulled by data springs of the default
/// stiffness, with the scenario's solver.
pub fn fem_model(scenario: &StaticScenario, dir: &Path) -> Result<(Organ, FemDeformer)> {
    let problem = scenario.build_problem(dir)?;
    let organ = organ_of(&scenario.mesh, problem.mesh.clone())?;
    let stiffness = FemDeformer::default_stiffness(&problem);
    Ok((organ, FemDeformer::new(problem, stiffness, scenario.solver.clone())?))
}

/// The co-rotational registration model (E = 5 kPa, ν = 0.48: another law than the truth's) on
/// [`model_mesh`], fixed between the lobes: the built-in static scenario `liver_corotational`.
pub fn corotational_model() -> Result<(Organ, FemDeformer)> {
    fem_model(&StaticScenario::builtin("liver_corotational"), Path::new(""))
}

/// The FEM of `scenario`'s method `name` of `material`: the phantom of `models.tets` linear
/// tetrahedra (quadratic when the material asks for it), fixed on the truth's fixed region.
pub fn fem_scenario(scenario: &CaseScenario, name: &str, material: Material) -> StaticScenario {
    let fixed = Fixed { select: NodeSelection::Region(scenario.truth.fixed.clone()) };
    let source = MeshSource::Phantom { tets: scenario.models.tets };
    StaticScenario { fixed: vec![fixed], ..StaticScenario::new(name, source, material) }
}

/// The shipped augmented-reality network, relative to the repository's root ([`shipped`]).
pub const SHIPPED_MODEL: &str = "models/liver_ar";

/// The shipped augmented-reality reduced-order model, trained on the same scenario.
pub const SHIPPED_ROM: &str = "models/liver_ar_rom";

/// The shipped scenario-1 network (forces to displacement).
pub const SHIPPED_FORCES_MODEL: &str = "models/liver_forces";

/// Where a shipped model (`models/...`) is: under the directory the command runs from, else in
/// the repository this program was built from; `None` where neither has it.
pub fn shipped(model: &str) -> Option<PathBuf> {
    let here = PathBuf::from(model);
    match here.exists() {
        true => Some(here),
        false => Path::new(env!("CARGO_MANIFEST_DIR")).join("../..").join(model).canonicalize().ok(),
    }
}

/// The shipped U-Net and reduced-order model that are found ([`shipped`]), and a line for each
/// one skipped.
pub fn shipped_models() -> Result<(Vec<Model>, Vec<String>)> {
    let (mut models, mut skipped) = (Vec::new(), Vec::new());
    for name in [SHIPPED_MODEL, SHIPPED_ROM] {
        match shipped(name) {
            Some(path) => models.push(Model::load(&path)?),
            None => skipped.push(skipped_line(name)),
        }
    }
    Ok((models, skipped))
}

/// The line saying that the shipped model `name` is skipped, not found ([`shipped`]).
pub fn skipped_line(name: &str) -> String {
    format!("skipped: {name} not found, here or where augsim was built")
}

/// The name of the built-in dataset scenario of the shipped AR network.
pub const AR_SCENARIO: &str = "liver_ar_t10";

/// The built-in scenario [`AR_SCENARIO`], parsed.
pub fn ar_scenario() -> DatasetScenario {
    DatasetScenario::builtin(AR_SCENARIO)
}

/// The camera model of a case's camera.
pub fn camera_model(camera: &CameraSpec) -> CameraModel {
    CameraModel { view: camera.view, points: camera.points, noise: camera.noise, outliers: camera.outliers }
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

impl Network<'_> {
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

/// The target errors (m) of a network model ([`network_model`]: its organ and deformer) fed the
/// truth's own motion of its input nodes at the case's peak frame, without a cloud: the
/// network's error alone, apart from the surface fit's (the input nodes take the motion of the
/// truth's surface point nearest to them).
pub fn network_from_truth(case: &SyntheticCase, organ: &Organ, network: &NetworkDeformer) -> Result<Vec<f64>> {
    let peak = case.peak();
    let motion = case.truth_organ.surface_displacement_at(&peak.truth_u, network.input_points())?;
    let u = network.predict(&motion)?;
    let stencils = organ.locate(&case.targets, "target")?;
    let moved: Vec<Point> =
        register::organ::displaced(&case.targets, &stencils, &u).into_iter().map(|p| case.pose.apply(p)).collect();
    Ok(register::target_errors(&moved, &peak.truth))
}

/// The registration of a learned model on its scenario's organ, its loop's settings from
/// `options` (the case's settings for its learned models). A model with a basis (the reduced-order
/// model) fits its shape space on a frame from rest ([`ShapeDeformer`], with its own loop budgets)
/// and runs the match-and-membrane loop on a stream's warm-started frames ([`RestAndStream`]): on
/// the design case streamed (21 frames, 2 N) the shape fit alone left 5.52 mm at the peak and 3.55
/// mm over the frames, with the membrane loop on the stream 4.12 and 2.23 mm. The U-Net fits a
/// membrane to the matches and predicts from it ([`NetworkDeformer`]); given a `basis` (a
/// reduced-order model), it predicts from the shape fit of that model's shape space on a frame from
/// rest ([`HybridDeformer`], [`NETWORK_AFTER_FIT`]).
pub fn learned_registration(
    network: &Network,
    basis: Option<&Model>,
    options: &RegistrationOptions,
) -> Result<LearnedRegistration> {
    let (organ, membrane) = network_model(network)?;
    let (deformer, options): (Box<dyn Deformer + Send>, _) = match (network.model, basis) {
        (Model::Reduced(_), None) => {
            let fit = shape_fit(network.model, &organ)?;
            (Box::new(RestAndStream::new(Box::new(fit), Box::new(membrane))), shape::loop_options(options))
        }
        (Model::Reduced(_), Some(_)) => {
            bail!("a reduced-order model fits its own shape space: another model's basis is for a U-Net")
        }
        // One way from rest, both ways on a stream's frames: on the design cases streamed (21 frames
        // each), matching both ways brought the U-Net's TRE at the peak from 2.41 to 1.98 mm on
        // average (better on all 7 cases); from rest it changed little (2.48 → 2.42 mm, better on 3,
        // worse on 2).
        (Model::UNet(_), None) => {
            (Box::new(membrane), RegistrationOptions { two_way: TwoWay::Streamed, ..options.clone() })
        }
        (Model::UNet(_), Some(basis)) => {
            let fit = shape_fit(basis, &organ)?;
            let hybrid = HybridDeformer::new(Box::new(fit), Box::new(membrane), shape::SHAPE_ITERATIONS)?;
            let options = shape::loop_options(options);
            let iterations = shape::SHAPE_ITERATIONS + NETWORK_AFTER_FIT;
            (Box::new(hybrid), RegistrationOptions { iterations, ..options })
        }
    };
    Ok(LearnedRegistration { organ, deformer, options })
}

/// The shape fit of `model`'s shape space (a model with a basis) on `organ`, whose mesh must lie in
/// the model's grid, in the default settings.
pub fn shape_fit(model: &Model, organ: &Organ) -> Result<ShapeDeformer> {
    let shape = ShapeOptions::default();
    let space = register::model_shape_space(model, organ, shape.max_modes)?;
    Ok(ShapeDeformer::new(space, organ, shape)?)
}

/// The U-Net's iterations after the shape fit of a reduced-order model's basis, on a frame from
/// rest ([`learned_registration`]). On the design cases (the built-in case pressed at 1–2.5 N,
/// lifted, dragged and pulled), one and two gave 1.95 mm (two at 1.5× the time); the shape fit
/// alone 2.34 mm, the U-Net alone 2.48 mm, the reduced-order model's own membrane loop after the
/// fit 2.60 mm (one iteration) and 2.76 mm (two).
pub const NETWORK_AFTER_FIT: usize = 1;

/// The FEM's iterations after a learned model's in a hybrid registration from rest, by default
/// ([`MethodSpec::Hybrid`]). On the design cases (the built-in case pressed at 1–2.5 N, lifted,
/// dragged and pulled; from rest), 1, 2, 3 and 4 co-rotational iterations after the reduced-order
/// model's shape fit gave a mean TRE of 2.40, 2.38, 2.40 and 2.41 mm, the shape fit alone on the
/// FEM's mesh 2.73 mm (on the model's own quadratic mesh 2.34 mm), the FEM alone 2.94 mm.
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

/// [`network_model`] of `model` trained on [`ar_scenario`] (e.g. the shipped `models/liver_ar`).
pub fn ar_network_model(model: &Model) -> Result<(Organ, NetworkDeformer)> {
    network_model(&Network { model, scenario: &ar_scenario(), dir: Path::new("") })
}

/// The methods of `scenario`, in its order, each with the case's loop settings and its own
/// iteration budgets: its FEM methods ([`fem_scenario`]); its network method once per learned
/// model of `networks` (on its scenario's organ), named by the model's kind ("U-Net", "ROM"), a
/// reduced-order model twice: its match-and-membrane loop ("ROM, membrane loop") and its shape fit;
/// a U-Net twice when a reduced-order model is given too: alone, and predicting from that model's
/// shape fit ("U-Net after the ROM's shape fit"); its hybrid methods with the first reduced-order
/// model (its shape space holds on the FEM's mesh), else the first network. Network and hybrid
/// methods are left out without a learned model.
pub fn case_methods(scenario: &CaseScenario, networks: &[Network]) -> Result<Vec<Method>> {
    let mut out = Vec::new();
    let reduced = networks.iter().find(|n| matches!(n.model, Model::Reduced(_)));
    for spec in &scenario.models.method {
        let name = spec.name.clone();
        let options = with_budgets(&scenario.registration, spec.iterations, spec.warm_iterations, None);
        let fem = |material| ScenarioSource::Given {
            scenario: Box::new(fem_scenario(scenario, &name, material)),
            dir: PathBuf::new(),
        };
        match (spec.kind, spec.material, reduced.or(networks.first())) {
            (MethodKind::Fem, Some(material), _) => {
                out.push(Method { method: MethodSpec::Fem(fem(material)), name, options });
            }
            (MethodKind::Fem, None, _) => {
                bail!("method {name:?}: a FEM method needs a material")
            }
            (MethodKind::Network, _, Some(_)) => {
                for network in networks {
                    let name = network.model.method().display_name().to_string();
                    let (model, trained_on) = network.sources();
                    let learned = |way| MethodSpec::Learned { model: model.clone(), scenario: trained_on.clone(), way };
                    if matches!(network.model, Model::Reduced(_)) {
                        let name = format!("{name}, membrane loop");
                        out.push(Method { name, method: learned(LearnedWay::Membrane), options: options.clone() });
                    }
                    out.push(Method { name: name.clone(), method: learned(LearnedWay::Own), options: options.clone() });
                    if let (Model::UNet(_), Some(basis)) = (network.model, reduced) {
                        let way = LearnedWay::AfterShapeFit(basis.sources().0);
                        let name = format!("{name} after the {}'s shape fit", basis.model.method().display_name());
                        out.push(Method { name, method: learned(way), options: options.clone() });
                    }
                }
            }
            (MethodKind::Hybrid, Some(material), Some(network)) => {
                let (model, trained_on) = network.sources();
                let method = MethodSpec::Hybrid {
                    model,
                    scenario: trained_on,
                    fem: fem(material),
                    network_iterations: spec.network_iterations,
                };
                out.push(Method { name, method, options });
            }
            (MethodKind::Hybrid, None, _) => bail!("method {name:?}: a hybrid method needs a material"),
            (MethodKind::Network | MethodKind::Hybrid, _, None) => {}
        }
    }
    Ok(out)
}

/// The registration settings of `scenario`'s network method (its iteration budgets).
pub fn network_options(scenario: &CaseScenario) -> Result<RegistrationOptions> {
    let spec = scenario
        .models
        .method
        .iter()
        .find(|m| m.kind == MethodKind::Network)
        .context("the registration case has no network method")?;
    Ok(with_budgets(&scenario.registration, spec.iterations, spec.warm_iterations, None))
}

/// `options` with a method's own iteration budgets and points, where it has them.
fn with_budgets(
    options: &RegistrationOptions,
    iterations: Option<usize>,
    warm: Option<usize>,
    max_points: Option<usize>,
) -> RegistrationOptions {
    RegistrationOptions {
        iterations: iterations.unwrap_or(options.iterations),
        warm_iterations: warm.unwrap_or(options.warm_iterations),
        max_points: max_points.or(options.max_points),
        ..options.clone()
    }
}

/// A registration method of a comparison: its name, what deforms the organ and the loop's
/// settings; [`Method::spec`] sets it up at a case's targets.
#[derive(Clone, Debug)]
pub struct Method {
    /// Name in the table.
    pub name: String,
    /// What deforms the organ.
    pub method: MethodSpec,
    /// The loop's settings: the comparison's, with the method's own iteration budgets.
    pub options: RegistrationOptions,
}

impl Method {
    /// The method's registration of `targets` (rest positions, m).
    pub fn spec(&self, targets: &[Point]) -> RegistrationSpec {
        RegistrationSpec {
            options: Some(self.options.clone()),
            ..RegistrationSpec::new(self.method.clone(), TargetsSpec::Points(targets.to_vec()))
        }
    }
}

/// One method's registration of a comparison case.
pub struct Registered {
    /// Its figures.
    pub summary: Summary,
    /// Its registration of each frame of the case, in order.
    pub outcomes: Vec<FrameOutcome>,
    /// The organ it deformed.
    pub organ: Organ,
}

impl Registered {
    /// Its registration of the case's [`SyntheticCase::peak`] frame.
    pub fn peak(&self, case: &SyntheticCase) -> &FrameOutcome {
        &self.outcomes[case.peak_index()]
    }
}

/// One method's result in a comparison: its registration, or why it failed (e.g. an SVK
/// model pulled past its compressive limit point), which does not stop the other methods.
pub struct Compared {
    /// The method's name.
    pub method: String,
    /// Its registration, or its error.
    pub result: register::Result<Registered>,
}

/// Registers the case's clouds with each method at the case's targets, in order: each set up anew
/// ([`RegistrationSpec::build`]), the first frame from rest, each next one warm-started from the
/// previous one. A method that cannot be set up fails as one that fails to register does.
pub fn compare(case: &SyntheticCase, methods: &[Method]) -> Vec<Compared> {
    let truths = case.truths();
    let register = |m: &Method| -> register::Result<Registered> {
        let mut registration = m.spec(&case.targets).build().map_err(|e| RegisterError::Invalid(format!("{e:#}")))?;
        let frames = case.frames.iter().map(|f| Ok(f.cloud.clone()));
        let outcomes = registration.register_sequence(frames, Some(&truths), |_, _, _| Ok(()))?;
        let summary = Summary::new(m.name.clone(), &outcomes)?;
        Ok(Registered { summary, outcomes, organ: registration.into_organ() })
    };
    methods.iter().map(|m| Compared { method: m.name.clone(), result: register(m) }).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use fem::Law;

    /// The case's FEM of a method is the phantom of `models.tets` T4 (T10 for a quadratic
    /// material) with the method's material, fixed on the truth's fixed region, solved with the
    /// default solver; the built-in case's co-rotational one is the built-in `liver_corotational`.
    #[test]
    fn a_case_s_fem_is_the_phantom_of_the_method_s_material_fixed_on_the_truth_s_region() {
        let mut case = CaseScenario::builtin();
        case.models.tets = 400;
        case.truth.fixed = "visible".into();
        let quadratic = Material { order: 2, ..Material::new(Law::NeoHookean, 4500.0, 0.49) };
        for material in [Material::new(Law::Svk, 5000.0, 0.49), quadratic] {
            let scenario = fem_scenario(&case, "method", material);
            assert_eq!(scenario.solver, SolverOptions::default());
            let problem = scenario.build_problem(Path::new("")).unwrap();
            let mut expected = Problem::new(mesh::phantom::liver_phantom(400).unwrap(), material);
            let fixed = expected.mesh.region("visible").unwrap().to_vec();
            expected.fix(&fixed);
            assert_eq!(problem.mesh, expected.mesh);
            assert_eq!(problem.material, expected.material);
            assert!(!problem.dirichlet.is_empty() && problem.dirichlet == expected.dirichlet);
            assert_eq!((problem.springs, problem.f_ext), (expected.springs, expected.f_ext));
            assert!(problem.point_springs.is_empty());
        }
        let builtin = CaseScenario::builtin();
        let corotational = builtin
            .models
            .method
            .iter()
            .find(|m| m.material.is_some_and(|m| m.law == Law::Corotational))
            .expect("the built-in case has a co-rotational FEM");
        let ours = fem_scenario(&builtin, &corotational.name, corotational.material.unwrap());
        let shipped = StaticScenario::builtin("liver_corotational");
        assert_eq!(ours.solver, shipped.solver);
        let (ours, shipped) =
            (ours.build_problem(Path::new("")).unwrap(), shipped.build_problem(Path::new("")).unwrap());
        assert_eq!((ours.mesh, ours.material, ours.dirichlet), (shipped.mesh, shipped.material, shipped.dirichlet));
    }
}
