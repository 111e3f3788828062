//! Building an assimilation experiment (model, unknowns, measurements, assessment) and running the filter.

use std::path::{Path, PathBuf};
use std::time::Instant;

use fem::Problem;
use mesh::io::Field;
use mesh::length::{LengthUnit, UnitMistake};
use mesh::select::nearest;
use mesh::{Mesh, MeshLocator, Point, SurfaceBvh};
use nalgebra::DVector;
use serde::Serialize;

use super::report::{self, FilterTimes, Reference, Report};
use super::tracks::{write_tracks, RestPositions, Tracks};
use super::{AssimilationError, Context};

use filter::observation::{add_noise, tracked_positions};
use filter::{
    ControlPath, FemModel, FemModelError, FemParameter, LoadPattern, Model, ObservationNoise, ParameterSpec, Roukf,
    RoukfConfig, TrackedPoint, Transform,
};
use scenario::assimilation::{AssessmentSpec, ObservationSpec};
use scenario::{build_mesh, AssimilationScenario};

/// Track files that replace the synthetic observations (formats in [`super::tracks`]).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ObservationFiles {
    /// Observed features (`frame,id,x,y,z`); frame k > 0 is the measurement of filter step k.
    pub observations: PathBuf,
    /// Rest positions (`id,x,y,z`) of the features of all track files; default: their frame-0 rows.
    pub features: Option<PathBuf>,
    /// Tool features (`frame,id,x,y,z`): each one's displacement from rest is prescribed on the nearest surface
    /// node that is not constrained otherwise; an occluded tool keeps its last displacement.
    pub controls: Option<PathBuf>,
    /// Assessment points (`frame,id,x,y,z`): where the estimated deformation is compared with the tracks.
    pub assessment: Option<PathBuf>,
    /// The scenario's parameter values are the truth behind the tracks (e.g. tracks written by a synthetic run on
    /// another mesh): the report gives the errors against them.
    pub known_truth: bool,
    /// The unit of the files whose header names none (`x,y,z` rather than `x_mm,y_mm,z_mm`).
    pub units: LengthUnit,
}

/// Most iterations of synthetic observations: each is a FEM solve of the reference.
pub const MAX_SYNTHETIC_ITERATIONS: usize = 100_000;

/// Summary of a prepared experiment.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Setup {
    /// Mesh nodes.
    pub nodes: usize,
    /// Mesh cells.
    pub cells: usize,
    /// Kind of the cells.
    pub cell_kind: &'static str,
    /// Fixed, tool and control nodes.
    pub constrained_nodes: usize,
    /// Nodes moved by the scenario's `[[tool]]`.
    pub tool_nodes: usize,
    /// Nodes moved by tracked tool features (`controls`).
    pub control_nodes: usize,
    /// Observed feature points.
    pub features: usize,
    /// Assessment points.
    pub assessment_points: usize,
    /// Estimated parameters.
    pub parameters: usize,
    /// Sigma points of the filter (p + 1 simplex or 2p + 1 star).
    pub sigma_points: usize,
    /// Filter iterations (time steps).
    pub iterations: usize,
    /// Feature observations missing (occluded) in the filtered frames.
    pub occluded: usize,
    /// Filtered frames in which no feature is seen (the filter only predicts there).
    pub blind_frames: usize,
    /// Features whose rest position lies deeper below the mesh's surface than an element (id,
    /// depth in m): a camera tracks the surface.
    pub deep_features: Vec<(String, f64)>,
    /// With a features file: the observed features whose frame-0 row (not read) lies more than
    /// the observation noise from the rest position the file gives, with the largest distance (m).
    pub rest_disagreement: Option<(usize, f64)>,
    /// Tracked points (features, assessment) outside the mesh moved onto its surface.
    pub projected: usize,
    /// The largest such move (m).
    pub max_projection: f64,
    /// The reference run (synthetic observations only).
    pub reference: Option<Reference>,
}

/// One measurement: stacked positions (x, y, z per point) and which components were measured.
#[derive(Debug, Clone)]
struct Frame {
    z: DVector<f64>,
    available: Vec<bool>,
}

impl Frame {
    fn complete(z: DVector<f64>) -> Self {
        let available = vec![true; z.len()];
        Frame { z, available }
    }
}

/// What the filter estimates, in filter order, and how it maps to the model.
#[derive(Debug, Clone)]
struct Unknowns {
    specs: Vec<ParameterSpec>,
    parameters: Vec<FemParameter>,
    /// The scenario's values in physical units (Pa, N/m): the truth of a synthetic run.
    truth: Vec<f64>,
    /// Nodes of Σ (one spring parameter each, after the modulus if estimated).
    springs: Option<Vec<usize>>,
}

/// Points where the estimated deformation is assessed and their true positions at steps 1, 2, ….
#[derive(Debug, Clone)]
struct Assessment {
    points: Vec<TrackedPoint>,
    truth: Vec<Frame>,
}

/// A track file to write: name, feature ids, frames from 0.
type TrackOutput = (&'static str, Vec<String>, Vec<DVector<f64>>);

/// The tracks an experiment reads: observed features, their rest positions (default: frame 0), tool features and
/// assessment points.
struct TrackSet {
    observations: Tracks,
    rest: Option<RestPositions>,
    controls: Option<Tracks>,
    assessment: Option<Tracks>,
}

/// A prepared assimilation experiment (see the module documentation).
pub struct Experiment {
    scenario: AssimilationScenario,
    start: Instant,
    base: Problem,
    loads: Vec<LoadPattern>,
    controls: Vec<ControlPath>,
    unknowns: Unknowns,
    observed: Vec<TrackedPoint>,
    /// The observed features' names (a track file's ids; `f0`, `f1`… when synthetic).
    observed_ids: Vec<String>,
    measurements: Vec<Frame>,
    filter_std: f64,
    every: usize,
    assessment: Option<Assessment>,
    synthetic_tracks: Vec<TrackOutput>,
    /// The scenario's values are the truth (synthetic observations, or [`ObservationFiles::known_truth`]).
    known_truth: bool,
    setup: Setup,
}

impl Experiment {
    /// Builds the model and the measurements of `scenario` (relative paths from `dir`): synthetic from a reference
    /// run when `files` is `None`, else read from the track files. Synthetic data need `iterations`; with files,
    /// the frames 1..=last are filtered, or the first `iterations` of them when it is set (an error when the
    /// file has fewer).
    pub fn prepare(
        scenario: AssimilationScenario,
        dir: &Path,
        files: Option<&ObservationFiles>,
    ) -> Result<Self, AssimilationError> {
        let start = Instant::now();
        let sc = &scenario;
        let setup_error = |m: String| Err(AssimilationError::Setup(m));
        if sc.young.is_none() && sc.springs.is_none() {
            return setup_error("nothing to estimate: add [young] or [springs]".into());
        }
        let obs = &sc.observations;
        if !(obs.noise_std.is_finite() && obs.noise_std >= 0.0) {
            return setup_error(format!("observations.noise_std must be finite and ≥ 0, got {}", obs.noise_std));
        }
        let filter_std = obs.filter_std.unwrap_or(obs.noise_std);
        if !(filter_std.is_finite() && filter_std > 0.0) {
            return setup_error(
                "the filter needs an observation std > 0: set observations.noise_std or observations.filter_std".into(),
            );
        }
        let every = sc.output.every.unwrap_or(1);
        if every == 0 {
            return setup_error("output.every must be at least 1".into());
        }
        let compare = sc.springs.as_ref().is_some_and(|s| s.compare);
        let has_assessment = match files {
            None => sc.assessment.is_some(),
            Some(f) => f.assessment.is_some(),
        };
        if compare && !has_assessment {
            return setup_error(match files {
                None => "springs.compare needs [assessment] points".into(),
                Some(_) => "springs.compare needs assessment points: give an assessment track file".into(),
            });
        }

        let mesh = build_mesh(&sc.mesh, dir).context(|| "building the mesh".into())?;
        let (problem, loads, tool_nodes) =
            sc.build_problem(mesh).map_err(|e| AssimilationError::Setup(e.to_string()))?;
        let locator = MeshLocator::new(&problem.mesh).context(|| "indexing the mesh for point location".into())?;
        check_noise_scale(obs, mesh::box_diagonal(problem.mesh.bounds()))?;
        let unknowns = unknowns(sc, &problem.mesh)?;

        let setup = Setup {
            nodes: problem.mesh.num_nodes(),
            cells: problem.mesh.cells.len(),
            cell_kind: problem.mesh.cells.kind_name(),
            constrained_nodes: 0,
            tool_nodes: tool_nodes.len(),
            control_nodes: 0,
            features: 0,
            assessment_points: 0,
            parameters: 0,
            sigma_points: 0,
            iterations: 0,
            occluded: 0,
            blind_frames: 0,
            deep_features: Vec::new(),
            rest_disagreement: None,
            projected: 0,
            max_projection: 0.0,
            reference: None,
        };
        let mut experiment = Experiment {
            scenario,
            start,
            base: problem,
            loads,
            controls: Vec::new(),
            unknowns,
            observed: Vec::new(),
            observed_ids: Vec::new(),
            measurements: Vec::new(),
            filter_std,
            every,
            assessment: None,
            synthetic_tracks: Vec::new(),
            known_truth: files.is_some_and(|f| f.known_truth),
            setup,
        };
        match (files, experiment.scenario.reference_scenario()) {
            (Some(f), reference) => {
                experiment.read_files(&locator, f)?;
                // Tracks of the reference run, its values the truth: carried to this mesh.
                if let Some(reference) = reference.filter(|_| f.known_truth) {
                    experiment.carry_reference_spring_truth(&reference, dir)?;
                }
            }
            (None, Some(reference)) => experiment.observe_reference(&locator, reference, dir)?,
            (None, None) => experiment.synthesise(&locator, &tool_nodes)?,
        }
        let s = &mut experiment.setup;
        s.constrained_nodes = experiment.base.dirichlet.len();
        s.control_nodes = experiment.controls.len();
        s.features = experiment.observed.len();
        s.assessment_points = experiment.assessment.as_ref().map_or(0, |a| a.points.len());
        s.parameters = experiment.unknowns.specs.len();
        s.sigma_points = experiment.scenario.filter.sigma_points.count(s.parameters);
        s.iterations = experiment.measurements.len();
        s.occluded = experiment.measurements.iter().map(|f| f.available.iter().filter(|a| !**a).count() / 3).sum();
        s.blind_frames = experiment.measurements.iter().filter(|f| !f.available.iter().any(|&a| a)).count();
        Ok(experiment)
    }

    /// Summary of the prepared experiment.
    pub fn setup(&self) -> &Setup {
        &self.setup
    }

    /// Synthetic data: feature points on the visible surface, assessment nodes, a reference run with the true
    /// parameters, noisy measurements; the tracks are kept for writing.
    fn synthesise(&mut self, locator: &MeshLocator, tool_nodes: &[usize]) -> Result<(), AssimilationError> {
        let sc = &self.scenario;
        let iterations = match sc.iterations {
            Some(n) if (1..=MAX_SYNTHETIC_ITERATIONS).contains(&n) => n,
            _ => {
                return Err(AssimilationError::Setup(format!(
                    "iterations must be 1 to {MAX_SYNTHETIC_ITERATIONS} for synthetic observations (a FEM solve \
                     each), got {}",
                    sc.iterations.unwrap_or(0)
                )))
            }
        };
        let (observed, rest) = feature_points(&self.base, locator, &sc.observations)?;
        let observed_nodes: Vec<usize> = observed.iter().flat_map(|t| t.terms().map(|(n, _)| n)).collect();
        let assessment = match &sc.assessment {
            Some(a) => assessment_points(&self.base, a, &observed_nodes)?,
            None => Vec::new(),
        };
        self.observed_ids = (0..observed.len()).map(|j| format!("f{j}")).collect();
        self.observed = observed;
        let nodes = self.base.mesh.nodes.clone();
        let model = self.model(self.base.clone(), self.unknowns.parameters.clone())?;
        let t0 = Instant::now();
        let mut clean = Vec::with_capacity(iterations);
        let mut truth = vec![tracked_positions(&nodes, &assessment, &vec![0.0; 3 * nodes.len()])];
        let tool_rest = DVector::from_iterator(3 * tool_nodes.len(), tool_nodes.iter().flat_map(|&k| nodes[k]));
        let mut tool = vec![tool_rest.clone()];
        let mut max_displacement: f64 = 0.0;
        model
            .simulate(&self.unknowns.truth, iterations, |_, s| {
                clean.push(model.observe(s));
                truth.push(tracked_positions(&nodes, &assessment, &s.u));
                let at = |k: usize, d: usize| nodes[k][d] + s.u[3 * k + d];
                tool.push(DVector::from_iterator(
                    3 * tool_nodes.len(),
                    tool_nodes.iter().flat_map(|&k| (0..3).map(move |d| at(k, d))),
                ));
                max_displacement = max_displacement.max(fem::post::max_displacement(&s.u));
            })
            .context(|| "reference simulation with the true parameters".into())?;
        self.setup.reference = Some(Reference {
            inverse_crime: true,
            nodes: nodes.len(),
            cells: self.base.mesh.cells.len(),
            law: self.base.material.law,
            seconds: t0.elapsed().as_secs_f64(),
            max_displacement,
        });
        let obs = &sc.observations;
        let measurements = add_noise(&clean, obs.noise_std, obs.seed).context(|| "observation noise".into())?;

        let ids = |prefix: &str, n: usize| (0..n).map(|j| format!("{prefix}{j}")).collect::<Vec<_>>();
        let mut observed_frames = vec![DVector::from_iterator(3 * rest.len(), rest.iter().flatten().copied())];
        observed_frames.extend(measurements.iter().cloned());
        self.synthetic_tracks.push(("observations.csv", ids("f", rest.len()), observed_frames));
        if !assessment.is_empty() {
            self.synthetic_tracks.push(("assessment.csv", ids("a", assessment.len()), truth.clone()));
            self.assessment = Some(Assessment {
                points: assessment,
                truth: truth.into_iter().skip(1).map(Frame::complete).collect(),
            });
        }
        if !tool_nodes.is_empty() {
            self.synthetic_tracks.push(("controls.csv", ids("c", tool_nodes.len()), tool));
        }
        self.measurements = measurements.into_iter().map(Frame::complete).collect();
        Ok(())
    }

    /// Measurements, controls and assessment points from track files; control nodes are constrained in the base
    /// problem.
    fn read_files(&mut self, locator: &MeshLocator, files: &ObservationFiles) -> Result<(), AssimilationError> {
        let units = files.units;
        let read = |path: &Option<PathBuf>| path.as_deref().map(|p| Tracks::read(p, units)).transpose();
        let tracks = TrackSet {
            rest: files.features.as_deref().map(|p| RestPositions::read(p, units)).transpose()?,
            observations: Tracks::read(&files.observations, units)?,
            controls: read(&files.controls)?,
            assessment: read(&files.assessment)?,
        };
        self.use_tracks(locator, &tracks)
    }

    /// Takes as the springs' truth those of the `reference` scenario (its mesh built, not run), carried to this
    /// model's mesh: tracks of that reference read from files.
    fn carry_reference_spring_truth(
        &mut self,
        reference: &AssimilationScenario,
        dir: &Path,
    ) -> Result<(), AssimilationError> {
        if self.unknowns.springs.is_none() {
            return Ok(());
        }
        let mesh = build_mesh(&reference.mesh, dir).context(|| "building the reference mesh".into())?;
        let (problem, ..) = reference.build_problem(mesh).map_err(|e| AssimilationError::Setup(e.to_string()))?;
        let springs = unknowns(reference, &problem.mesh)?;
        self.carry_spring_truth(&problem.mesh, &springs);
        Ok(())
    }

    /// Takes as the springs' truth those of a reference run on `mesh` (its `unknowns`), carried to this model's
    /// mesh ([`equivalent_springs`]).
    fn carry_spring_truth(&mut self, mesh: &Mesh, unknowns: &Unknowns) {
        if let (Some(model), Some(springs)) = (&self.unknowns.springs, &unknowns.springs) {
            let truth = &unknowns.truth[unknowns.truth.len() - springs.len()..];
            let equivalent = equivalent_springs((mesh, springs, truth), (&self.base.mesh, model));
            let first = self.unknowns.truth.len() - model.len();
            self.unknowns.truth[first..].copy_from_slice(&equivalent);
        }
    }

    /// Synthetic observations of a reference run on another mesh (and law), `scenario`: its tracks are located on
    /// this model's mesh like track files (its tool acts on this model through the scenario's own `[[tool]]`, so
    /// its tool tracks are not used as controls) and kept for writing; its parameters are the truth.
    fn observe_reference(
        &mut self,
        locator: &MeshLocator,
        scenario: AssimilationScenario,
        dir: &Path,
    ) -> Result<(), AssimilationError> {
        let reference = Experiment::prepare(scenario, dir, None)?;
        let label = |file: &str| PathBuf::from(format!("the reference run's {file}"));
        let track = |file: &str| {
            reference
                .synthetic_tracks
                .iter()
                .find(|t| t.0 == file)
                .map(|(_, ids, frames)| Tracks::from_frames(label(file), ids, frames))
        };
        let tracks = TrackSet {
            rest: None,
            observations: track("observations.csv").expect("a synthetic run tracks its features"),
            controls: None,
            assessment: track("assessment.csv"),
        };
        self.use_tracks(locator, &tracks)?;
        self.known_truth = true;
        self.carry_spring_truth(&reference.base.mesh, &reference.unknowns);
        let run = reference.setup.reference.expect("a synthetic run records its reference run");
        self.setup.reference = Some(Reference { inverse_crime: false, ..run });
        self.synthetic_tracks = reference.synthetic_tracks;
        Ok(())
    }

    /// Measurements, controls and assessment points from tracks; control nodes are constrained in the base problem.
    fn use_tracks(&mut self, locator: &MeshLocator, tracks: &TrackSet) -> Result<(), AssimilationError> {
        let rest = tracks.rest.as_ref();
        let last = tracks.observations.last_frame();
        let path = &tracks.observations.path;
        if last == 0 {
            return Err(AssimilationError::file(path, None, "no frame after frame 0 (the rest)".into()));
        }
        let iterations = match self.scenario.iterations {
            Some(0) => return Err(AssimilationError::Setup("iterations must be at least 1 (one per frame)".into())),
            Some(n) if n > last => {
                let why = format!("{n} iterations asked for, but the file's last frame is {last} (one per iteration)");
                return Err(AssimilationError::file(path, None, why));
            }
            Some(n) => n,
            None => last,
        };
        let mut finder = PointFinder::new(&self.base.mesh, locator)?;
        // Each file's rest positions, once: located, then checked against the file's motion.
        let mut at_rest = Vec::new();
        let observed_rest = tracks.observations.rest_positions(rest)?;
        if rest.is_some() {
            let apart: Vec<f64> = (0..observed_rest.len())
                .filter_map(|j| Some(mesh::distance(tracks.observations.position(j, 0)?, observed_rest[j])))
                .filter(|&d| d > self.filter_std)
                .collect();
            self.setup.rest_disagreement =
                (!apart.is_empty()).then(|| (apart.len(), apart.iter().copied().fold(0.0, f64::max)));
        }
        self.observed = locate_tracks(&tracks.observations, &observed_rest, rest, &mut finder)?;
        self.observed_ids = tracks.observations.ids.clone();
        // A camera sees the surface: a feature deep inside is another organ's, or a wrong position.
        let depths =
            tracks.observations.ids.iter().zip(&observed_rest).map(|(id, p)| (id, -finder.surface.signed_distance(*p)));
        self.setup.deep_features =
            depths.filter(|(_, d)| *d > 2.0 * finder.reach).map(|(id, d)| (id.clone(), d)).collect();
        at_rest.push((&tracks.observations, observed_rest));
        self.measurements = (1..=iterations)
            .map(|k| tracks.observations.frame(k))
            .map(|(z, available)| Frame { z, available })
            .collect();
        if let Some(controls) = &tracks.controls {
            if self.setup.tool_nodes > 0 {
                let why = format!(
                    "these track the tool, which the scenario's [[tool]] also moves ({} nodes): remove [[tool]] from \
                     the scenario to follow the tracked one",
                    self.setup.tool_nodes
                );
                return Err(AssimilationError::file(&controls.path, None, why));
            }
            let control_rest = controls.rest_positions(rest)?;
            self.controls = control_paths(&mut self.base, controls, &control_rest, iterations)?;
            at_rest.push((controls, control_rest));
        }
        if let Some(assessment) = &tracks.assessment {
            let assessment_rest = assessment.rest_positions(rest)?;
            let points = locate_tracks(assessment, &assessment_rest, rest, &mut finder)?;
            at_rest.push((assessment, assessment_rest));
            let truth =
                (1..=iterations).map(|k| assessment.frame(k)).map(|(z, available)| Frame { z, available }).collect();
            self.assessment = Some(Assessment { points, truth });
        }
        // Located at rest first: a bad rest position is named before the motion it would seem to make.
        let size = self.organ_size();
        for (t, positions) in &at_rest {
            t.check_motion(positions, size, iterations, rest)?;
        }
        self.setup.projected = finder.moved.len();
        self.setup.max_projection = finder.moved.iter().copied().fold(0.0, f64::max);
        Ok(())
    }

    /// The FEM model of `problem` with these parameters, the scenario's loads, the controls and the observed points.
    fn model(&self, problem: Problem, parameters: Vec<FemParameter>) -> Result<FemModel, AssimilationError> {
        FemModel::new(problem, parameters, self.loads.clone(), self.observed.clone(), self.scenario.solver.clone())
            .and_then(|m| m.with_controls(self.controls.clone()))
            .context(|| "building the FEM model".into())
    }

    /// The filter at its prior, over the FEM model, configured as the scenario says: step it with
    /// the measurements of [`observations`](Self::observations) (or others of the same points).
    pub fn filter(&self) -> Result<Roukf<FemModel>, AssimilationError> {
        let config = RoukfConfig {
            parameters: self.unknowns.specs.clone(),
            observation_std: ObservationNoise::Uniform(self.filter_std),
            execution: self.scenario.filter.execution,
            forgetting: self.scenario.filter.forgetting,
            sigma_points: self.scenario.filter.sigma_points,
            gate: self.scenario.filter.gate,
        };
        let model = self.model(self.base.clone(), self.unknowns.parameters.clone())?;
        let initial = model.initial_state();
        let filter = &self.scenario.filter;
        Roukf::new(model, initial, config)
            .and_then(|f| f.with_discrepancy(filter.discrepancy, filter.discrepancy_dof))
            .context(|| "configuring the filter".into())
    }

    /// The measurements of steps 1, 2, …: the observed points' positions stacked (x, y, z per
    /// point, m), and which components were measured.
    pub fn observations(&self) -> impl Iterator<Item = (&DVector<f64>, &[bool])> {
        self.measurements.iter().map(|f| (&f.z, f.available.as_slice()))
    }

    /// Rest positions of the observed points, in the order of the measurements.
    pub fn observed_points(&self) -> Vec<Point> {
        let rest = vec![0.0; self.base.num_dofs()];
        self.observed.iter().map(|t| t.position(&self.base.mesh.nodes, &rest)).collect()
    }

    /// The farthest any observed feature lies from its rest position in a frame that measures it (m).
    fn largest_feature_motion(&self) -> f64 {
        let rest = self.observed_points();
        let moved = |f: &Frame| -> f64 {
            let away = |(i, p): (usize, &Point)| (0..3).map(|c| (f.z[3 * i + c] - p[c]).powi(2)).sum::<f64>().sqrt();
            rest.iter().enumerate().filter(|&(i, _)| f.available[3 * i]).map(away).fold(0.0, f64::max)
        };
        self.measurements.iter().map(moved).fold(0.0, f64::max)
    }

    /// The organ's size: its mesh's box diagonal (m). No feature moves farther than that.
    pub fn organ_size(&self) -> f64 {
        mesh::box_diagonal(self.base.mesh.bounds())
    }

    /// The scenario's values of the estimated parameters, in filter order (the truth of
    /// synthetic observations).
    pub fn scenario_values(&self) -> &[f64] {
        &self.unknowns.truth
    }

    /// Writes the synthetic observations into `dir` (`observations.csv`, and `assessment.csv` and `controls.csv`
    /// when there are such points): track files another experiment can read, e.g. on another mesh. Nothing is
    /// written for observations read from files.
    pub fn write_tracks(&self, dir: &Path) -> Result<(), AssimilationError> {
        for (file, ids, frames) in &self.synthetic_tracks {
            write_tracks(&dir.join(file), ids, frames)?;
        }
        Ok(())
    }

    /// Runs the filter and writes the outputs into `out_dir` (see the module documentation); reports
    /// every iteration to `progress`, with the current estimate in words (e.g.
    /// `E = 4979.1 ± 4.2 Pa, |innovation| = 1.2e-3 m`).
    pub fn run(&self, out_dir: &Path, progress: &dyn learn::Progress) -> Result<Report, AssimilationError> {
        mesh::io::create_folder(out_dir).context(|| "creating the output folder".into())?;
        self.write_tracks(&out_dir.join("tracks"))?;
        let iterations = self.measurements.len();
        let nodes = &self.base.mesh.nodes;
        let comparisons = self.comparisons()?;

        let mut roukf = self.filter()?;
        let mut estimated_errors = Vec::with_capacity(iterations);
        let mut newton = 0usize;
        let mut spent = FilterTimes::default();
        let mut factorizations = 0usize;
        let mut frames = Vec::new();
        let t_filter = Instant::now();
        for (k, frame) in (1..).zip(&self.measurements) {
            let rec = roukf.step_partial(&frame.z, &frame.available).context(|| format!("filter iteration {k}"))?;
            let innovation = rec.innovation_norm;
            let states = roukf.sigma_states();
            newton += states.iter().map(|s| s.newton_iterations).sum::<usize>();
            for s in states {
                factorizations += s.factorizations;
                spent.solves += s.timings.total.as_secs_f64();
                spent.assembly += s.timings.assembly.as_secs_f64();
                spent.factorization += s.timings.factorization.as_secs_f64();
                spent.triangular_solves += s.timings.solve.as_secs_f64();
            }
            let mut mean = vec![0.0; self.base.num_dofs()];
            for (s, w) in states.iter().zip(roukf.sigma_points().weights()) {
                for (m, u) in mean.iter_mut().zip(&s.u) {
                    *m += w * u;
                }
            }
            if let Some(a) = &self.assessment {
                estimated_errors.push(mean_error(&tracked_positions(nodes, &a.points, &mean), &a.truth[k - 1]));
            }
            // Every `every` steps, and the last (the final estimate's deformation).
            if k % self.every == 0 || k == iterations {
                let t_write = Instant::now();
                let file = format!("deformation/step_{k:05}.vtu");
                mesh::io::write_vtu(out_dir.join(&file), &self.base.mesh, &[Field::point("displacement", 3, mean)])
                    .context(|| format!("writing the estimated deformation of step {k}"))?;
                frames.push((k as f64, file));
                spent.writing += t_write.elapsed().as_secs_f64();
            }
            let note = self.progress_message(&roukf.mean_physical(), &roukf.std_physical(), innovation);
            progress.advance(k as u64, iterations as u64, &note);
        }
        let filter_seconds = t_filter.elapsed().as_secs_f64();
        let sigma_count = roukf.sigma_points().count();
        spent.factorizations_per_solve = factorizations as f64 / (iterations * sigma_count).max(1) as f64;
        if !frames.is_empty() {
            mesh::io::write_pvd(out_dir.join("deformation.pvd"), &frames)
                .context(|| "writing deformation.pvd".into())?;
        }

        let trace = roukf.trace();
        trace.write_csv(&out_dir.join("trace.csv")).context(|| "writing the trace".into())?;
        trace.write_json(&out_dir.join("trace.json")).context(|| "writing the trace".into())?;
        // The truth is known for synthetic observations (a reference run) and for track files said
        // to come from the scenario's values (--known-truth); only the former are synthetic.
        let synthetic = self.setup.reference.is_some();
        let truth_known = synthetic || self.known_truth;
        let offset = usize::from(self.scenario.young.is_some());
        let young = match self.scenario.young {
            Some(_) => Some(report::young(trace, truth_known.then_some(self.unknowns.truth[0]), out_dir)?),
            None => None,
        };
        let springs = match &self.unknowns.springs {
            Some(nodes) => {
                let truth = truth_known.then(|| &self.unknowns.truth[offset..]);
                Some(report::springs(trace, nodes, truth, offset, out_dir)?)
            }
            None => None,
        };
        report::innovation(trace, out_dir)?;
        let mut assessment = Vec::new();
        if let Some(a) = &self.assessment {
            let mut cases = vec![("estimated", estimated_errors)];
            cases.extend(comparisons);
            assessment = report::assessment(&cases, a.points.len(), out_dir)?;
        }
        let mut times: Vec<f64> = trace.records.iter().filter_map(|r| r.wall_seconds).collect();
        let report = Report {
            scenario: self.scenario.name.clone(),
            synthetic,
            nodes: nodes.len(),
            iterations,
            sigma_points: sigma_count,
            sigma_point_set: self.scenario.filter.sigma_points,
            execution: self.scenario.filter.execution,
            filter_seconds,
            seconds_per_iteration_mean: times.iter().sum::<f64>() / times.len().max(1) as f64,
            seconds_per_iteration_median: mesh::stats::median(&mut times),
            newton_iterations_per_solve: newton as f64 / (iterations * sigma_count).max(1) as f64,
            filter_times: spent,
            total_seconds: self.start.elapsed().as_secs_f64(),
            reference: self.setup.reference,
            young,
            springs,
            assessment,
            deformation_frames: frames.len(),
            observation_std: self.filter_std,
            largest_feature_motion: self.largest_feature_motion(),
            measured_components: self.measurements.iter().map(|f| f.available.iter().filter(|&&a| a).count()).sum(),
            gated_components: trace.records.iter().map(|r| r.gated).sum(),
            gated_features: gated_features(trace, &self.observed_ids),
            gated_steps: trace.records.iter().filter(|r| r.gated > 0).count(),
        };
        report.write_json(&out_dir.join(crate::output::SUMMARY_FILE))?;
        Ok(report)
    }

    /// With `springs.compare`: the assessment errors over time with Σ fully fixed and fully free.
    fn comparisons(&self) -> Result<Vec<(&'static str, Vec<f64>)>, AssimilationError> {
        let (Some(nodes), Some(a), true) =
            (&self.unknowns.springs, &self.assessment, self.scenario.springs.as_ref().is_some_and(|s| s.compare))
        else {
            return Ok(Vec::new());
        };
        let young: Vec<FemParameter> = self.scenario.young.iter().map(|_| FemParameter::Young).collect();
        let theta = &self.unknowns.truth[..young.len()];
        let mut fixed = self.base.clone();
        fixed.fix(nodes);
        let mut out = Vec::new();
        for (label, p) in [("fixed", fixed), ("free", self.base.clone())] {
            let m = self.model(p, young.clone())?;
            let mut errors = Vec::with_capacity(a.truth.len());
            m.simulate(theta, a.truth.len(), |k, s| {
                errors.push(mean_error(&tracked_positions(&self.base.mesh.nodes, &a.points, &s.u), &a.truth[k - 1]));
            })
            .context(|| format!("comparison run with Σ {label}"))?;
            out.push((label, errors));
        }
        Ok(out)
    }

    fn progress_message(&self, mu: &[f64], sd: &[f64], innovation: Option<f64>) -> String {
        let innovation = match innovation {
            Some(norm) => format!("|innovation| = {norm:.2e} m"),
            None => "no feature seen".to_string(),
        };
        match (&self.unknowns.springs, self.unknowns.parameters.first()) {
            (_, Some(FemParameter::Young)) => format!("E = {:.1} ± {:.1} Pa, {innovation}", mu[0], sd[0]),
            (Some(_), _) => {
                let mean = mu.iter().sum::<f64>() / mu.len() as f64;
                format!("mean k = {mean:.1} N/m, {innovation}")
            }
            _ => innovation,
        }
    }
}

/// Refuses an observation noise (`noise_std`, `filter_std`, m) over a tenth of the organ's size
/// (`size`, m): no camera tracks so badly; such a noise is one given in mm.
fn check_noise_scale(obs: &ObservationSpec, size: f64) -> Result<(), AssimilationError> {
    for (key, std) in [("noise_std", Some(obs.noise_std)), ("filter_std", obs.filter_std)] {
        if let Some(std) = std.filter(|&std| std > 0.1 * size) {
            return Err(AssimilationError::Setup(format!(
                "observations.{key} = {std} m is {:.0} % of the organ's size ({:.0} mm): a tracking noise is in \
                 metres (0.2 mm is 0.0002)",
                100.0 * std / size,
                mesh::length::mm(size)
            )));
        }
    }
    Ok(())
}

/// The filter's parameters, in order: Young's modulus (if estimated), then one spring per node of Σ.
fn unknowns(sc: &AssimilationScenario, mesh: &Mesh) -> Result<Unknowns, AssimilationError> {
    let mut u = Unknowns { specs: Vec::new(), parameters: Vec::new(), truth: Vec::new(), springs: None };
    if let Some(y) = &sc.young {
        let modulus = y.transform.to_physical(y.prior_mean);
        if !(modulus.is_finite() && modulus > 0.0) {
            let ln = if y.transform == Transform::Exp { " (under transform = \"exp\" it is ln E)" } else { "" };
            return Err(AssimilationError::Setup(format!(
                "[young] prior_mean = {} gives a Young's modulus of {modulus} Pa{ln}: the prior's mean must give a \
                 positive, finite modulus",
                y.prior_mean
            )));
        }
        u.specs.push(ParameterSpec::new("young", y.transform, y.prior_mean, y.prior_std));
        u.parameters.push(FemParameter::Young);
        u.truth.push(sc.material.young);
    }
    if let Some(s) = &sc.springs {
        if !(s.scale.is_finite() && s.scale > 0.0) {
            return Err(AssimilationError::Setup(format!("springs.scale must be finite and > 0, got {}", s.scale)));
        }
        let nodes = s.select.select(mesh).context(|| "springs selection".into())?;
        let mut truth = vec![0.0; nodes.len()];
        for t in &s.truth {
            if !(t.value.is_finite() && t.value >= 0.0) {
                return Err(AssimilationError::Setup(format!(
                    "spring truth values must be finite and ≥ 0, got {}",
                    t.value
                )));
            }
            let picked = t.select.select(mesh).context(|| "springs.truth selection".into())?;
            let mut hit = false;
            for (j, k) in nodes.iter().enumerate() {
                if picked.binary_search(k).is_ok() {
                    truth[j] = t.value;
                    hit = true;
                }
            }
            if !hit {
                return Err(AssimilationError::Setup(format!(
                    "springs.truth selection {} picks no node of the springs region",
                    t.select
                )));
            }
        }
        for (j, &k) in nodes.iter().enumerate() {
            u.specs.push(ParameterSpec::new(format!("k_{k}"), s.transform, s.prior_mean, s.prior_std).scaled(s.scale));
            u.parameters.push(FemParameter::Springs { nodes: vec![k] });
            u.truth.push(s.scale * truth[j]);
        }
        u.springs = Some(nodes);
    }
    Ok(u)
}

/// The features the validation gate left out of a step, each with the number of such steps, most often first.
fn gated_features(trace: &filter::Trace, ids: &[String]) -> Vec<(String, usize)> {
    let mut steps = vec![0; ids.len()];
    for record in &trace.records {
        let mut features: Vec<usize> = record.gated_components.iter().map(|c| c / 3).collect();
        features.dedup();
        features.iter().filter(|&&j| j < ids.len()).for_each(|&j| steps[j] += 1);
    }
    let mut gated: Vec<(String, usize)> = ids.iter().cloned().zip(steps).filter(|(_, n)| *n > 0).collect();
    gated.sort_by_key(|(_, n)| std::cmp::Reverse(*n));
    gated
}

/// The springs on `model`'s nodes equivalent to the `reference` mesh's (its nodes and stiffnesses, N/m): a node's
/// spring holds its share of the boundary's area, so the truth on another mesh is the reference's stiffness per
/// area at its nearest spring node times the model node's area (a finer reference carries more, weaker springs).
fn equivalent_springs(reference: (&Mesh, &[usize], &[f64]), model: (&Mesh, &[usize])) -> Vec<f64> {
    let (reference_mesh, reference_nodes, stiffness) = reference;
    let (model_mesh, model_nodes) = model;
    let area = mesh::boundary_node_areas(reference_mesh);
    let per_area: Vec<f64> =
        reference_nodes.iter().zip(stiffness).map(|(&n, k)| if area[n] > 0.0 { k / area[n] } else { 0.0 }).collect();
    let at: Vec<Point> = reference_nodes.iter().map(|&n| reference_mesh.nodes[n]).collect();
    let model_area = mesh::boundary_node_areas(model_mesh);
    model_nodes
        .iter()
        .map(|&i| nearest(&at, 0..at.len(), model_mesh.nodes[i]).map_or(0.0, |j| per_area[j] * model_area[i]))
        .collect()
}

/// Feature points drawn on the surface facing the camera, on triangles without constrained nodes, located in
/// the mesh; with their rest positions.
fn feature_points(
    problem: &Problem,
    locator: &MeshLocator,
    spec: &ObservationSpec,
) -> Result<(Vec<TrackedPoint>, Vec<Point>), AssimilationError> {
    let count = match spec.points {
        Some(n) if n > 0 => n,
        _ => {
            return Err(AssimilationError::Setup(
                "observations.points (at least 1) is needed for synthetic observations".into(),
            ))
        }
    };
    // Draw generously, then keep the first points away from constrained nodes.
    let samples = mesh::sampling::sample_visible_boundary(&problem.mesh, spec.view_direction, 8 * count, spec.seed)
        .context(|| "drawing feature points".into())?;
    let mut points = Vec::with_capacity(count);
    let mut rest = Vec::with_capacity(count);
    for s in samples.iter().filter(|s| s.nodes.iter().all(|k| !problem.dirichlet.contains_key(k))).take(count) {
        points.push(TrackedPoint::locate(locator, s.point).context(|| "locating a feature point".into())?);
        rest.push(s.point);
    }
    if points.len() < count {
        return Err(AssimilationError::Setup(format!(
            "only {} feature points found on the visible surface away from constrained nodes, {count} asked",
            points.len()
        )));
    }
    Ok((points, rest))
}

/// `count` nodes of the selection, neither constrained nor carrying an observed point, spread out by farthest-point
/// sampling from the candidate nearest their centroid.
fn assessment_points(
    problem: &Problem,
    spec: &AssessmentSpec,
    observed_nodes: &[usize],
) -> Result<Vec<TrackedPoint>, AssimilationError> {
    let nodes = &problem.mesh.nodes;
    let candidates: Vec<usize> = spec
        .select
        .select(&problem.mesh)
        .context(|| "assessment selection".into())?
        .into_iter()
        .filter(|k| !problem.dirichlet.contains_key(k) && !observed_nodes.contains(k))
        .collect();
    if spec.count == 0 || candidates.len() < spec.count {
        return Err(AssimilationError::Setup(format!(
            "assessment: {} points asked, {} candidate nodes are neither constrained nor observed",
            spec.count,
            candidates.len()
        )));
    }
    Ok(mesh::select::farthest_points(nodes, &candidates, spec.count).into_iter().map(TrackedPoint::at_node).collect())
}

/// Locates tracked points in a tetrahedral mesh. A point outside the mesh by at most half the mean element size
/// (a feature of a finer or smoother surface than the mesh's facets) is located at the closest point of the mesh's
/// surface and keeps its offset from there ([`TrackedPoint::tracked_at`]); the moves' lengths are kept.
struct PointFinder<'a> {
    locator: &'a MeshLocator,
    surface: SurfaceBvh,
    /// Half an element: how far outside the surface a feature is still moved onto it.
    reach: f64,
    /// The mesh's box diagonal (m).
    organ_size: f64,
    moved: Vec<f64>,
}

impl<'a> PointFinder<'a> {
    fn new(mesh: &Mesh, locator: &'a MeshLocator) -> Result<Self, AssimilationError> {
        let surface = SurfaceBvh::new(&mesh::boundary_surface(mesh)).context(|| "indexing the mesh surface".into())?;
        let reach = 0.5 * (mesh.volume() / mesh.cells.len().max(1) as f64).cbrt();
        let organ_size = mesh::box_diagonal(mesh.bounds());
        Ok(PointFinder { locator, surface, reach, organ_size, moved: Vec::new() })
    }

    /// Whether `p` lies in the mesh or within [`PointFinder::reach`] of its surface (where it is located).
    fn holds(&self, p: Point) -> bool {
        self.locator.locate(p).is_some() || self.surface.closest_point(p).distance <= self.reach
    }

    fn locate(&mut self, p: Point) -> Result<TrackedPoint, FemModelError> {
        let outside = match TrackedPoint::locate(self.locator, p) {
            Ok(t) => return Ok(t),
            Err(e) => e,
        };
        let c = self.surface.closest_point(p);
        if !(c.distance <= self.reach) {
            if !c.distance.is_finite() || self.locator.locate(p).is_some() {
                return Err(outside);
            }
            return Err(FemModelError::Invalid(format!(
                "tracked point {} lies outside the mesh, {:.2} mm from its surface (points within {:.2} mm, half an \
                 element, are moved onto it)",
                mesh::length::point_in_mm(p),
                mesh::length::mm(c.distance),
                mesh::length::mm(self.reach)
            )));
        }
        // A hair inside, so that rounding cannot leave the point on the outer side of the facet.
        let inside: Point = std::array::from_fn(|d| c.point[d] + 1e-3 * (c.point[d] - p[d]));
        let t = TrackedPoint::locate(self.locator, inside)?;
        self.moved.push(c.distance);
        Ok(t.tracked_at(inside, p))
    }
}

/// The features of a track file located in the mesh at their rest positions (`positions`, from `rest` when
/// given); an error names the line that gives the rest position (in `rest`'s file, or the feature's first row).
fn locate_tracks(
    tracks: &Tracks,
    positions: &[Point],
    rest: Option<&RestPositions>,
    finder: &mut PointFinder,
) -> Result<Vec<TrackedPoint>, AssimilationError> {
    let mut located = Vec::with_capacity(positions.len());
    for (j, (id, p)) in tracks.ids.iter().zip(positions).enumerate() {
        let point = finder.locate(*p).map_err(|e| {
            let (path, line) = match rest.and_then(|r| Some((&r.path, r.line(id)?))) {
                Some(given) => given,
                None => (&tracks.path, tracks.line(j)),
            };
            // Where it is: a data error, not the model's.
            let why = match e {
                FemModelError::Invalid(why) => why,
                other => other.to_string(),
            };
            // Millimetres read as metres lie a thousand times too far out: farther from the organ than
            // its size, and each inside it read so. (A feature just outside it fits when shrunk too,
            // about an origin the organ holds: its unit is not blamed.)
            let mistake = UnitMistake { given: LengthUnit::Millimetre, expected: LengthUnit::Metre };
            let far = finder.surface.closest_point(*p).distance > finder.organ_size;
            let in_mm = far && positions.iter().all(|p| finder.holds(p.map(|x| x * mistake.factor())));
            let hint = match in_mm {
                true => format!(
                    ": read {}, every feature lies in the organ or on its surface; is the file {}? A header x_mm, \
                     y_mm, z_mm names the unit (or give --units mm)",
                    mistake.undone_words(),
                    mistake.question()
                ),
                false => String::new(),
            };
            AssimilationError::file(path, Some(line), format!("feature `{id}`: {why}{hint}"))
        })?;
        located.push(point);
    }
    Ok(located)
}

/// Control paths of the tool features: each on the surface node nearest its rest position (`positions`) among
/// those not constrained yet (which it then constrains); displacement = tracked position − rest position, held while
/// occluded.
fn control_paths(
    problem: &mut Problem,
    tracks: &Tracks,
    positions: &[Point],
    steps: usize,
) -> Result<Vec<ControlPath>, AssimilationError> {
    let surface = mesh::boundary_nodes(&problem.mesh);
    let mut paths: Vec<ControlPath> = Vec::with_capacity(positions.len());
    for (j, p) in positions.iter().enumerate() {
        let bad = |m: String| AssimilationError::file(&tracks.path, Some(tracks.line(j)), m);
        let id = &tracks.ids[j];
        let free = surface.iter().copied().filter(|k| !problem.dirichlet.contains_key(k));
        let node = nearest(&problem.mesh.nodes, free, *p)
            .ok_or_else(|| bad(format!("tool feature `{id}`: every surface node is constrained already")))?;
        if let Some(other) = paths.iter().position(|c| c.node == node) {
            return Err(bad(format!(
                "tool features `{}` and `{id}` are nearest to the same surface node {node}",
                tracks.ids[other]
            )));
        }
        let mut last = [0.0; 3];
        let displacements = (1..=steps)
            .map(|k| {
                if let Some(x) = tracks.position(j, k) {
                    last = std::array::from_fn(|d| x[d] - p[d]);
                }
                last
            })
            .collect();
        problem.dirichlet.insert(node, [0.0; 3]);
        paths.push(ControlPath { node, displacements });
    }
    Ok(paths)
}

/// Mean Euclidean distance between stacked positions and the measured points of a frame (NaN if none measured).
fn mean_error(a: &DVector<f64>, truth: &Frame) -> f64 {
    let (sum, n) = (0..a.len() / 3)
        .filter(|&i| truth.available[3 * i])
        .map(|i| (0..3).map(|d| (a[3 * i + d] - truth.z[3 * i + d]).powi(2)).sum::<f64>().sqrt())
        .fold((0.0, 0usize), |(s, n), e| (s + e, n + 1));
    sum / n as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Springs of 100 N/m on every node of a box's top face, carried over to a coarser box: the
    /// coarse mesh's springs are fewer and stiffer, each by its share of the area, and hold about the
    /// same stiffness in all.
    #[test]
    fn springs_carried_to_another_mesh_keep_their_stiffness_per_area() {
        let top = |m: &Mesh| -> Vec<usize> { (0..m.nodes.len()).filter(|&i| m.nodes[i][2] > 0.0999).collect() };
        let fine = mesh::generate::box_tet([0.0; 3], [0.1; 3], [8, 8, 2]).unwrap();
        let coarse = mesh::generate::box_tet([0.0; 3], [0.1; 3], [4, 4, 2]).unwrap();
        let (fine_top, coarse_top) = (top(&fine), top(&coarse));
        let stiffness = vec![100.0; fine_top.len()];
        let equivalent = equivalent_springs((&fine, &fine_top, &stiffness), (&coarse, &coarse_top));
        // In all: about the fine springs' 8,100 N/m (81 nodes), the edges' springs sampled at their nearest.
        let total: f64 = equivalent.iter().sum();
        assert!((total / 8100.0 - 1.0).abs() < 0.1, "{total}");
        let centre = coarse_top.iter().position(|&i| mesh::distance(coarse.nodes[i], [0.05, 0.05, 0.1]) < 1e-9);
        assert!((equivalent[centre.unwrap()] - 400.0).abs() < 1e-6, "four times the area: {equivalent:?}");
    }
}
