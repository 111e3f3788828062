//! A synthetic intraoperative case on the built-in phantom: the ground truth
//! comes from a finer mesh and another law than the registration model (no
//! inverse crime), the cloud from a camera looking at its deformed surface.
//! The case and its methods are described by a [`CaseScenario`]
//! (the built-in `register_case` scenario is the built-in one).

use std::path::{Path, PathBuf};

use fem::{Material, Problem, SolverOptions, StaticSolver};
use mesh::phantom::PhantomSpec;
use mesh::{NodeSelection, Point};

use learn::Model;

use anyhow::{anyhow, bail, Result};
use register::{FrameOutcome, NetworkDeformer, Organ, RegisterError, RegistrationOptions, RigidTransform, Summary};
use scenario::registration::{CameraSpec, MethodKind};
use scenario::{CaseScenario, DatasetScenario, Fixed, MeshSource, StaticScenario};

use crate::models::ScenarioSource;
use crate::models::{hybrid_options, network_model, Network};
use crate::registration::{LearnedWay, MethodSpec, RegistrationSpec, TargetsSpec};
use crate::simulate::simulate_cloud;

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
    /// (frame `k` from the camera's seed + `k`) and moved by the case's pose. Another view of a
    /// case costs no solve of its truth.
    pub fn seen_by(mut self, camera: &CameraSpec) -> Result<SyntheticCase> {
        for (k, frame) in self.frames.iter_mut().enumerate() {
            let surface = self.truth_organ.deformed_surface(&frame.truth_u);
            frame.cloud = simulate_cloud(&surface, &CameraSpec { seed: camera.seed + k as u64, ..*camera })?;
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
    SyntheticCase { frames, targets, pose, truth_organ: organ }.seen_by(camera)
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
        let options = method_options(scenario, spec);
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

/// The loop's settings of `scenario`'s method `spec`: the case's, with its kind's default
/// budgets (a network's [`NetworkDeformer::loop_options`], a hybrid's [`hybrid_options`]) unless
/// the method gives its own.
pub fn method_options(scenario: &CaseScenario, spec: &scenario::registration::CaseMethod) -> RegistrationOptions {
    let base = &scenario.registration;
    let kind = match (spec.kind, spec.network_iterations) {
        (MethodKind::Network, _) => NetworkDeformer::loop_options(base),
        (MethodKind::Hybrid, Some(network_iterations)) => hybrid_options(base, network_iterations),
        _ => base.clone(),
    };
    RegistrationOptions {
        iterations: spec.iterations.unwrap_or(kind.iterations),
        warm_iterations: spec.warm_iterations.unwrap_or(kind.warm_iterations),
        ..kind
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

    /// A method's budgets are its kind's unless it gives its own: a FEM the case's loop's, a
    /// network its real-time budget (as `register --model` gives it), a hybrid its learned
    /// iterations and the FEM's polish; a budget given beside the case holds for every method.
    #[test]
    fn a_method_s_budgets_are_its_kind_s_unless_it_gives_its_own() {
        let mut case = CaseScenario::builtin();
        let hybrid = scenario::registration::CaseMethod {
            name: "hybrid".into(),
            kind: MethodKind::Hybrid,
            material: Some(Material::new(Law::Corotational, 5000.0, 0.48)),
            iterations: None,
            warm_iterations: None,
            network_iterations: Some(7),
        };
        case.models.method.push(hybrid);
        let budgets = |case: &CaseScenario| -> Vec<(MethodKind, usize, usize)> {
            case.models
                .method
                .iter()
                .map(|m| (m.kind, method_options(case, m)))
                .map(|(k, o)| (k, o.iterations, o.warm_iterations))
                .collect()
        };
        let (base, network) = (&case.registration, NetworkDeformer::loop_options(&case.registration));
        let expected = [
            (MethodKind::Fem, base.iterations, base.warm_iterations),
            (MethodKind::Fem, base.iterations, base.warm_iterations),
            (MethodKind::Network, NetworkDeformer::ITERATIONS, NetworkDeformer::WARM_ITERATIONS),
            (MethodKind::Hybrid, 7 + crate::models::POLISH_ITERATIONS, base.warm_iterations),
        ];
        assert_eq!(budgets(&case), expected);
        assert_eq!((network.iterations, network.warm_iterations), (4, 2));
        let default_learned = NetworkDeformer::loop_options(&RegistrationOptions::default());
        let builtin_network = case.models.method.iter().find(|m| m.kind == MethodKind::Network).unwrap();
        assert_eq!(method_options(&CaseScenario::builtin(), builtin_network), default_learned);
        case.models.method[2].iterations = Some(9);
        case.models.method[2].warm_iterations = Some(3);
        assert_eq!(budgets(&case)[2], (MethodKind::Network, 9, 3));
        let overrides = scenario::registration::CaseOverrides { iterations: Some(12), ..Default::default() };
        let given = CaseScenario::with_overrides(None, &overrides).unwrap();
        assert!(budgets(&given).iter().all(|&(_, iterations, _)| iterations == 12), "{:?}", budgets(&given));
    }
}
