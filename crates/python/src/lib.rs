//! `augsim._augsim`, the native module of augsim's Python package (`python/`, built by maturin):
//! static solves, registration of point clouds with a warm start between frames, U-Net
//! predictions and the ROUKF one step at a time. Every call reuses what the command line does
//! (scenario loaders, `app::registration`, `app::output`, `app::assimilation`);
//! long computations run without the GIL on a thread of their own, which Ctrl-C stops
//! (`KeyboardInterrupt`), and augsim's errors, panics included, arrive in Python as
//! `augsim.AugsimError` with augsim's message.

use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::PathBuf;
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::{Mutex, MutexGuard};
use std::time::Duration;

use app::assimilation::{AssimilationChoice, Experiment, OnlineFilter};
use app::output::write_registered_cloud;
use app::registration::{RegistrationChoice, RegistrationSpec, TargetsSpec};
use fem::post;
use learn::{Model, PointCloud, PredictInput};
use mesh::io::npy::{NpyArray, NpyData};
use mesh::io::{Frame, GivenCoordinates};
use mesh::length::LengthUnit;
use mesh::Point;
use nalgebra::DVector;
use numpy::ndarray::{Array2, Array3, ArrayD, IxDyn};
use numpy::{
    AllowTypeChange, IntoPyArray, PyArray1, PyArray2, PyArray3, PyArrayDyn, PyArrayLikeDyn, PyUntypedArrayMethods,
};
use pyo3::create_exception;
use pyo3::exceptions::{PyRuntimeError, PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;

// Named as the package exports it (`augsim.AugsimError`), so that pickle finds it: an error
// raised in a worker process reaches its parent whole.
create_exception!(
    augsim,
    AugsimError,
    PyRuntimeError,
    "An error reported by augsim: a file that cannot be read, an invalid scenario, cloud or \
     model, a solve that failed. Its message is augsim's."
);

create_exception!(
    augsim,
    AugsimWarning,
    pyo3::exceptions::PyUserWarning,
    "A warning of augsim's: a solve's, a registration's set-up (targets, structures), a file it \
     wrote or left out, a cloud whose result may not be believed (in the same words every cloud: \
     the result's `warnings` say why). Filter them with the `warnings` module by this class."
);

/// The warning of a cloud whose registration may not be believed: the same words every cloud,
/// which Python's default filter shows once at a call site (a frame's own warnings hold numbers
/// that change from frame to frame, and would be shown every frame of a stream).
const DOUBTED: &str = "this cloud's registration may not be believed: its result's `warnings` say why";

/// Each of `lines` as an [`AugsimWarning`].
fn warn_each(py: Python<'_>, lines: &[String]) -> PyResult<()> {
    for line in lines {
        PyErr::warn(py, &py.get_type::<AugsimWarning>(), &std::ffi::CString::new(line.as_str())?, 1)?;
    }
    Ok(())
}

/// How often a caller waiting for a computation checks for Ctrl-C.
const SIGNAL_POLL: Duration = Duration::from_millis(50);

/// Outcome of a call into augsim: a value, an error, or a panic caught.
type Outcome<T> = std::thread::Result<anyhow::Result<T>>;

/// The process that first computed with augsim (0: none yet). Its worker threads (rayon's) are
/// not in a process forked from it, whose computations would wait for them forever.
static COMPUTING_PROCESS: AtomicU32 = AtomicU32::new(0);

/// Refuses to compute in a process forked from one that computed with augsim (multiprocessing's
/// "fork", Linux's default before Python 3.14), saying how to start workers instead; claims the
/// process otherwise.
fn check_not_forked() -> PyResult<()> {
    let me = std::process::id();
    match COMPUTING_PROCESS.compare_exchange(0, me, Ordering::SeqCst, Ordering::SeqCst) {
        Err(parent) if parent != me => Err(AugsimError::new_err(
            "this process was forked from one that computed with augsim, whose worker threads a forked process \
             lacks (it would wait for them forever): start worker processes with \"spawn\" or \"forkserver\" \
             (multiprocessing.get_context(\"spawn\"); ProcessPoolExecutor(mp_context=...)), or use augsim in the \
             parent only after the workers started",
        )),
        _ => Ok(()),
    }
}

/// Runs `f` on a thread of its own, without the GIL, while the caller checks for signals: Ctrl-C
/// asks it to stop ([`fem::interrupt`]) and raises `KeyboardInterrupt` once it has. Its error, or a
/// panic, becomes an [`AugsimError`]; so does a call in a process forked from one that computed
/// ([`check_not_forked`]).
fn compute<T: Send>(py: Python<'_>, f: impl FnOnce() -> anyhow::Result<T> + Send) -> PyResult<T> {
    check_not_forked()?;
    let outcome = std::thread::scope(|scope| {
        let (sender, receiver) = std::sync::mpsc::channel::<Outcome<T>>();
        scope.spawn(move || sender.send(catch_unwind(AssertUnwindSafe(f))));
        // The receiver is not shared between threads; the lock makes it so for `detach`.
        let receiver = Mutex::new(receiver);
        let wait = |timeout: Option<Duration>| {
            let receiver = receiver.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
            match timeout {
                Some(t) => receiver.recv_timeout(t).ok(),
                None => receiver.recv().ok(),
            }
        };
        loop {
            if let Some(outcome) = py.detach(|| wait(Some(SIGNAL_POLL))) {
                return Ok(outcome);
            }
            if let Err(signal) = py.check_signals() {
                fem::interrupt::request();
                py.detach(|| wait(None));
                fem::interrupt::clear();
                return Err(signal);
            }
        }
    })?;
    result(outcome)
}

/// Reads the state of an object with `f`, without the GIL (a read takes no time: it is not
/// interrupted); its error, or a panic, becomes an [`AugsimError`].
fn read<T: Send>(py: Python<'_>, f: impl FnOnce() -> anyhow::Result<T> + Send) -> PyResult<T> {
    check_not_forked()?;
    result(py.detach(|| catch_unwind(AssertUnwindSafe(f))))
}

/// The value of an outcome; its error, or its panic, as an [`AugsimError`].
fn result<T>(outcome: Outcome<T>) -> PyResult<T> {
    match outcome {
        Ok(Ok(value)) => Ok(value),
        Ok(Err(e)) => Err(AugsimError::new_err(format!("{e:#}"))),
        Err(panic) => {
            let message = panic
                .downcast_ref::<String>()
                .map(String::as_str)
                .or_else(|| panic.downcast_ref::<&str>().copied())
                .unwrap_or("no message");
            Err(AugsimError::new_err(format!("internal error (a bug in augsim): {message}")))
        }
    }
}

/// The state behind `lock`; an error when an earlier call panicked while holding it.
fn locked<T>(lock: &Mutex<T>) -> anyhow::Result<MutexGuard<'_, T>> {
    lock.lock().map_err(|_| anyhow::anyhow!("an earlier call failed inside augsim: build a new object"))
}

/// The values of an array-like (converted to float64) with its shape.
fn array(value: &Bound<'_, PyAny>, what: &str) -> PyResult<(Vec<usize>, Vec<f64>)> {
    if value.is_none() {
        return Err(PyTypeError::new_err(format!("{what} is None: an array of numbers is expected")));
    }
    // NumPy would cast these to numbers silently (complex losing its imaginary part).
    if let Ok(kind) = value.getattr("dtype").and_then(|d| d.getattr("kind")).and_then(|k| k.extract::<String>()) {
        if let Some(name) = match kind.as_str() {
            "c" => Some("complex numbers"),
            "b" => Some("booleans"),
            _ => None,
        } {
            return Err(PyValueError::new_err(format!("{what} holds {name}: real numbers are expected")));
        }
    }
    let a: PyArrayLikeDyn<'_, f64, AllowTypeChange> =
        value.extract().map_err(|e| PyValueError::new_err(format!("{what} must be an array of numbers: {e}")))?;
    let values = a.as_array();
    Ok((values.shape().to_vec(), values.iter().copied().collect()))
}

/// A count given from Python (`None`: the default), refused below 1 with its name.
fn count(value: Option<i64>, what: &str) -> PyResult<Option<usize>> {
    value
        .map(|n| usize::try_from(n).ok().filter(|&n| n >= 1).ok_or(n))
        .transpose()
        .map_err(|n| PyValueError::new_err(format!("{what} = {n} must be at least 1")))
}

/// Points from an array of shape `[N, 3]`.
fn points(value: &Bound<'_, PyAny>, what: &str) -> PyResult<Vec<Point>> {
    let (shape, values) = array(value, what)?;
    if shape.len() != 2 || shape[1] != 3 {
        return Err(PyValueError::new_err(format!("{what} must have shape [N, 3], got {shape:?}")));
    }
    let given: Vec<Point> = values.chunks_exact(3).map(|p| [p[0], p[1], p[2]]).collect();
    if let Some((i, fault)) = mesh::measured_fault(&given) {
        return Err(AugsimError::new_err(format!("{what} point {i} {fault}")));
    }
    Ok(given)
}

/// An `[N, 3]` array of nodal vectors (3 values per node).
fn nodal<'py>(py: Python<'py>, values: &[f64]) -> Bound<'py, PyArray2<f64>> {
    Array2::from_shape_vec((values.len() / 3, 3), values.to_vec()).expect("3 values per node").into_pyarray(py)
}

/// An `[N, 3]` array of points.
fn point_array<'py>(py: Python<'py>, points: &[Point]) -> Bound<'py, PyArray2<f64>> {
    nodal(py, points.as_flattened())
}

/// The result of a static solve (m).
#[pyclass(frozen, module = "augsim")]
struct Solution {
    /// Rest positions of the mesh's nodes, float64 [n, 3] (m).
    #[pyo3(get)]
    points: Py<PyArray2<f64>>,
    /// Displacement of each node, float64 [n, 3] (m).
    #[pyo3(get)]
    displacement: Py<PyArray2<f64>>,
    /// The force each node's supports (its hold, its springs) exert on it, float64 [n, 3] (N); zero
    /// on a node that none holds.
    #[pyo3(get)]
    reaction_force: Py<PyArray2<f64>>,
    /// Solver iterations over all load steps.
    #[pyo3(get)]
    iterations: usize,
    /// Load steps taken.
    #[pyo3(get)]
    load_steps: usize,
    /// Numeric factorisations of the tangent stiffness.
    #[pyo3(get)]
    factorizations: usize,
    /// Final relative residual |r| / max(|f_ext|, |f_int|).
    #[pyo3(get)]
    residual: f64,
    /// Largest nodal displacement (m).
    #[pyo3(get)]
    max_displacement: f64,
    /// Wall time of the solve (ms).
    #[pyo3(get)]
    ms: f64,
}

#[pymethods]
impl Solution {
    fn __repr__(&self, py: Python<'_>) -> String {
        format!(
            "Solution(nodes={}, iterations={}, load_steps={}, residual={:.3e}, max_displacement={:.6}, ms={:.1})",
            self.points.bind(py).shape()[0],
            self.iterations,
            self.load_steps,
            self.residual,
            self.max_displacement,
            self.ms
        )
    }
}

/// Solves a static scenario as `augsim solve` does.
///
/// `scenario`: a scenario file (TOML, `kind = "static"`) or the name of a built-in one (`beam`,
/// `liver`, ...). Returns a `Solution` (`points`, `displacement`, `iterations`, ...). Raises
/// `AugsimError` when the scenario cannot be read or the solve fails to converge; warns
/// (`AugsimWarning`) as `augsim solve` does.
#[pyfunction]
fn solve(py: Python<'_>, scenario: PathBuf) -> PyResult<Solution> {
    let (nodes, sol, reaction, warnings) = compute(py, || {
        let solved = app::solve::solve_scenario(&scenario, |_, _| {})?;
        let warnings = solved.warnings()?;
        Ok((solved.solver.problem().mesh.nodes.clone(), solved.solution, solved.reaction, warnings))
    })?;
    warn_each(py, &warnings)?;
    Ok(Solution {
        points: point_array(py, &nodes).unbind(),
        displacement: nodal(py, &sol.u).unbind(),
        reaction_force: nodal(py, &reaction).unbind(),
        iterations: sol.iterations,
        load_steps: sol.load_steps,
        factorizations: sol.factorizations,
        residual: sol.residuals.last().copied().unwrap_or(0.0),
        max_displacement: post::max_displacement(&sol.u),
        ms: mesh::stats::ms(sol.timings.total),
    })
}

/// A registered cloud, in the registration's units.
#[pyclass(frozen, module = "augsim")]
struct Registered {
    /// The registered targets, float64 [k, 3], in the order given.
    #[pyo3(get)]
    targets: Py<PyArray2<f64>>,
    /// Displacement of the organ's nodes, float64 [n, 3] (rest positions: `Registration.points`).
    #[pyo3(get)]
    displacement: Py<PyArray2<f64>>,
    /// Mean distance from the cloud's points to the registered surface (those registered, when the
    /// cloud is subsampled: `points`).
    #[pyo3(get)]
    surface_residual: f64,
    /// Cloud points matched (outliers rejected) in the last iteration.
    #[pyo3(get)]
    inliers: usize,
    /// Cloud points registered: every point up to the library's limit (an evenly spaced subset of a
    /// larger cloud; a reduced-order model's shape fit takes fewer still).
    #[pyo3(get)]
    points: usize,
    /// Match-and-deform iterations.
    #[pyo3(get)]
    iterations: usize,
    /// The cloud registered from rest, not from the previous cloud's result (the first, after
    /// `reset()`, or after a cloud that left the organ distorted or lay on it in the other frame).
    #[pyo3(get)]
    from_rest: bool,
    /// What to know of the result: why it may not be believed (the registered surface far from
    /// the cloud, an implausible motion or change of the organ's volume), or that the frame ran
    /// out of its time budget (which alone leaves it plausible); empty when there is none.
    #[pyo3(get)]
    warnings: Vec<String>,
    /// Whether the result passed the plausibility checks (no warning but the time budget's): the
    /// files of one that did not are named `…_implausible`, as a stream's answers are.
    #[pyo3(get)]
    plausible: bool,
    /// With `rigid=True`: the organ-to-cloud transform, float64 [4, 4] (translation in `units`);
    /// otherwise None.
    #[pyo3(get)]
    rigid: Option<Py<PyArray2<f64>>>,
    /// The predicted standard deviation of each target's error, float64 [k], in `units`, for a
    /// method that predicts one (the reduced-order model, and the U-Net after its shape fit);
    /// otherwise None.
    #[pyo3(get)]
    target_sigma: Option<Py<PyArray1<f64>>>,
    /// Wall time of the registration (ms).
    #[pyo3(get)]
    ms: f64,
    /// Each structure's vertices moved with the organ, float64 [n, 3], by its name (the file's
    /// stem; its triangles are the file's); empty without `structures`.
    #[pyo3(get)]
    structures: Py<PyDict>,
}

#[pymethods]
impl Registered {
    /// Its fields as a dict of NumPy arrays and plain values (the object itself cannot be pickled:
    /// return this from a worker process).
    fn to_dict<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        d.set_item("targets", self.targets.clone_ref(py))?;
        d.set_item("displacement", self.displacement.clone_ref(py))?;
        d.set_item("surface_residual", self.surface_residual)?;
        d.set_item("inliers", self.inliers)?;
        d.set_item("points", self.points)?;
        d.set_item("iterations", self.iterations)?;
        d.set_item("from_rest", self.from_rest)?;
        d.set_item("warnings", self.warnings.clone())?;
        d.set_item("plausible", self.plausible)?;
        d.set_item("rigid", self.rigid.as_ref().map(|r| r.clone_ref(py)))?;
        d.set_item("target_sigma", self.target_sigma.as_ref().map(|s| s.clone_ref(py)))?;
        d.set_item("ms", self.ms)?;
        d.set_item("structures", self.structures.bind(py).copy()?)?;
        Ok(d)
    }

    fn __repr__(&self, py: Python<'_>) -> String {
        format!(
            "Registered(targets={}, iterations={}, from_rest={}, surface_residual={:.6}, inliers={}, points={}, \
             plausible={}, warnings={}, ms={:.1})",
            self.targets.bind(py).shape()[0],
            self.iterations,
            if self.from_rest { "True" } else { "False" },
            self.surface_residual,
            self.inliers,
            self.points,
            if self.plausible { "True" } else { "False" },
            self.warnings.len(),
            self.ms
        )
    }
}

/// Registration of intraoperative point clouds, as `augsim serve` does for each client: each
/// cloud is warm-started from the previous one's registration.
///
/// Either `patient`: a directory written by `augsim prepare` (the method it found the best on
/// its validation and its targets; `use_fem=True` for its FEM, `False` for its learned model,
/// `use_hybrid=True` for its learned model from rest then its FEM); or
/// `fem`: a static scenario (file or built-in name, e.g. `liver`) whose FEM deforms the organ; or `model` (a model directory or its model.json) with `scenario`, the dataset scenario
/// it was trained on (e.g. `liver_ar_t10` for the shipped `models/liver_ar`). `targets`: rest
/// positions, a CSV file (x, y, z) or an array [k, 3], in `units`; default: the mesh's `markers`
/// and `tumour` nodes. `units`: "m", "mm", "cm" or "um", of the targets, every cloud and every result
/// (default: a patient's own unit, else "m"). `frame`: "RAS" or "LPS", the frame of every cloud
/// and every result, converted from and to the organ's when it names one (a patient's, or a
/// targets file's); default: a patient's own (the frame of the files it was prepared from), else
/// the organ's.
/// `iterations`: most match-and-deform iterations of the first cloud, from rest (default: the
/// library's for a FEM, 30; a U-Net's real-time budget, 4; 10
/// for a reduced-order model's shape fit); a warm-started cloud takes at most min(iterations, 4)
/// for a FEM, min(iterations, 2) for a U-Net and min(iterations, 3) for a reduced-order model's
/// shape fit. `rigid`: align the first cloud rigidly to
/// the organ (trimmed ICP) and keep that pose while the clouds register plausibly (after a frame
/// with a warning other than the time budget's, the next cloud is aligned again); `targets`
/// (and `rigid`) are then in the cloud's frame, `points` and `displacement` in the organ's.
/// `time_budget_ms`: most wall time of a cloud's registration; a cloud past it returns the
/// estimate reached, with a warning (default: none, as `augsim register`; `augsim serve` takes
/// 1000 ms).
#[pyclass(module = "augsim")]
struct Registration {
    state: Mutex<register::Registration>,
    /// The unit and frame of clouds, targets and results, against the organ's.
    given: GivenCoordinates,
    /// The organ's frame and the one clouds are given in (`frame`), each when known: the files
    /// `out` writes are in the clouds' frame, else the organ's.
    frames: (Option<Frame>, Option<Frame>),
    /// The method in words (e.g. "FEM, Corotational (Standard elements)").
    #[pyo3(get)]
    method: String,
    /// The units of clouds, targets and results ("m", "mm", "cm" or "um").
    #[pyo3(get)]
    units: String,
    /// The frame of clouds and results ("RAS", "LPS"), or None where neither the organ nor the
    /// user names one.
    #[pyo3(get)]
    frame: Option<String>,
}

#[pymethods]
impl Registration {
    #[new]
    #[pyo3(signature = (*, fem=None, model=None, scenario=None, shape_model=None, patient=None, use_fem=None, use_hybrid=false, targets=None, units=None, frame=None, iterations=None, rigid=false, structures=None, time_budget_ms=None))]
    #[allow(clippy::too_many_arguments)] // one per Python keyword argument
    fn new(
        py: Python<'_>,
        fem: Option<PathBuf>,
        model: Option<PathBuf>,
        scenario: Option<PathBuf>,
        shape_model: Option<PathBuf>,
        patient: Option<PathBuf>,
        use_fem: Option<bool>,
        use_hybrid: bool,
        targets: Option<&Bound<'_, PyAny>>,
        units: Option<&str>,
        frame: Option<&str>,
        iterations: Option<i64>,
        rigid: bool,
        structures: Option<&Bound<'_, PyAny>>,
        time_budget_ms: Option<f64>,
    ) -> PyResult<Self> {
        // One path (a str or a PathLike) or a list of them.
        let structures: Vec<PathBuf> = match structures {
            None => Vec::new(),
            Some(given) => match given.extract::<PathBuf>() {
                Ok(one) => vec![one],
                Err(_) => given.extract().map_err(|_| {
                    PyTypeError::new_err("structures must be a path or a list of paths (models, or 'labelmap:label')")
                })?,
            },
        };
        let iterations = count(iterations, "iterations")?;
        // The loop's own check of the budget, raised as a ValueError (as for `iterations`).
        let budget = register::RegistrationOptions { time_budget_ms, ..Default::default() };
        budget.validate().map_err(|e| PyValueError::new_err(e.to_string()))?;
        let units: Option<LengthUnit> =
            units.map(str::parse).transpose().map_err(|e| PyValueError::new_err(format!("units: {e}")))?;
        let frame: Option<Frame> =
            frame.map(str::parse).transpose().map_err(|e| PyValueError::new_err(format!("frame: {e}")))?;
        let targets = match targets {
            None => None,
            Some(t) => Some(match t.extract::<PathBuf>() {
                Ok(path) => TargetsSpec::File(path),
                Err(_) => match points(t, "targets")? {
                    given if given.is_empty() => {
                        return Err(PyValueError::new_err("targets: the array holds no point"))
                    }
                    given => TargetsSpec::Points(given),
                },
            }),
        };
        let choice = RegistrationChoice {
            patient,
            use_fem: use_fem == Some(true),
            use_model: use_fem == Some(false),
            use_hybrid,
            fem,
            model,
            scenario,
            shape_model,
            targets,
            units,
            frame,
            iterations,
            rigid,
            structures,
        };
        choice.check().map_err(PyValueError::new_err)?;
        let (state, spec) = compute(py, move || {
            let spec = RegistrationSpec { time_budget_ms, ..choice.spec()? };
            Ok((spec.build()?, spec))
        })?;
        let organ_frame = state.frame();
        let given = spec.coordinates(&state);
        warn_each(py, state.warnings())?;
        let method = state.method().to_string();
        Ok(Registration {
            state: Mutex::new(state),
            given,
            frames: (organ_frame, spec.given_frame),
            method,
            units: given.unit.to_string(),
            frame: spec.given_frame.or(organ_frame).map(|f| f.to_string()),
        })
    }

    /// Registers a cloud of positions, float [N, 3] in `units` (no correspondences needed),
    /// starting from the previous cloud's registration. Returns a `Registered` (`targets`,
    /// `target_sigma`, `points`, `displacement`, `rigid`, `surface_residual`, `inliers`,
    /// `iterations`, `warnings`, `plausible`, `ms`). With `out`,
    /// a directory, also writes there what `augsim register` writes: organ.vtu (m), targets.csv (in
    /// `units`), summary.json, registration.png and .html (pictures), and for 3D Slicer
    /// targets.mrk.json, organ_deformed.vtk, displacement.nrrd and, with `rigid=True`, rigid.tfm (mm; named
    /// targets_implausible.mrk.json and so on for a registration that is not plausible), all
    /// in the clouds' frame (`frame`, or its default), which they name when known; a directory
    /// that holds an earlier run's results (its summary.json), or other files, is refused, as
    /// `augsim register` refuses it. Raises ValueError for an array of another shape,
    /// AugsimError for a cloud augsim rejects (no point, a NaN) or a failed registration (the
    /// warm start is then kept). What to know of the files written (a displacement.nrrd left
    /// out, or folded somewhere) comes as an AugsimWarning, and so does a result that may not be
    /// believed, in words that do not change from cloud to cloud (shown once at a call site by
    /// Python's default filter: the result's `warnings` say why); a filter that turns them into
    /// errors raises them after the cloud registered (the warm start has moved on).
    #[pyo3(signature = (cloud, *, out=None))]
    fn register(&self, py: Python<'_>, cloud: &Bound<'_, PyAny>, out: Option<PathBuf>) -> PyResult<Registered> {
        let cloud: Vec<Point> = points(cloud, "cloud")?.into_iter().map(|p| self.given.point_in(p)).collect();
        let (tracked, moved, notes) = compute(py, || {
            // A directory that cannot be made, or holds an earlier run's results, fails before the
            // cloud moves the warm start on.
            if let Some(dir) = &out {
                app::output::refuse_used_folder(dir)?;
                mesh::io::create_folder(dir)?;
            }
            let mut state = locked(&self.state)?;
            let tracked = state.register(&cloud)?;
            let notes = match &out {
                Some(dir) => {
                    let frames = (self.given.unit, self.frames);
                    write_registered_cloud(dir, "python", &state, frames, tracked.clone(), &cloud)?.notes
                }
                None => Vec::new(),
            };
            let moved: Vec<(String, Vec<Point>)> = state
                .structure_surfaces(&tracked.registration.u, tracked.rigid.as_ref())
                .into_iter()
                .map(|(name, surface)| (name.to_string(), surface.vertices))
                .collect();
            Ok((tracked, moved, notes))
        })?;
        warn_each(py, &notes)?;
        if !tracked.registration.plausible() {
            warn_each(py, &[DOUBTED.to_string()])?;
        }
        let structures = PyDict::new(py);
        for (name, vertices) in moved {
            structures.set_item(name, self.point_array(py, &vertices))?;
        }
        let back = tracked.given_back(self.given);
        let result = tracked.registration;
        let rigid = back
            .organ_to_cloud
            .map(|rows| Array2::from_shape_fn((4, 4), |(i, j)| rows[i][j]).into_pyarray(py).unbind());
        Ok(Registered {
            targets: point_array(py, &back.targets).unbind(),
            displacement: self.point_array(py, result.u.as_chunks::<3>().0).unbind(),
            surface_residual: back.surface_residual,
            inliers: result.inliers,
            points: result.points,
            iterations: result.iterations,
            from_rest: result.from_rest,
            warnings: result.warnings.clone(),
            plausible: result.plausible(),
            rigid,
            target_sigma: back.target_std.map(|s| s.into_pyarray(py).unbind()),
            ms: mesh::stats::ms(result.time),
            structures: structures.unbind(),
        })
    }

    fn __repr__(&self, py: Python<'_>) -> PyResult<String> {
        let (nodes, targets) = read(py, || {
            let state = locked(&self.state)?;
            Ok((state.organ().mesh().num_nodes(), state.targets().len()))
        })?;
        let frame = self.frame.as_deref().map_or("None".to_string(), |f| format!("'{f}'"));
        Ok(format!(
            "Registration(method='{}', units='{}', frame={frame}, nodes={nodes}, targets={targets})",
            self.method, self.units
        ))
    }

    /// Forgets the previous cloud: the next one is registered from the organ at rest (a FEM
    /// keeps its solver's factorisation, which changes the result slightly: 0.06 mm on the tests' case).
    fn reset(&self, py: Python<'_>) -> PyResult<()> {
        read(py, || {
            locked(&self.state)?.reset();
            Ok(())
        })
    }

    /// Rest positions of the organ's nodes, float64 [n, 3], in `units`.
    #[getter]
    fn points<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let nodes = read(py, || Ok(locked(&self.state)?.organ().mesh().nodes.clone()))?;
        Ok(self.point_array(py, &nodes))
    }

    /// Rest positions of the targets, float64 [k, 3], in `units`.
    #[getter]
    fn targets<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let targets = read(py, || Ok(locked(&self.state)?.targets().to_vec()))?;
        Ok(self.point_array(py, &targets))
    }

    /// The targets' labels, in the order of `targets`: a targets file's ("" where it gives none).
    #[getter]
    fn target_labels(&self, py: Python<'_>) -> PyResult<Vec<String>> {
        read(py, || Ok(locked(&self.state)?.target_labels().to_vec()))
    }
}

impl Registration {
    /// Points (or vectors) of the organ's frame, in m, as an `[N, 3]` array in the registration's
    /// frame and unit.
    fn point_array<'py>(&self, py: Python<'py>, points: &[Point]) -> Bound<'py, PyArray2<f64>> {
        let given: Vec<Point> = points.iter().map(|&p| self.given.point_out(p)).collect();
        point_array(py, &given)
    }
}

/// The split `augsim train` makes of the samples of the dataset in `dataset` (a directory)
/// whose generation indices are `indices`: the last `test` uniform draws, the `validation`
/// before them, the rest (σ-chosen draws included) for training. Returns the split as a model
/// records it (JSON: `source`, `train`, `validation`, `test`) and the positions in `indices` of
/// the training, validation and test samples. Raises AugsimError for counts that leave no
/// training sample, or an unreadable manifest.
#[pyfunction]
fn dataset_split(
    py: Python<'_>,
    dataset: PathBuf,
    indices: Vec<u64>,
    validation: usize,
    test: usize,
) -> PyResult<(String, [Vec<usize>; 3])> {
    compute(py, || {
        let manifest = learn::Manifest::read(&dataset.join(learn::MANIFEST_FILE))?;
        let split = learn::Split::of_indices(Some(manifest.source_id()), &indices, validation, test)?;
        let positions = |set: &learn::IndexSet| (0..indices.len()).filter(|&p| set.contains(indices[p])).collect();
        let sets = [positions(&split.train), positions(&split.validation), positions(&split.test)];
        Ok((serde_json::to_string(&split)?, sets))
    })
}

/// The digest of the weights file at `path` that a U-Net's model.json records as
/// `weights_digest` (augsim refuses weights whose digest differs). Raises AugsimError for an
/// unreadable file.
#[pyfunction]
fn weights_digest(py: Python<'_>, path: PathBuf) -> PyResult<String> {
    compute(py, || {
        let bytes = std::fs::read(&path).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
        Ok(learn::digest(&bytes))
    })
}

/// A training's hold on its model folder ([`lock_model_folder`]), until `release()` or its end.
#[pyclass(module = "augsim")]
struct ModelFolderLock(Option<learn::WriterLock>);

#[pymethods]
impl ModelFolderLock {
    /// Lets another training write the folder.
    fn release(&mut self) {
        self.0 = None;
    }
}

/// Makes the model folder `out` and holds it for one training, as `augsim train` does: a second
/// training there (of either) is refused while this one holds it. Raises AugsimError where
/// another training holds it, the folder cannot be made, or it holds what a U-Net trained in
/// PyTorch would replace or mix with: a dataset, a reduced-order model, a run of `augsim train`
/// (its checkpoint).
#[pyfunction]
fn lock_model_folder(py: Python<'_>, out: PathBuf) -> PyResult<ModelFolderLock> {
    compute(py, || {
        app::training::check_model_folder(&out, learn::Method::UNet)?;
        let checkpoint = learn::training::train::CHECKPOINT_FILE;
        if out.join(checkpoint).exists() {
            anyhow::bail!(
                "{} holds a run of `augsim train` ({checkpoint}): a training in PyTorch would replace its model; \
                 give another --out, or resume it with `augsim train`",
                out.display()
            );
        }
        Ok(ModelFolderLock(Some(learn::take_model_folder(&out)?)))
    })
}

/// Reads an intraoperative cloud file as `augsim register` does: CSV with a header naming x, y, z
/// (or x_mm, …), 3D Slicer's .fcsv or .mrk.json, .npy [N, 3], or the points of a .ply, .vtk, .vtp,
/// .vtu, .stl or .obj file. Returns float64 [N, 3] in `units` ("m", "cm", "mm" or "um"), in the
/// frame the file is in; a file that names no unit is read in `file_units` (default: `units`).
/// Raises AugsimError for a file that is not such a cloud, ValueError for an unknown unit.
#[pyfunction]
#[pyo3(signature = (path, units = "m", file_units = None))]
fn read_cloud<'py>(
    py: Python<'py>,
    path: PathBuf,
    units: &str,
    file_units: Option<&str>,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let unit =
        |name: &str, what: &str| name.parse::<LengthUnit>().map_err(|e| PyValueError::new_err(format!("{what}: {e}")));
    let into = unit(units, "units")?;
    let given = file_units.map_or(Ok(into), |u| unit(u, "file_units"))?;
    let cloud = compute(py, || Ok(app::points::PointInput::new(None, into, given).read_cloud(&path)?))?;
    Ok(point_array(py, &cloud))
}

/// Predicts with a trained U-Net, as `augsim predict` does.
///
/// `model`: a model directory or its model.json. `input`: a grid tensor [3, nx, ny, nz] on the
/// model's grid, in the model's input unit; or a point cloud [N, 6] (x, y, z in m and the vector
/// in the model's input unit) that is put on the grid. Returns the displacement, float32
/// [3, nx, ny, nz] (m), meaningful inside the organ. Raises ValueError for an empty cloud,
/// AugsimError for an unreadable model or an input that does not fit it.
#[pyfunction]
fn predict<'py>(py: Python<'py>, model: PathBuf, input: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
    let (shape, values) = array(input, "input")?;
    let input = match shape.as_slice() {
        [0, 6] => return Err(PyValueError::new_err("input: a point cloud without points")),
        [_, 6] => PredictInput::Points(PointCloud::from_rows(
            &values.chunks_exact(6).map(|r| std::array::from_fn(|i| r[i])).collect::<Vec<_>>(),
        )),
        [3, _, _, _] => PredictInput::Grid(NpyArray { shape: shape.clone(), data: NpyData::F64(values) }),
        other => {
            return Err(PyValueError::new_err(format!(
                "input: an array of shape {other:?}, where a grid tensor [3, nx, ny, nz] or a point cloud [N, 6] \
                 is expected"
            )))
        }
    };
    let (grid, prediction) = compute(py, || {
        let model = Model::load(&model)?;
        let data = input.into_network_input(&model)?.field;
        Ok((model.grid(), model.predictor(learn::Compute::Cpu)?.predict(&data)?))
    })?;
    let array = ArrayD::from_shape_vec(IxDyn(&[3, grid.nx, grid.ny, grid.nz]), prediction)
        .map_err(|e| AugsimError::new_err(format!("prediction of an unexpected size: {e}")))?;
    Ok(array.into_pyarray(py))
}

/// The filter's estimate after a step.
#[pyclass(frozen, module = "augsim")]
struct Estimate {
    /// Filter iterations done.
    #[pyo3(get)]
    iteration: usize,
    /// The parameters' estimate (physical units; `Assimilation.names` says which).
    #[pyo3(get)]
    mean: Vec<f64>,
    /// Their standard deviations.
    #[pyo3(get)]
    std: Vec<f64>,
    /// Norm of the innovation of the step (m), over the measured components; None when no point was
    /// seen.
    #[pyo3(get)]
    innovation: Option<f64>,
    /// Measured components the validation gate left out of the step (the scenario's
    /// `[filter] gate`: farther from the prediction than it allows, as a tracking failure).
    #[pyo3(get)]
    gated: usize,
}

#[pymethods]
impl Estimate {
    fn __repr__(&self) -> String {
        let list = |v: &[f64]| v.iter().map(|x| x.to_string()).collect::<Vec<_>>().join(", ");
        format!(
            "Estimate(iteration={}, mean=[{}], std=[{}], gated={})",
            self.iteration,
            list(&self.mean),
            list(&self.std),
            self.gated
        )
    }
}

/// The ROUKF of an assimilation scenario, one step at a time.
///
/// `scenario`: an assimilation scenario file or built-in name (`roukf_young`, `roukf_springs`).
/// Building it runs the scenario's reference simulation, whose synthetic measurements are
/// `observations`; `iterations` overrides the scenario's number of steps. Each `step` takes the
/// measured positions of the observed points at the next time step of the scenario's loading.
#[pyclass(module = "augsim")]
struct Assimilation {
    experiment: Experiment,
    filter: Mutex<OnlineFilter>,
    /// The estimated parameters' names, in order (`young`, `k_<node>` for a spring).
    #[pyo3(get)]
    names: Vec<String>,
}

#[pymethods]
impl Assimilation {
    #[new]
    #[pyo3(signature = (scenario, *, iterations=None))]
    fn new(py: Python<'_>, scenario: PathBuf, iterations: Option<i64>) -> PyResult<Self> {
        let iterations = count(iterations, "iterations")?;
        let choice = AssimilationChoice { scenario, iterations, ..AssimilationChoice::default() };
        let (experiment, filter) = compute(py, || choice.online())?;
        let names = filter.names().to_vec();
        Ok(Assimilation { experiment, filter: Mutex::new(filter), names })
    }

    /// One filter step with the measured positions of the observed points, float [p, 3] (m,
    /// in the order of `observed_points`; NaN for a point not seen). Returns the `Estimate`
    /// after it. Raises ValueError for another shape, AugsimError when the step is refused or
    /// fails: the filter is then left as it was, and the next call is the same step again.
    fn step(&self, py: Python<'_>, observation: &Bound<'_, PyAny>) -> PyResult<Estimate> {
        let (shape, z) = array(observation, "observation")?;
        let p = self.experiment.setup().features;
        if shape != [p, 3] {
            return Err(PyValueError::new_err(format!("observation must have shape [{p}, 3], got {shape:?}")));
        }
        compute(py, || {
            let mut filter = locked(&self.filter)?;
            let next = filter.iteration() + 1;
            let e = filter.step(z).map_err(|e| {
                anyhow::Error::new(e).context(format!(
                    "step {next} refused: the filter is left as it was, and the next call is step {next} again, at \
                     its load (an observation all NaN counts a step with no point seen)"
                ))
            })?;
            Ok(Estimate { iteration: e.iteration, mean: e.mean, std: e.std, innovation: e.innovation, gated: e.gated })
        })
    }

    /// The current estimate of the parameters (physical units), in the order of `names`.
    #[getter]
    fn mean(&self, py: Python<'_>) -> PyResult<Vec<f64>> {
        read(py, || Ok(locked(&self.filter)?.mean()))
    }

    /// The current standard deviations of the parameters.
    #[getter]
    fn std(&self, py: Python<'_>) -> PyResult<Vec<f64>> {
        read(py, || Ok(locked(&self.filter)?.std()))
    }

    /// Filter steps done.
    #[getter]
    fn iteration(&self, py: Python<'_>) -> PyResult<usize> {
        read(py, || Ok(locked(&self.filter)?.iteration()))
    }

    /// The scenario's values of the parameters, in the order of `names`: the truth behind
    /// `observations`.
    #[getter]
    fn scenario_values(&self) -> Vec<f64> {
        self.experiment.scenario_values().to_vec()
    }

    /// Rest positions of the observed points, float64 [p, 3] (m).
    #[getter]
    fn observed_points<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        point_array(py, &self.experiment.observed_points())
    }

    /// The scenario's synthetic measurements, float64 [steps, p, 3] (m; NaN where not seen).
    #[getter]
    fn observations<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray3<f64>> {
        let frames: Vec<(&DVector<f64>, &[bool])> = self.experiment.observations().collect();
        let values: Vec<f64> = frames
            .iter()
            .flat_map(|(z, available)| z.iter().zip(available.iter()).map(|(&v, &a)| if a { v } else { f64::NAN }))
            .collect();
        let p = self.experiment.setup().features;
        Array3::from_shape_vec((frames.len(), p, 3), values).expect("3 values per observed point").into_pyarray(py)
    }
}

/// augsim's native module: see the `augsim` package.
#[pymodule]
fn _augsim(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("AugsimError", m.py().get_type::<AugsimError>())?;
    m.add("AugsimWarning", m.py().get_type::<AugsimWarning>())?;
    m.add_function(wrap_pyfunction!(solve, m)?)?;
    m.add_function(wrap_pyfunction!(predict, m)?)?;
    m.add_function(wrap_pyfunction!(read_cloud, m)?)?;
    m.add_function(wrap_pyfunction!(dataset_split, m)?)?;
    m.add_function(wrap_pyfunction!(weights_digest, m)?)?;
    m.add_function(wrap_pyfunction!(lock_model_folder, m)?)?;
    m.add("CANDIDATE_BASE", learn::CANDIDATE_BASE)?;
    m.add_class::<Solution>()?;
    m.add_class::<Registration>()?;
    m.add_class::<Registered>()?;
    m.add_class::<Assimilation>()?;
    m.add_class::<Estimate>()?;
    m.add_class::<ModelFolderLock>()?;
    Ok(())
}
