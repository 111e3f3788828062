//! A patient's organ from its segmented surface to a registration set-up, in one resumable run
//! (`augsim prepare`):
//!
//! 1. **organ**: the surface read (STL, OBJ, PLY, VTK, VTP, VTU) in its unit (given, or detected
//!    from its size) and frame (`SPACE=` in its header or field data), the landmarks, targets and camera in theirs
//!    (3D Slicer's `.fcsv` and `.mrk.json` name them; see [`crate::points`]), repaired
//!    ([`mesh::repair`], through voxels when local repair cannot mend it: [`mesh::rebuild`]), or a
//!    label of a segmentation's labelmap (NIfTI, NRRD: in mm, in the scanner's frame the file
//!    states, RAS or LPS) extracted as a closed surface ([`mesh::labelmap`]); meshed with
//!    tetrahedra; the nodes the camera sees
//!    (`visible`, self-occlusion included) and those near the attachment landmarks (`attached`,
//!    on the surface) selected; the targets located inside the organ (a unit mistake is named).
//!    Written in [`SET_UP_FRAME`] (LPS) when the inputs name a frame, so that the same organ in
//!    RAS or LPS gives the same set-up: `surface.stl` in millimetres, for 3D Slicer (its header
//!    naming the frame when known); in metres `organ.vtu` (the regions as point data
//!    `region_visible`, `region_attached`), `attach.csv`, `targets.csv` (with the points'
//!    labels, `x_m` headers, and the frame in a `# CoordinateSystem` line when known).
//! 2. **scenarios**, written out to be read and edited: `dataset.toml` (a tool pushing the
//!    visible surface, the organ held at the landmarks, the input the visible surface's normal
//!    displacement: the built-in `liver_ar`'s set-up on this organ), `static.toml` (the FEM
//!    registration on the same mesh) and `registration.toml` (the set-up that `register`, `serve`
//!    and Python take as `--patient DIR`).
//! 3. **dataset**: the FEM draws (resumes where it stopped), and how far they move the organ: an
//!    organ that swings from where it is held is named here, before the validation's hours.
//! 4. **model**: the reduced-order model (or the U-Net) trained on it.
//! 5. **evaluation**: its error on the test split, which played no part in training it.
//! 6. **validation**: registration of held-out cases, the learned model's, the FEM's and the
//!    hybrid's (the learned model from rest, then the FEM from its estimate), against
//!    a truth they did not see: the same surface meshed anew with quadratic tetrahedra (T10, the
//!    dataset's Neo-Hookean law without its F-bar linear elements), 3, 6 or 12 times finer (the
//!    first whose targets move by at most 10 % on a mesh twice as fine, under the push that moves
//!    them most), pushed by a tool at four places of what the camera sees; the cloud is the
//!    truth's seen surface with 0.5 mm of noise; the TRE at the targets, each push registered from
//!    rest and as a stream (the tool pressing in by quarters of its force, each frame warm-started
//!    from the last). Each truth solve is told as it ends; their solutions are kept in
//!    `validation/`, so that a validation run again does not solve them again.
//!    `registration.toml` names, of the methods no worse than the FEM from rest and on the streams
//!    (within 5 % of its TRE: on par), the one with the lowest mean ratio of its TRE to the FEM's
//!    over the two.
//! 7. **report**: `report.md`, with `regions.png` (the organ seen from the camera: what it
//!    sees, where it is held, the targets), `validation.png` (the chosen method's registration of
//!    the strongest push, drawn by the validation with its 3D page `validation.html`) and the time
//!    of each step.
//!
//! `prepare.json` records the inputs and the steps done; a second run with the same inputs
//! resumes after the last step done (the report is written anew), and one with other inputs is
//! refused.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, ensure, Context, Result};
use mesh::io::points::{read_points_csv, write_points, LabelledPoints};
use mesh::io::{write_atomic_bytes, Frame};
use mesh::length::{mm, point_in_mm, Length, LengthUnit, UnitOrAuto};
use mesh::{Camera, Mesh, Near, Point, TriSurface};
use plot::{scatter_plot, PlotSpec, PointSet};
use serde::{Deserialize, Serialize};

use learn::LearnedModel;

use crate::meshing::{
    mesh_organ_surface, note_lines, tet_mesh_warnings, write_surface_in_mm, OrganInput, OrganMesh, ToMetres,
};
use crate::points::PointInput;
use crate::registration::{absolute_structure, read_structure, structure_labelmap, structure_name};
use crate::setup::{Patient, PatientMethod, SigmaFactors, PATIENT_FILE, SET_UP_FRAME, STATE_FILE, SURFACE_FILE};
use crate::training::{train_unet, UNetRun, UNetStart};

mod validation;
pub use validation::{PICTURE, TABLE, TRUTH_DIR};

/// What `augsim prepare` is given.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PrepareOptions {
    /// The segmented surface (.stl, .obj, .ply, .vtk, .vtp, .vtu) or labelmap (.nii, .nii.gz, .nrrd,
    /// .seg.nrrd, a DICOM SEG or RTSTRUCT).
    pub surface: PathBuf,
    /// The labelmap's label: a number or a segment name (`None`: the only label it holds).
    #[serde(default)]
    pub label: Option<String>,
    /// The unit of the surface, the camera, the landmarks and the targets (`None`: detected from
    /// the surface's size; a labelmap's is the one its header names, else mm).
    pub units: UnitOrAuto,
    /// The frame (RAS or LPS) of the inputs whose files name none: a surface without a `SPACE=`
    /// tag, CSV points (`None`: the first that a file names).
    #[serde(default)]
    pub frame: Option<Frame>,
    /// Where the laparoscope looks from, in the segmentation's frame.
    pub camera: CameraAt,
    /// Landmarks where the organ is held (ligaments, the hilum): a points file (CSV x, y, z,
    /// `.fcsv`, `.mrk.json`).
    pub attach: PathBuf,
    /// Surface nodes within this distance of a landmark are held (`None`: the distance that holds
    /// [`HELD_SHARE`] of the organ's surface).
    #[serde(default)]
    pub attach_distance: Option<Length>,
    /// The targets (tumour, vessels) at rest: a points file (CSV x, y, z, `.fcsv`, `.mrk.json`).
    pub targets: PathBuf,
    /// Structures that move with the organ (a tumour, vessels): surface files in the surface's
    /// unit and frame (else the one their header names), or `LABELMAP:LABEL`
    /// ([`crate::registration::read_structure`]); kept in the set-up, which registers them.
    #[serde(default)]
    pub structures: Vec<PathBuf>,
    /// Tetrahedra of the organ's mesh (about).
    pub tets: usize,
    /// FEM draws of the dataset.
    pub samples: usize,
    /// The learned model: the reduced-order model or the U-Net.
    pub method: learn::Method,
    /// Seed of the draws and the training.
    pub seed: u64,
}

/// Tetrahedra of an organ's mesh, unless given.
pub const DEFAULT_TETS: usize = 3000;

/// FEM draws of an organ's dataset, unless given.
pub const DEFAULT_SAMPLES: usize = 2000;

impl PrepareOptions {
    /// The options with the defaults for what is not given: held near the landmarks over
    /// [`HELD_SHARE`] of the organ's surface, 3,000 tetrahedra, 2,000 draws, the reduced-order model, seed 2.
    pub fn new(surface: PathBuf, camera: impl Into<CameraAt>, attach: PathBuf, targets: PathBuf) -> PrepareOptions {
        PrepareOptions {
            surface,
            label: None,
            units: None,
            frame: None,
            camera: camera.into(),
            attach,
            attach_distance: None,
            targets,
            structures: Vec::new(),
            tets: DEFAULT_TETS,
            samples: DEFAULT_SAMPLES,
            method: learn::Method::Rom,
            seed: 2,
        }
    }
}

/// Arguments of `augsim prepare`.
#[derive(Debug, clap::Args)]
pub struct PrepareArgs {
    /// The segmented organ: a surface (.stl, .obj, .ply, .vtk, .vtp, .vtu) as a segmentation gives it (holes,
    /// duplicated vertices and flipped triangles are repaired; what local repair cannot mend is
    /// rebuilt through voxels), or a labelmap (.nii, .nii.gz from TotalSegmentator, .seg.nrrd
    /// from 3D Slicer, .nrrd, .nhdr, .mha, .mhd, a DICOM SEG or RTSTRUCT; in mm, in the scanner's frame the file states, RAS or LPS).
    pub surface: PathBuf,
    /// The labelmap's label: a number (TotalSegmentator's liver is 5) or a segment name (3D
    /// Slicer's); needed when it holds several. `1+2` takes labels 1 and 2 together (a liver and
    /// the tumour labelled apart in it).
    #[arg(long)]
    pub label: Option<String>,
    /// Where the laparoscope looks from: X,Y,Z in the surface's unit and frame (a labelmap's: mm,
    /// its scanner frame), or a points file of one point (.csv, 3D Slicer's .fcsv or .mrk.json).
    #[arg(long, value_parser = CameraAt::parse, allow_hyphen_values = true)]
    pub camera: CameraAt,
    /// Landmarks where the organ is held (ligaments, the hilum): CSV with a header x, y, z, or
    /// 3D Slicer's .fcsv or .mrk.json (in the frame and unit they name).
    #[arg(long, value_name = "LANDMARKS")]
    pub attach: PathBuf,
    /// Surface nodes within this distance of a landmark are held, with its unit (25mm) [default:
    /// the distance that holds 12 % of the organ's surface, as SOFA's liver scenario does]
    #[arg(long, value_name = "DISTANCE")]
    pub attach_distance: Option<Length>,
    /// The targets at rest (tumour, vessels): CSV with a header x, y, z, or .fcsv or .mrk.json
    /// (their labels are kept).
    #[arg(long, value_name = "TARGETS")]
    pub targets: PathBuf,
    /// A structure inside the organ (a tumour, vessels) that the set-up's registrations give back
    /// moved with it: a surface (in the surface's unit and frame, else those its header names) or
    /// LABELMAP:LABEL (Segmentation.seg.nrrd:tumour). Repeat for several.
    #[arg(long = "structure", value_name = "SURFACE")]
    pub structures: Vec<PathBuf>,
    /// Output directory (resumed when it holds a preparation of the same inputs).
    #[arg(short, long)]
    pub out: PathBuf,
    /// Unit of the surface, camera, landmarks and targets: mm, cm, m, um, or auto (told from the
    /// surface's size; a labelmap's is the one its header names, else mm).
    #[arg(long, default_value = "auto", value_parser = mesh::length::parse_unit_or_auto)]
    pub units: mesh::length::UnitOrAuto,
    /// Frame (RAS or LPS) of the inputs whose files name none: a surface without a SPACE= tag
    /// (3D Slicer writes one), CSV points [default: the one the first file naming one names]
    #[arg(long)]
    pub frame: Option<Frame>,
    /// FEM draws of the dataset.
    #[arg(long, default_value_t = DEFAULT_SAMPLES)]
    pub samples: usize,
    /// The learned model: rom (the reduced-order model) or unet.
    #[arg(long, default_value = "rom")]
    pub method: learn::Method,
    /// Tetrahedra of the organ's mesh (about).
    #[arg(long, default_value_t = DEFAULT_TETS)]
    pub tets: usize,
}

impl CameraAt {
    /// `X,Y,Z` as three finite numbers, or else a file.
    pub fn parse(text: &str) -> Result<CameraAt, String> {
        let values: Vec<f64> = match text.split(',').map(|v| v.trim().parse::<f64>()).collect() {
            Ok(values) => values,
            Err(_) if std::path::Path::new(text).is_file() => return Ok(CameraAt::File(PathBuf::from(text))),
            Err(e) => return Err(format!("expected X,Y,Z or a points file, got {text:?} ({e})")),
        };
        if values.iter().any(|v| !v.is_finite()) {
            return Err(format!("expected X,Y,Z as finite numbers, got {text:?}"));
        }
        <[f64; 3]>::try_from(values).map(CameraAt::Point).map_err(|v| format!("expected X,Y,Z, got {} values", v.len()))
    }
}

impl PrepareArgs {
    /// The preparation's options.
    pub fn options(&self) -> PrepareOptions {
        PrepareOptions {
            label: self.label.clone(),
            units: self.units,
            frame: self.frame,
            structures: self.structures.clone(),
            attach_distance: self.attach_distance,
            samples: self.samples,
            method: self.method,
            tets: self.tets,
            ..PrepareOptions::new(self.surface.clone(), self.camera.clone(), self.attach.clone(), self.targets.clone())
        }
    }
}

/// Where the camera is: a point, or a points file holding one (CSV, `.fcsv`, `.mrk.json`, in the
/// frame and unit it names, else the surface's).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum CameraAt {
    /// The point, in the surface's unit and frame.
    Point(Point),
    /// A file of one point.
    File(PathBuf),
}

impl CameraAt {
    /// The file it is read from, if any.
    pub fn file(&self) -> Option<&Path> {
        match self {
            CameraAt::File(path) => Some(path),
            CameraAt::Point(_) => None,
        }
    }
}

impl From<Point> for CameraAt {
    fn from(p: Point) -> CameraAt {
        CameraAt::Point(p)
    }
}

/// One step done.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StepRecord {
    /// The step's name.
    pub name: String,
    /// Its wall time (s).
    pub seconds: f64,
    /// What it did, one line each.
    pub lines: Vec<String>,
}

/// `prepare.json`: the inputs and the steps done.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PrepareState {
    /// `augsim-prepare`.
    pub format: String,
    /// The inputs, with paths made absolute.
    pub options: PrepareOptions,
    /// The steps done, in order.
    pub steps: Vec<StepRecord>,
    /// The frame the inputs were given in, as the organ step found it (`None` when none names
    /// one): the frame of clouds and results whose files name none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub input_frame: Option<Frame>,
    /// The unit the inputs were given in, as the organ step found it: the unit of clouds and
    /// results whose files name none (`None` in a preparation recorded before it was kept).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub input_unit: Option<LengthUnit>,
    /// A digest ([`learn::digest`]) of each input file, by path: a file changed since is not
    /// taken for the one prepared from (empty in a preparation recorded before they were kept).
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub input_digests: BTreeMap<PathBuf, String>,
}

impl PrepareState {
    /// The time of the steps done (s), over every run.
    pub fn seconds(&self) -> f64 {
        self.steps.iter().map(|s| s.seconds).sum()
    }
}

/// A structure's surface in the set-up (mm, the organ's frame), relative to its directory.
fn structure_file(name: &str) -> String {
    format!("structures/{name}.stl")
}

/// The organ's Young's modulus (Pa) in the set-up's training draws and the validation's truth
/// (Neo-Hookean).
const ORGAN_YOUNG: f64 = 5000.0;

/// The organ's Poisson's ratio in the set-up's training draws and the validation's truth.
const ORGAN_POISSON: f64 = 0.49;

/// The steps, in order.
pub const STEPS: [&str; 7] = ["organ", "scenarios", "dataset", "model", "evaluation", "validation", "report"];

/// What a preparation tells its user as it goes: the steps as they start, on top of the lines of
/// what each step did and the advance of its dataset's draws and its training
/// ([`learn::Progress`]).
pub trait PrepareProgress: learn::Progress {
    /// A step starts (`index` of [`STEPS`]).
    fn step(&self, index: usize, name: &str);
}

/// Prepares the organ of `options` into `dir` (see the module documentation); resumes after the
/// steps already done there. Returns the record of every step. A `dir` this call made is removed
/// again when it fails before writing into it.
pub fn prepare(options: &PrepareOptions, dir: &Path, progress: &dyn PrepareProgress) -> Result<PrepareState> {
    let made = !dir.exists();
    crate::output::tidy_failed_run(dir, made, prepare_steps(options, dir, progress))
}

/// [`prepare`]'s steps.
fn prepare_steps(options: &PrepareOptions, dir: &Path, progress: &dyn PrepareProgress) -> Result<PrepareState> {
    let options = absolute(options)?;
    let inputs: Vec<&Path> = [&options.surface, &options.attach, &options.targets]
        .into_iter()
        .chain(&options.structures)
        .map(PathBuf::as_path)
        .chain(options.camera.file())
        .collect();
    crate::output::refuse_inputs_inside(dir, &inputs)?;
    // A folder of other files is no place for a set-up, whose files would replace theirs.
    if !dir.join(STATE_FILE).exists() {
        crate::output::refuse_used_folder(dir)?;
    }
    mesh::io::create_folder(dir)?;
    // What a killed run left half-written goes: its step is done again.
    mesh::io::remove_stale_temporaries(dir);
    let state_path = dir.join(STATE_FILE);
    let digests = input_digests(&inputs)?;
    let mut state = if state_path.exists() {
        let mut state: PrepareState = serde_json::from_str(&std::fs::read_to_string(&state_path)?)
            .with_context(|| format!("reading {}", state_path.display()))?;
        if state.options != options {
            bail!(
                "{} was prepared from other inputs ({}: {}); give another --out, or remove it to start again",
                dir.display(),
                state_path.display(),
                learn::json_differences(&serde_json::to_value(&state.options)?, &serde_json::to_value(&options)?)
                    .join("; ")
            );
        }
        let changed: Vec<String> = state
            .input_digests
            .iter()
            .filter(|(path, digest)| digests.get(*path) != Some(*digest))
            .map(|(path, _)| path.display().to_string())
            .collect();
        if !changed.is_empty() {
            bail!(
                "{} was prepared from other inputs: {} changed since; give another --out, or remove it to start again",
                dir.display(),
                changed.join(", ")
            );
        }
        state.input_digests = digests;
        // Recorded before the inputs' unit was kept: the organ step finds it again for the scenarios.
        if state.input_unit.is_none() && !state.steps.iter().any(|s| s.name == "scenarios") {
            state.steps.retain(|s| s.name != "organ");
        }
        state
    } else {
        let (steps, input_frame, input_unit, input_digests) = (Vec::new(), None, None, digests);
        let format = "augsim-prepare".into();
        let state = PrepareState { format, options: options.clone(), steps, input_frame, input_unit, input_digests };
        // Written before any step, so that the folder is known as this preparation's if it stops.
        write_atomic_bytes(&state_path, serde_json::to_string_pretty(&state)?.as_bytes())?;
        state
    };
    for (index, name) in STEPS.iter().enumerate() {
        // The report is written anew at every run; the other steps once.
        if let Some(done) = state.steps.iter().find(|s| s.name == *name && *name != "report") {
            progress.line(&format!("{name}: done before ({:.1} s), kept", done.seconds));
            continue;
        }
        state.steps.retain(|s| s.name != *name);
        progress.step(index, name);
        let start = Instant::now();
        let lines = match index {
            0 => {
                let (lines, given, unit) = organ_step(&options, dir)?;
                (state.input_frame, state.input_unit) = (given, Some(unit));
                lines
            }
            1 => {
                let unit = state.input_unit.context("the inputs' unit is not recorded")?;
                scenarios_step(&options, (state.input_frame, unit), dir)?
            }
            2 => dataset_step(dir, progress)?,
            3 => model_step(&options, dir, progress)?,
            4 => evaluation_step(dir)?,
            5 => validation::validation_step(&options, dir, progress)?,
            _ => report_step(&state, dir)?,
        };
        lines.iter().for_each(|l| progress.line(l));
        state.steps.push(StepRecord { name: name.to_string(), seconds: start.elapsed().as_secs_f64(), lines });
        write_atomic_bytes(&state_path, serde_json::to_string_pretty(&state)?.as_bytes())?;
    }
    Ok(state)
}

/// A digest ([`learn::digest`]) of each of the `inputs` that is a file, by path.
fn input_digests(inputs: &[&Path]) -> Result<BTreeMap<PathBuf, String>> {
    inputs
        .iter()
        .filter(|path| path.is_file())
        .map(|path| {
            let bytes = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
            Ok((path.to_path_buf(), learn::digest(&bytes)))
        })
        .collect()
}

/// The options with their files' paths absolute (the record must not depend on where the
/// program runs) and checked.
fn absolute(options: &PrepareOptions) -> Result<PrepareOptions> {
    let full = |p: &Path| std::path::absolute(p).with_context(|| format!("resolving {}", p.display()));
    let camera = options.camera.file().map(|path| ("camera", path));
    let files = [("surface", &options.surface), ("landmarks", &options.attach), ("targets", &options.targets)]
        .map(|(what, path)| (what, path.as_path()));
    if options.surface.is_dir() {
        // What a folder holds (a DICOM series, a SEG among its files) and what to give instead.
        let why = mesh::labelmap::unreadable_segmentation(&options.surface).unwrap_or_default();
        bail!("{}: {why}", options.surface.display());
    }
    for (what, path) in files.into_iter().chain(camera) {
        if path.is_dir() {
            bail!("the {what} file {} is a folder, not a file", path.display());
        }
        if !path.is_file() {
            bail!("the {what} file {} does not exist", path.display());
        }
    }
    if let Some(distance) = options.attach_distance.filter(|d| !(d.in_metres() > 0.0)) {
        bail!("the attachment distance must be positive, got {distance}");
    }
    if options.samples < 10 {
        bail!("{} draws are too few to train and test a model (at least 10)", options.samples);
    }
    Ok(PrepareOptions {
        surface: full(&options.surface)?,
        attach: full(&options.attach)?,
        targets: full(&options.targets)?,
        structures: options.structures.iter().map(|s| absolute_structure(s)).collect::<Result<_>>()?,
        camera: match &options.camera {
            CameraAt::File(path) => CameraAt::File(full(path)?),
            at => at.clone(),
        },
        ..options.clone()
    })
}

/// The organ's inputs in the set-up's frame (see [`crate::points`]): the surface in its file's
/// `unit` (it is repaired there, so that what the repair reports is in that unit), the points in
/// metres.
struct Inputs {
    surface: mesh::TriSurface,
    unit: LengthUnit,
    /// The unit of the points given (and of the clouds to come) whose files name none: the one
    /// given, else the surface's (a labelmap's surface is in mm whatever unit its voxels were read in).
    points_unit: LengthUnit,
    landmarks: LabelledPoints,
    targets: LabelledPoints,
    camera: Point,
    /// The frame they were given in: the surface's, or, when its header names none, the first
    /// named by the points' files; they are in [`SET_UP_FRAME`] when it is named.
    given: Option<Frame>,
    /// The frame the surface's file names, if any.
    named_frame: Option<Frame>,
}

/// Reads the surface in its unit (given or detected) and frame, and the landmarks, the targets
/// and the camera, each in the unit and frame its file names, else the unit given (the surface's
/// when none is) and the surface's frame; all brought to
/// the set-up's frame ([`SET_UP_FRAME`] where any input names one), the points to metres.
fn read_inputs(options: &PrepareOptions, lines: &mut Vec<String>) -> Result<Inputs> {
    let (surface, named_frame, unit) = read_surface_input(options, lines)?;
    let surface_frame = named_frame.or(options.frame);
    let points_unit = options.units.unwrap_or(unit);
    let mut input = PointInput::new(surface_frame, LengthUnit::Metre, points_unit).with_given_frame(options.frame);
    // Each error of a points file names the file.
    let landmarks = input.read(&options.attach)?;
    let targets = input.read(&options.targets)?;
    crate::points::check_targets(&options.targets, &targets)?;
    let camera = match &options.camera {
        CameraAt::Point(p) => points_unit.point_to_metres(*p),
        CameraAt::File(path) => match input.read(path)?.points.as_slice() {
            [p] => *p,
            other => bail!("{}: the camera is one point, the file holds {}", path.display(), other.len()),
        },
    };
    let given = input.frame;
    let set_up = match given {
        Some(f) if f != SET_UP_FRAME => format!(", set up in {SET_UP_FRAME} (x and y negated)"),
        _ => String::new(),
    };
    lines.push(match (named_frame, given) {
        (Some(f), _) => format!("frame: {f} (named by {}){set_up}", options.surface.display()),
        (None, Some(f)) if options.frame.is_some() => {
            format!("frame: {f} (given; the surface's header names none){set_up}")
        }
        (None, Some(f)) => format!("frame: {f} (named by the points' files; the surface's header names none){set_up}"),
        (None, None) => "frame: not named by any input (SPACE= header, .fcsv, .mrk.json): all taken as given".into(),
    });
    lines.extend(input.warnings.iter().map(|w| format!("warning: {w}")));
    let mut inputs = Inputs { surface, unit, points_unit, landmarks, targets, camera, given, named_frame };
    if let Some(from) = given {
        inputs.convert(from, SET_UP_FRAME);
    }
    Ok(inputs)
}

impl Inputs {
    /// Every point brought from frame `from` to `to`.
    fn convert(&mut self, from: Frame, to: Frame) {
        from.convert_all(to, &mut self.surface.vertices);
        from.convert_all(to, &mut self.landmarks.points);
        from.convert_all(to, &mut self.targets.points);
        self.camera = from.convert(to, self.camera);
    }

    /// The frame they are in: [`SET_UP_FRAME`] when one was named.
    fn frame(&self) -> Option<Frame> {
        self.given.map(|_| SET_UP_FRAME)
    }
}

/// Why the first target outside the organ's mesh (the one its error names) lies there when it
/// lies inside the organ's surface (m): the part around it was left out of the mesh; `None` when
/// it lies outside the surface too.
fn thin_part_left_out(surface: &TriSurface, organ: &register::Organ, targets: &[Point]) -> Option<String> {
    let bvh = mesh::SurfaceBvh::new(surface).ok()?;
    // The first outside the mesh, which the error names.
    let first = targets.iter().find(|&&p| organ.locate(&[p], "target").is_err())?;
    bvh.is_inside(*first).then(|| {
        "it lies inside the organ's surface, in a part thinner than the tetrahedra that the mesh leaves out: \
         mesh finer (--tets)"
            .to_string()
    })
}

/// A camera farther from the organ than this many times its size (its box's diagonal) is warned
/// about: a unit mistake (a camera in mm read as m lies 1,000 times too far).
const FAR_CAMERA: f64 = 10.0;

/// The warning for a camera farther from `organ` than [`FAR_CAMERA`] times its size (`unit`: the
/// one the camera was read in).
fn far_camera(organ: &mesh::Mesh, camera: Point, unit: LengthUnit) -> Option<String> {
    let (lo, hi) = organ.bounds();
    let size = mesh::norm(mesh::sub(hi, lo));
    let nearest = organ.nodes.iter().map(|&p| mesh::distance(p, camera)).fold(f64::INFINITY, f64::min);
    (nearest > FAR_CAMERA * size).then(|| {
        format!(
            "warning: the camera at {} lies {:.0} mm from the organ, {:.0} times its size ({:.0} mm): a laparoscope \
             or a depth camera is centimetres to a metre away; is it given in the inputs' unit ({})?",
            point_in_mm(camera),
            mm(nearest),
            nearest / size,
            mm(size),
            unit.symbol()
        )
    })
}

/// A warning when `camera` (in the set-up's frame, LPS) lies behind the organ, more towards the
/// patient's back than to any side of it: a laparoscope, an open view or a depth camera looks from
/// the front; the same numbers in the other frame (x and y negated) put it there. `read`: the
/// frame the inputs were given in; `given`: how the camera was given (typed numbers are taken in
/// the surface's frame).
fn camera_behind(organ: &Mesh, camera: Point, read: Frame, given: &CameraAt) -> Option<String> {
    let (lo, hi) = organ.bounds();
    let centre: Point = std::array::from_fn(|d| 0.5 * (lo[d] + hi[d]));
    let towards = mesh::sub(camera, centre);
    // LPS: +y is posterior.
    (towards[1] > 0.0 && towards[1] > towards[0].abs().max(towards[2].abs())).then(|| {
        let typed = match given {
            CameraAt::Point(_) => format!(", typed on the command line: taken in the surface's frame, {}", read.name()),
            CameraAt::File(_) => String::new(),
        };
        let mirrored = [-camera[0], -camera[1], camera[2]];
        format!(
            "warning: the camera at {} (set-up's {}) lies behind the organ, {:.0} mm towards the patient's back from \
             its centre{typed}; a laparoscope or an open view looks from the front: in the other frame (x and y \
             negated) it lies in front, at {}; is it given in the surface's frame?",
            point_in_mm(camera),
            SET_UP_FRAME.name(),
            mm(towards[1]),
            point_in_mm(mirrored)
        )
    })
}

/// A warning when the camera at `camera` sees most of the `attached` nodes where the camera of the
/// other frame (x and y negated) would see under half as many: an organ is held at its back, away
/// from the laparoscope, so a camera given in the other frame than the surface's is the likely
/// cause (a ligament in view is not warned about unless the other frame's camera explains it);
/// `shown`: what frame the positions are in, when not the files'.
fn camera_sees_the_hold(
    organ: &Mesh,
    camera: Point,
    (visible, attached): (&[usize], &[usize]),
    shown: &str,
) -> Result<Option<String>> {
    let seen = |nodes: &[usize]| attached.iter().filter(|n| nodes.contains(n)).count();
    let here = seen(visible);
    if 2 * here <= attached.len() {
        return Ok(None);
    }
    let mirrored = [-camera[0], -camera[1], camera[2]];
    let there = seen(&Camera { view: None, position: Some(mirrored), max_angle_deg: 90.0 }.seen_nodes(organ)?);
    Ok((2 * there < here).then(|| {
        format!(
            "warning: the camera at {} sees {here} of the {} held nodes, where the organ is held away from it; given \
             in the other frame (RAS for LPS: x and y negated, at {}), it would see {there}: is the camera in the \
             surface's frame?{shown}",
            point_in_mm(camera),
            attached.len(),
            point_in_mm(mirrored)
        )
    }))
}

/// Step 1: the surface repaired and meshed, the regions selected, the targets located.
/// Returns what it did and the frame its inputs were given in.
fn organ_step(options: &PrepareOptions, dir: &Path) -> Result<(Vec<String>, Option<Frame>, LengthUnit)> {
    let mut lines = Vec::new();
    let (frame, unit) = organ_lines(options, dir, &mut lines).map_err(|e| {
        // The step's lines are said only once it is done: its warnings go with its error. One
        // that doubts the organ itself (a unit that makes no organ's size, an organ cut by the
        // image's border) is often the error's cause, and comes first. Which label of a labelmap
        // was read may be too (a number that names a segment of another layer than the one meant).
        let (doubts, others): (Vec<&str>, Vec<&str>) =
            lines.iter().filter_map(|l| l.strip_prefix("warning: ")).partition(|w| is_organ_doubt(w));
        // The others come after the error, which they may have nothing to do with.
        let e = match others.is_empty() {
            true => e,
            false => anyhow::anyhow!("{e:#} (warned as the organ was read, besides: {})", others.join("; ")),
        };
        let e = match doubts.is_empty() {
            true => e,
            false => e.context(format!("{} (likely the cause of what follows)", doubts.join("; "))),
        };
        let read = lines.iter().find_map(|l| l.strip_prefix("labelmap: ").filter(|l| l.starts_with("label")));
        match read.and_then(|l| l.split_once("): ")) {
            Some((label, _)) => e.context(format!("the organ read from the labelmap's {label})")),
            None => e,
        }
    })?;
    Ok((lines, frame, unit))
}

/// Whether a warning doubts the organ itself: the unit of the inputs (an organ's size in it), an
/// organ cut by the image's border (targets and regions in the part cut off), or one placed nowhere
/// (a labelmap without its place in the scanner's frame).
fn is_organ_doubt(warning: &str) -> bool {
    ["unit", "the image's border", "places its voxels nowhere"].iter().any(|doubt| warning.contains(doubt))
}

/// [`organ_step`], its lines said in `lines` as they come.
fn organ_lines(options: &PrepareOptions, dir: &Path, lines: &mut Vec<String>) -> Result<(Option<Frame>, LengthUnit)> {
    let inputs = read_inputs(options, lines)?;
    let frame = inputs.frame();
    let Inputs {
        surface,
        unit,
        points_unit,
        landmarks: labelled_landmarks,
        targets: labelled_targets,
        camera,
        given,
        named_frame,
    } = inputs;
    let mut notes = Vec::new();
    let meshed =
        mesh_organ_surface(&options.surface, surface, ToMetres::FromUnit(unit), options.tets, true, &mut notes);
    lines.extend(note_lines(&notes));
    let OrganMesh { surface, mesh: mut organ, quality } = meshed?;
    let landmarks = labelled_landmarks.points.clone();
    let targets = labelled_targets.points.clone();
    let [x, y, z] = extent(&organ).map(mm);
    lines.push(format!(
        "mesh: {} nodes, {} T4 (dihedral angles {:.1}–{:.1}°), {x:.0} × {y:.0} × {z:.0} mm",
        organ.num_nodes(),
        organ.cells.len(),
        quality.min_dihedral_deg,
        quality.max_dihedral_deg,
    ));
    lines.extend(tet_mesh_warnings(&quality).into_iter().map(|w| format!("warning: {w}")));
    // A laparoscope looks at the organ from outside it.
    if mesh::SurfaceBvh::new(&surface).is_ok_and(|bvh| bvh.is_inside(camera)) {
        bail!(
            "the camera at {} lies inside the organ: give where the laparoscope looks from, outside it (in the \
             surface's unit and frame)",
            point_in_mm(camera)
        );
    }
    let visible = Camera { view: None, position: Some(camera), max_angle_deg: 90.0 }.seen_nodes(&organ)?;
    if visible.is_empty() {
        bail!(
            "the camera at {} sees no node of the organ: is it given in the surface's unit and frame?",
            point_in_mm(camera)
        );
    }
    lines.extend(far_camera(&organ, camera, points_unit));
    if let Some(read) = given {
        lines.extend(camera_behind(&organ, camera, read, &options.camera));
    }
    let located = register::Organ::new(organ.clone(), None)?;
    // Positions in messages are the set-up's; say so where the files' differ.
    let shown = match given.filter(|&f| f != SET_UP_FRAME) {
        Some(read) => format!(
            " (positions in the set-up's {} frame: x and y negated from the {} the file was read in)",
            SET_UP_FRAME.name(),
            read.name()
        ),
        None => String::new(),
    };
    let landmark_warnings = located
        .check_landmarks(&landmarks, &labelled_landmarks.labels)
        .with_context(|| format!("the landmarks of {}{shown}", options.attach.display()))?;
    let (attached, regions) = held_nodes(options, &organ, &landmarks, &visible)?;
    lines.push(regions);
    lines.extend(landmark_warnings.into_iter().map(|w| format!("warning: {w}")));
    lines.extend(camera_sees_the_hold(&organ, camera, (&visible, &attached), &shown)?);
    let (_, warnings) = located.locate_targets(&targets, &labelled_targets.labels).map_err(|e| {
        let context = format!("the targets of {}{shown}", options.targets.display());
        match thin_part_left_out(&surface, &located, &targets) {
            Some(why) => anyhow::anyhow!("{e}: {why}").context(context),
            None => anyhow::Error::from(e).context(context),
        }
    })?;
    lines.push(format!("targets: {} inside the organ", targets.len()));
    lines.extend(warnings.into_iter().map(|w| format!("warning: {w}")));
    let mut names: Vec<String> = Vec::new();
    for source in &options.structures {
        let context = || format!("the structure {}", source.display());
        let read = read_structure(source, unit, given, frame).with_context(context)?;
        let taken: Vec<&str> = names.iter().map(String::as_str).collect();
        register::registration::check_structure_name(&read.name, &taken).with_context(context)?;
        // In the organ's frame as a registration takes it, or where both are one labelmap's.
        let organ_file = |path: &Path| path.canonicalize().ok() == options.surface.canonicalize().ok();
        let embed =
            match read.in_organ_frame(named_frame.is_some()) || structure_labelmap(source).is_some_and(organ_file) {
                true => register::Structure::in_organ_frame,
                false => register::Structure::new,
            };
        let (embedded, warnings) = embed(&located, &read.name, read.surface).with_context(context)?;
        let file = structure_file(&read.name);
        write_surface_in_mm(&dir.join(&file), embedded.rest(), frame)?;
        lines.push(format!("structure: {}, {} vertices, {file}", read.name, embedded.rest().vertices.len()));
        lines.extend(read.warnings.into_iter().chain(warnings).map(|w| format!("warning: {w}")));
        names.push(read.name);
    }
    organ.regions.insert("visible".into(), visible);
    organ.regions.insert("attached".into(), attached);
    // In millimetres, for 3D Slicer (which shows it over the CT where the frame is named).
    write_surface_in_mm(&dir.join(SURFACE_FILE), &surface, frame)?;
    // The regions as point data `region_visible`, `region_attached` (ParaView shows them; the
    // mesh reads them back).
    mesh::io::write_mesh_in_frame(dir.join("organ.vtu"), &organ, &[], frame)?;
    // In metres, in the organ's frame, with their labels: what `register` reads back.
    write_points(dir.join("attach.csv"), &LabelledPoints { frame, ..labelled_landmarks })?;
    write_points(dir.join("targets.csv"), &LabelledPoints { frame, ..labelled_targets })?;
    let camera = LabelledPoints { frame, unit: Some(LengthUnit::Metre), ..LabelledPoints::new(vec![camera]) };
    write_points(dir.join("camera.csv"), &camera)?;
    Ok((given, points_unit))
}

/// The organ's surface in its own unit, with its frame and unit ([`OrganInput`]).
fn read_surface_input(
    options: &PrepareOptions,
    lines: &mut Vec<String>,
) -> Result<(TriSurface, Option<Frame>, LengthUnit)> {
    let path = &options.surface;
    let mut input = OrganInput::read(path, options.label.as_deref(), options.units)?;
    let unit = input.unit().with_context(|| format!("the unit of {}", path.display()))?;
    lines.extend(crate::meshing::note_lines(&input.notes));
    Ok((input.surface, input.frame, unit))
}

/// The grid of the network's input and output: 32 nodes along the organ's longest side (about
/// 6 mm apart on a liver), at least as fine along the others, each count a multiple of 8 (the
/// U-Net halves it three times).
fn grid_for(organ: &Mesh) -> [usize; 3] {
    let extent = extent(organ);
    let longest = extent.iter().copied().fold(0.0, f64::max);
    std::array::from_fn(|d| ((32.0 * extent[d] / longest / 8.0).ceil() as usize).max(1) * 8)
}

/// The sides of `organ`'s bounding box (m).
fn extent(organ: &Mesh) -> [f64; 3] {
    let (lo, hi) = organ.bounds();
    std::array::from_fn(|d| hi[d] - lo[d])
}

/// The longest side of `organ`'s bounding box (m).
fn longest_side(organ: &Mesh) -> f64 {
    mesh::longest_side(organ.bounds())
}

/// The tool's footprint on `organ`: 3 cm on the phantom's 21 cm, in proportion to its longest side.
fn tool_radius(organ: &Mesh) -> f64 {
    0.03 * longest_side(organ) / 0.21
}

/// Two unit directions across a line of sight along the unit vector `axis`, square to it and to
/// each other.
fn across_sight(axis: Point) -> (Point, Point) {
    let helper = if axis[2].abs() < 0.9 { [0.0, 0.0, 1.0] } else { [1.0, 0.0, 0.0] };
    let u = mesh::unit(mesh::cross(helper, axis));
    (u, mesh::cross(axis, u))
}

/// The organ's name: its file's name without the extension (.seg.nrrd and .nii.gz whole).
fn organ_name(path: &Path) -> String {
    let file = path.file_name().map_or(String::new(), |n| n.to_string_lossy().into_owned());
    let lower = file.to_ascii_lowercase();
    let cut = [".seg.nrrd", ".nii.gz"].iter().find(|e| lower.ends_with(*e)).map(|e| file.len() - e.len());
    let name = match cut {
        Some(end) => file[..end].to_string(),
        None => path.file_stem().map_or(String::new(), |s| s.to_string_lossy().into_owned()),
    };
    if name.is_empty() {
        "organ".into()
    } else {
        name
    }
}

/// The surface nodes of `organ` held near its `landmarks` (within the distance given or chosen)
/// and the line that says them beside the nodes the camera sees (`visible`); an error where none
/// is held, or every node seen is (the tool would have nothing to push).
fn held_nodes(
    options: &PrepareOptions,
    organ: &Mesh,
    landmarks: &[Point],
    visible: &[usize],
) -> Result<(Vec<usize>, String)> {
    let distance = hold_distance(options, organ, landmarks)?;
    let attached = Near { points: landmarks.to_vec(), file: None, distance, surface: true }.nodes(organ)?;
    if attached.is_empty() {
        bail!(
            "no surface node lies within {} mm of the landmarks of {}: are they in the surface's unit and frame?",
            mm(distance),
            options.attach.display()
        );
    }
    // The boundary nodes are those with a share of the surface: one pass over its faces.
    let area = mesh::boundary_node_areas(organ);
    let boundary = area.iter().filter(|&&a| a > 0.0).count();
    let held_share = attached.iter().map(|&n| area[n]).sum::<f64>() / area.iter().sum::<f64>();
    let mut held = vec![false; organ.num_nodes()];
    attached.iter().for_each(|&n| held[n] = true);
    if visible.iter().all(|&n| held[n]) {
        let given = if options.attach_distance.is_some() { "--attach-distance " } else { "" };
        bail!(
            "the organ is held within {given}{:.1} mm of its landmarks, {:.0} % of its surface, every node the \
             camera sees among them: nothing is left free for the tool to push; give a smaller --attach-distance",
            mm(distance),
            100.0 * held_share
        );
    }
    let line = format!(
        "regions: the camera sees {} of {boundary} surface nodes; {} held within {:.1} mm of {} landmarks, {:.0} % of \
         its surface",
        visible.len(),
        attached.len(),
        mm(distance),
        landmarks.len(),
        100.0 * held_share
    );
    Ok((attached, line))
}

/// The share of the organ's surface held near its landmarks by default: what SOFA's liver
/// scenario holds (25 mm around its four ligaments), whatever the organ's size. A fixed distance
/// holds a large organ by a smaller part of itself, and it swings from it.
pub const HELD_SHARE: f64 = 0.12;

/// The distance (m) from the landmarks within which `organ`'s surface nodes are held: the one
/// given, or the one that holds [`HELD_SHARE`] of its surface.
fn hold_distance(options: &PrepareOptions, organ: &Mesh, landmarks: &[Point]) -> Result<f64> {
    match options.attach_distance {
        Some(distance) => Ok(distance.in_metres()),
        None => Ok(mesh::distance_holding_share(organ, landmarks, HELD_SHARE)?),
    }
}

/// The camera position a set-up's `camera.csv` in `dir` holds.
fn read_camera(dir: &Path) -> Result<Point> {
    let path = dir.join("camera.csv");
    read_points_csv(&path)?.first().copied().with_context(|| {
        format!(
            "{} holds no point (the camera position `prepare` wrote there): prepare the organ again",
            path.display()
        )
    })
}

/// Step 2: the scenario files.
fn scenarios_step(
    options: &PrepareOptions,
    (input_frame, input_unit): (Option<Frame>, LengthUnit),
    dir: &Path,
) -> Result<Vec<String>> {
    let organ = mesh::io::read_mesh(dir.join("organ.vtu"))?;
    let camera = read_camera(dir)?;
    let [nx, ny, nz] = grid_for(&organ);
    let radius = tool_radius(&organ);
    let name = organ_name(&options.surface);
    let camera_toml = format!("{{ facing = {{ position = [{}, {}, {}] }} }}", camera[0], camera[1], camera[2]);
    let distance = hold_distance(options, &organ, &read_points_csv(&dir.join("attach.csv"))?)?;
    let held = format!("{{ near = {{ file = \"attach.csv\", distance = {distance}, surface = true }} }}");
    let dataset = format!(
        "# The organ of {surface}, as `augsim prepare` set it up: a tool pushing what the camera\n\
         # sees, the organ held near the landmarks of attach.csv; the input is the visible surface's\n\
         # displacement along its normal (what a camera's point cloud measures). Edit and rerun\n\
         # `augsim generate` and `augsim train` to change it.\n\
         kind = \"dataset\"\n\
         name = \"{name}\"\n\
         description = \"{name}: {tets} T4, Neo-Hookean, nu = {ORGAN_POISSON}, a tool pushing the visible surface\"\n\n\
         [mesh.file]\npath = \"organ.vtu\"\n\n\
         [material]\nlaw = \"neo_hookean\"\nyoung = {ORGAN_YOUNG:?}\npoisson = {ORGAN_POISSON}\n\n\
         [dataset]\nsamples = {samples}\nseed = {seed}\nshard_size = 100\ngrid = [{nx}, {ny}, {nz}]\n\
         fixed = [{held}]\n\
         input = {{ displacement = {{ nodes = {camera_toml}, normal = true }} }}\n\n\
         [dataset.load.patch_force]\ncentres = {camera_toml}\nradius = {radius:.4}\nmagnitude = [0.5, 3.5]\ncone = 90.0\n\n\
         [solver]\nmax_step_cuts = 4\n",
        surface = options.surface.display(),
        tets = organ.cells.len(),
        samples = options.samples,
        seed = options.seed,
    );
    let fem = format!(
        "# The FEM registration of the organ of {surface}: co-rotational tetrahedra, held near the\n\
         # landmarks of attach.csv.\n\
         kind = \"static\"\nname = \"{name}_fem\"\n\n\
         [mesh.file]\npath = \"organ.vtu\"\n\n\
         [material]\nlaw = \"corotational\"\nyoung = 5000.0\npoisson = 0.48\n\n\
         [[fixed]]\nselect = {held}\n",
        surface = options.surface.display(),
    );
    let patient = Patient {
        method: PatientMethod::Learned,
        model: "model".into(),
        scenario: "dataset.toml".into(),
        fem: "static.toml".into(),
        targets: "targets.csv".into(),
        units: LengthUnit::Metre,
        input_units: Some(input_unit),
        input_frame,
        structures: options.structures.iter().map(|s| structure_file(&structure_name(s)).into()).collect(),
        sigma: SigmaFactors::default(),
    };
    write_atomic_bytes(&dir.join("dataset.toml"), dataset.as_bytes())?;
    write_atomic_bytes(&dir.join("static.toml"), fem.as_bytes())?;
    patient.write(dir)?;
    let mut lines = vec![format!(
        "scenarios: dataset.toml (grid {nx} × {ny} × {nz}, tool radius {:.0} mm), static.toml, {PATIENT_FILE}",
        mm(radius)
    )];
    lines.extend(input_frame.map(|f| {
        format!(
            "frame: clouds whose files name no frame will be taken in {f}, the inputs' frame, and results given in \
             it (input_frame in {PATIENT_FILE}; --frame says otherwise)"
        )
    }));
    Ok(lines)
}

/// Step 3: the FEM draws.
fn dataset_step(dir: &Path, progress: &dyn learn::Progress) -> Result<Vec<String>> {
    let (scenario, base) = scenario::DatasetScenario::load(&dir.join("dataset.toml"))?;
    let generator = scenario.generator(&base)?;
    let start = Instant::now();
    let manifest = generator.run(&dir.join("dataset"), &scenario.name, None, progress)?;
    let elapsed = start.elapsed();
    let motions = draw_motions(&learn::Dataset::open(&dir.join("dataset"))?)?;
    let mean = mesh::stats::mean(&motions);
    let organ = mesh::io::read_mesh(dir.join("organ.vtu"))?;
    let mut lines = vec![
        format!(
            "dataset: {} draws solved, {} failed (reasons in dataset/manifest.json), {:.0} ms per draw",
            manifest.num_samples,
            manifest.failed.len(),
            mesh::stats::ms(elapsed) / manifest.num_samples.max(1) as f64
        ),
        format!(
            "dataset: the draws move the organ by {:.1} mm on average over its grid nodes (90 % of the draws by at \
             most {:.1} mm, the largest by {:.1} mm)",
            mm(mean),
            mm(mesh::stats::percentile(&motions, 90.0)),
            mm(mesh::stats::max(&motions))
        ),
    ];
    // Said here, before the validation: a swinging truth converges slowly, on its finest meshes.
    lines.extend(swing_warning("the draws", mean, &organ).map(|w| {
        format!("dataset: {w}; the validation's truth may then need its finest meshes, whose solves are its longest")
    }));
    Ok(lines)
}

/// Each draw's mean displacement (m) over the grid nodes inside the organ, shard by shard.
fn draw_motions(dataset: &learn::Dataset) -> Result<Vec<f64>> {
    let unit = dataset.manifest().units.target;
    ensure!(
        unit == learn::FieldUnit::Metre,
        "the dataset's targets are in {unit}, not in metres as the generator writes them"
    );
    let mut motions = Vec::with_capacity(dataset.len());
    for shard in 0..dataset.manifest().shards.len() {
        let samples = dataset.load_shard(shard)?;
        for i in 0..samples.len() {
            let (u, mask) = (samples.target(i), samples.mask(i));
            let n = mask.len();
            let inside: Vec<f64> = (0..n)
                .filter(|&k| mask[k] != 0)
                .map(|k| (0..3).map(|c| f64::from(u[c * n + k]).powi(2)).sum::<f64>().sqrt())
                .collect();
            motions.push(mesh::stats::mean(&inside));
        }
    }
    Ok(motions)
}

/// Step 4: the learned model, on the split `augsim train` makes (the last 20 % held out for the
/// test, the 10 % before them for validation).
fn model_step(options: &PrepareOptions, dir: &Path, progress: &dyn learn::Progress) -> Result<Vec<String>> {
    let dataset = learn::Dataset::open(&dir.join("dataset"))?;
    let all = dataset.load_all()?;
    let (split, [train, validation, test]) = learn::SplitPolicy::default().apply(&all)?;
    let manifest = dataset.manifest();
    let out = dir.join("model");
    let split_line =
        format!("split: {} training, {} validation, {} test draws", train.len(), validation.len(), test.len());
    match options.method {
        learn::Method::Rom => {
            // Trained for registration: the inputs corrupted by 0.5 mm of noise, twice per draw.
            let config = learn::rom::RomConfig {
                noise_copies: 2,
                corruption: learn::Corruption { sparsity: None, noise_std: 0.0005 },
                seed: options.seed,
                ..learn::rom::RomConfig::default()
            };
            let context = learn::rom::Context::of_dataset(manifest, split);
            let (model, report) = learn::rom::fit(&train, &validation, &config, context, None)?;
            model.save(&out)?;
            Ok(vec![
                split_line,
                format!(
                    "model: reduced-order model, {} modes, {} kernel; validation ē {:.3} mm",
                    model.info.modes,
                    model.info.kernel.name(),
                    mm(report.val_mean_error)
                ),
            ])
        }
        learn::Method::UNet => {
            let start = UNetStart::Scratch(learn::UNetConfig::default());
            let config = learn::TrainConfig { seed: options.seed, ..learn::TrainConfig::default() };
            let run = UNetRun { out, resume: true, compute: learn::Compute::Cpu };
            let outcome = train_unet(&dataset, &split, [&train, &validation], start, &config, run, progress)?;
            Ok(vec![split_line, format!("model: U-Net, {} steps", outcome.iterations_done)])
        }
    }
}

/// Step 5: the model's error on the test split.
fn evaluation_step(dir: &Path) -> Result<Vec<String>> {
    let model = learn::Model::load(&dir.join("model"))?;
    let dataset = learn::Dataset::open(&dir.join("dataset"))?;
    let all = dataset.load_all()?;
    let test = model.held_out(&all)?;
    let report = learn::evaluate(&model, &test, &learn::Corruption::none(), 0, learn::Compute::Cpu)?;
    let [mean, _, max] = report.summary_mm();
    Ok(vec![format!(
        "test: ē {mean:.3} mm, largest {max:.2} mm over the organ's grid nodes, {} held-out draws",
        test.len()
    )])
}

/// Above this share of the organ's longest side, a mean motion under a tool's pushes is that of
/// an organ swinging from where it is held rather than of tissue deformed by the tool.
const SWING_SHARE: f64 = 0.1;

/// The warning when `what` (the draws, the targets) moves on average by `motion` (m), more than
/// [`SWING_SHARE`] of `organ`'s longest side: what it means and what to change.
fn swing_warning(what: &str, motion: f64, organ: &Mesh) -> Option<String> {
    let longest = longest_side(organ);
    (motion > SWING_SHARE * longest).then(|| {
        format!(
            "{what} move by {:.0} mm on average, {:.0} % of the organ's longest side ({:.0} mm): held near the landmarks only, it \
             swings rather than deforms under these pushes, and a registration is judged on that swing; hold it \
             over more of its attachments (more landmarks, a larger --attach-distance) for the motions of surgery",
            mm(motion),
            100.0 * motion / longest,
            mm(longest)
        )
    })
}

/// Step 7: the report page and its picture.
fn report_step(state: &PrepareState, dir: &Path) -> Result<Vec<String>> {
    let mesh = mesh::io::read_mesh(dir.join("organ.vtu"))?;
    let camera = read_camera(dir)?;
    let targets = read_points_csv(&dir.join("targets.csv"))?;
    let in_region =
        |name: &str| -> Result<Vec<Point>> { Ok(mesh.region(name)?.iter().map(|&n| mesh.nodes[n]).collect()) };
    regions_picture(
        &dir.join("regions.png"),
        &mesh,
        camera,
        &in_region("visible")?,
        &in_region("attached")?,
        &targets,
    )?;
    let mut text = format!(
        "# {}\n\nPrepared by `augsim prepare` from `{}`.\n\n![The organ seen from the camera](regions.png)\n\n",
        state.options.surface.file_stem().map_or("organ".into(), |s| s.to_string_lossy().into_owned()),
        state.options.surface.display()
    );
    if dir.join(PICTURE).with_extension("png").exists() {
        text.push_str(&format!(
            "![The chosen method's registration of the validation's strongest push, seen from the side \
             ({PICTURE}.html in 3D)]({PICTURE}.png)\n\n"
        ));
    }
    text.push_str("| step | time (s) | what it did |\n| --- | ---: | --- |\n");
    for step in &state.steps {
        text.push_str(&format!("| {} | {:.1} | {} |\n", step.name, step.seconds, step.lines.join("<br>")));
    }
    if let Some(table) = validation::report_table(dir)? {
        text.push_str(&format!(
            "\n**Validation** ({TABLE}: each push too; the method {PATIENT_FILE} names registers with its σ \
             calibrated):\n\n{table}"
        ));
    }
    let total: f64 = state.steps.iter().map(|s| s.seconds).sum();
    text.push_str(&format!(
        "\nTotal {total:.0} s before the report. Register with `augsim register CLOUD --patient {0}` or \
         stream with `augsim serve --patient {0}`.\n",
        dir.display()
    ));
    write_atomic_bytes(&dir.join("report.md"), text.as_bytes())?;
    Ok(vec!["report: report.md, regions.png".into()])
}

/// The organ seen from the camera (a projection on the plane across its line of sight): the
/// surface, what the camera sees, where the organ is held, the targets.
fn regions_picture(
    path: &Path,
    organ: &Mesh,
    camera: Point,
    visible: &[Point],
    attached: &[Point],
    targets: &[Point],
) -> Result<()> {
    let (lo, hi) = organ.bounds();
    let centre: Point = std::array::from_fn(|d| 0.5 * (lo[d] + hi[d]));
    let axis = mesh::unit(mesh::sub(centre, camera));
    let (u, v) = across_sight(axis);
    let project = |points: &[Point]| -> Vec<(f64, f64)> {
        points.iter().map(|p| (mesh::dot(mesh::sub(*p, centre), u), mesh::dot(mesh::sub(*p, centre), v))).collect()
    };
    let surface: Vec<Point> = mesh::topology::boundary_nodes(organ).into_iter().map(|n| organ.nodes[n]).collect();
    let sets = [
        PointSet { name: "surface".into(), points: project(&surface), radius: 1, color: 7 },
        PointSet { name: "seen by the camera".into(), points: project(visible), radius: 2, color: 0 },
        PointSet { name: "held (near the landmarks)".into(), points: project(attached), radius: 3, color: 2 },
        PointSet { name: "targets".into(), points: project(targets), radius: 5, color: 1 },
    ];
    let spec = PlotSpec {
        title: "The organ seen from the camera".into(),
        x_label: "across the line of sight (m)".into(),
        y_label: "(m)".into(),
        log_y: false,
    };
    Ok(scatter_plot(path, &spec, &sets, &[])?)
}

#[cfg(test)]
mod tests {
    use super::*;
    use mesh::io::points::write_points_csv;

    /// A target in a flap of the organ thinner than the tetrahedra is outside the mesh but inside
    /// the surface, and said to be so; a target outside both is not.
    #[test]
    fn a_target_in_a_part_the_mesh_left_out_is_told_so() {
        let flap = |p: Point| {
            let q = [(p[0] - 0.06).abs() - 0.03, p[1].abs() - 0.02, p[2].abs() - 0.003];
            mesh::norm(q.map(|c| c.max(0.0))) + q[0].max(q[1]).max(q[2]).min(0.0)
        };
        let sdf = move |p: Point| (mesh::norm(p) - 0.04).min(flap(p));
        let domain = mesh::SdfDomain::new(sdf, [-0.041; 3], [0.091, 0.041, 0.041]);
        let fine = mesh::stuff(&domain, &mesh::TetMeshOptions::with_size(0.0015)).unwrap();
        let surface = mesh::boundary_surface(&fine).compacted();
        let coarse = mesh::stuff(&domain, &mesh::TetMeshOptions::with_size(0.015)).unwrap();
        let organ = register::Organ::new(coarse, None).unwrap();
        let why = thin_part_left_out(&surface, &organ, &[[0.0; 3], [0.08, 0.0, 0.0]]).unwrap();
        assert!(why.contains("thinner than the tetrahedra"), "{why}");
        assert_eq!(thin_part_left_out(&surface, &organ, &[[0.0; 3], [0.0, 0.1, 0.0]]), None);
    }

    /// A camera that sees the held side of the organ, where the other frame's would not, is
    /// warned about; one that looks at the other side is not.
    #[test]
    fn a_camera_seeing_where_the_organ_is_held_is_told_of_the_other_frame() {
        let organ = mesh::box_tet([-0.1, -0.1, -0.05], [0.1, 0.1, 0.05], [4, 4, 2]).unwrap();
        let attached: Vec<usize> = (0..organ.num_nodes()).filter(|&n| organ.nodes[n][1] < -0.099).collect();
        let warning = |camera: Point| {
            let visible =
                Camera { view: None, position: Some(camera), max_angle_deg: 90.0 }.seen_nodes(&organ).unwrap();
            camera_sees_the_hold(&organ, camera, (&visible, &attached), "").unwrap()
        };
        // Facing the held side (the seen nodes as `Camera::seen_nodes` finds them: 13 of 15).
        let line = warning([0.0, -0.3, 0.0]).expect("a camera facing the held side");
        assert!(
            line.contains(&format!("sees 13 of the {} held nodes", attached.len())) && line.contains("it would see 0"),
            "{line}"
        );
        assert_eq!(warning([0.0, 0.3, 0.0]), None);
    }

    /// A camera behind the organ (LPS: +y) is warned about, naming where the other frame puts it
    /// and, when typed, the frame it was taken in; one in front, or to a side, is not.
    #[test]
    fn a_camera_behind_the_organ_is_told_of_the_other_frame() {
        let organ = mesh::box_tet([-0.1, -0.1, -0.05], [0.1, 0.1, 0.05], [4, 4, 2]).unwrap();
        let typed = CameraAt::Point([0.0; 3]);
        let line = camera_behind(&organ, [0.035, 0.36, -0.18], Frame::Ras, &typed).expect("behind");
        assert!(line.contains("360 mm towards the patient's back"), "{line}");
        assert!(
            line.contains("taken in the surface's frame, RAS") && line.contains("at (-35, -360, -180) mm"),
            "{line}"
        );
        assert_eq!(camera_behind(&organ, [0.035, -0.36, -0.18], Frame::Ras, &typed), None);
        assert_eq!(camera_behind(&organ, [0.4, 0.2, 0.0], Frame::Lps, &typed), None);
        let file = CameraAt::File("camera.csv".into());
        assert!(!camera_behind(&organ, [0.0, 0.3, 0.0], Frame::Lps, &file).unwrap().contains("typed"));
    }

    #[test]
    fn an_organ_that_swings_under_the_pushes_is_told_so() {
        let organ = mesh::box_tet([0.0; 3], [0.2, 0.1, 0.1], [2, 1, 1]).unwrap();
        assert_eq!(swing_warning("the targets", 0.019, &organ), None, "a tenth of its 200 mm is not yet a swing");
        let line = swing_warning("the targets", 0.163, &organ).unwrap();
        assert!(
            line.starts_with("the targets move by 163 mm on average, 82 % of the organ's longest side (200 mm)"),
            "{line}"
        );
        assert!(line.contains("--attach-distance"), "{line}");
    }

    /// The shipped labelmaps of the liver phantom (its origin at (−80, 30, −140) mm in RAS).
    fn labelmap(name: &str) -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../mesh/tests/data").join(name)
    }

    /// The organ step's options on `file`, the landmarks, targets and camera given in RAS (mm)
    /// and turned to LPS when `lps`.
    fn options(dir: &Path, file: &str, label: &str, lps: bool) -> PrepareOptions {
        let frame = |p: Point| if lps { [-p[0], -p[1], p[2]] } else { p };
        let landmarks = [[-115.0, 30.0, -183.0], [-45.0, 30.0, -183.0], [-80.0, 0.0, -183.0], [-80.0, 60.0, -183.0]];
        // The centres of the two lobes.
        let targets = [[-45.0, 30.0, -140.0], [-125.0, 35.0, -135.0]];
        write_points_csv(&dir.join("attach.csv"), &landmarks.map(frame)).unwrap();
        write_points_csv(&dir.join("targets.csv"), &targets.map(frame)).unwrap();
        let mut options = PrepareOptions::new(
            labelmap(file),
            frame([-80.0, 30.0, 150.0]),
            dir.join("attach.csv"),
            dir.join("targets.csv"),
        );
        options.label = Some(label.into());
        options.tets = 800;
        options
    }

    /// A folder given for the organ says what a folder cannot be (a DICOM series) and what to give;
    /// one given for the landmarks is called a folder, not a file gone missing.
    #[test]
    fn a_folder_given_for_a_file_is_named_so() {
        let dir = tempfile::tempdir().unwrap();
        let mut organ_folder = options(dir.path(), "liver_labels.nii.gz", "5", false);
        organ_folder.surface = dir.path().to_path_buf();
        let e = absolute(&organ_folder).unwrap_err().to_string();
        assert!(e.contains("a folder, not a file (a DICOM series is not read)"), "{e}");
        let mut landmarks_folder = options(dir.path(), "liver_labels.nii.gz", "5", false);
        landmarks_folder.attach = dir.path().to_path_buf();
        let e = absolute(&landmarks_folder).unwrap_err().to_string();
        assert!(e.starts_with("the landmarks file ") && e.ends_with(" is a folder, not a file"), "{e}");
    }

    /// A hold that takes every node the camera sees leaves the tool nothing to push: refused in the
    /// organ's step, naming the option, not when the dataset's draws all fail.
    #[test]
    fn a_hold_over_all_the_seen_surface_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let mut whole = options(dir.path(), "liver_labels.nii.gz", "5", false);
        whole.attach_distance = Some("1000mm".parse().unwrap());
        let e = format!("{:#}", organ_step(&whole, dir.path()).unwrap_err());
        assert!(e.contains("held within --attach-distance 1000.0 mm of its landmarks, 100 % of its surface"), "{e}");
    }

    /// Points given with a labelmap are read in the unit given (`--units`), the unit of the clouds
    /// to come; the labelmap's surface comes in mm whatever unit its voxels were read in.
    #[test]
    fn a_labelmap_s_points_are_read_in_the_unit_given() {
        let dir = tempfile::tempdir().unwrap();
        let mut options = options(dir.path(), "liver_labels.nii.gz", "5", false);
        options.units = Some(LengthUnit::Centimetre);
        let inputs = read_inputs(&options, &mut Vec::new()).unwrap();
        assert_eq!((inputs.unit, inputs.points_unit), (LengthUnit::Millimetre, LengthUnit::Centimetre));
        // The first landmark, (−115, 30, −183) in the file, in cm, set up in LPS (x and y negated).
        let read = inputs.landmarks.points[0];
        assert!(mesh::distance(read, [1.15, -0.30, -1.83]) < 1e-12, "{read:?}");
        assert!(mesh::distance(inputs.camera, [0.80, -0.30, 1.50]) < 1e-12, "{:?}", inputs.camera);
    }

    /// The same segmentation in RAS (NIfTI) and in LPS (Slicer's .seg.nrrd) is set up in LPS, the
    /// organ where the scanner saw it, with the same mesh.
    #[test]
    fn a_labelmap_is_set_up_in_lps_whatever_its_scanner_frame() {
        let mut organs = Vec::new();
        for (file, label, lps) in [("liver_labels.nii.gz", "5", false), ("liver_labels.seg.nrrd", "liver", true)] {
            let dir = tempfile::tempdir().unwrap();
            let (lines, given, unit) = organ_step(&options(dir.path(), file, label, lps), dir.path()).unwrap();
            assert_eq!(unit, LengthUnit::Millimetre);
            let (frame, set_up) =
                if lps { (Frame::Lps, "") } else { (Frame::Ras, ", set up in LPS (x and y negated)") };
            assert_eq!(given, Some(frame));
            let line = lines.iter().find(|l| l.starts_with("frame: ")).unwrap();
            assert!(line.starts_with(&format!("frame: {frame} (named by")) && line.ends_with(set_up), "{line}");
            assert!(lines.iter().any(|l| l == "targets: 2 inside the organ"), "{lines:?}");
            // The organ stays where the scanner saw it: the phantom spans x from −180 to 20 mm
            // (RAS), y from −40 to 100, z from −185 to −95; in LPS, x and y negated.
            let organ = mesh::io::read_mesh(dir.path().join("organ.vtu")).unwrap();
            assert_eq!(mesh::io::surface_frame(dir.path().join("organ.vtu")).unwrap(), Some(Frame::Lps));
            let (lo, hi) = organ.bounds();
            let middle: Point = std::array::from_fn(|d| 0.5e3 * (lo[d] + hi[d]));
            assert!(mesh::distance(middle, [80.0, -30.0, -140.0]) < 3.0, "{file}: centre {middle:?}");
            let targets = mesh::io::points::read_points(dir.path().join("targets.csv")).unwrap();
            assert_eq!(targets.frame, Some(Frame::Lps));
            assert!(mesh::distance(targets.points[0], [0.045, -0.030, -0.140]) < 1e-9, "{:?}", targets.points);
            organs.push(organ);
        }
        assert_eq!(organs[0].nodes.len(), organs[1].nodes.len());
        let apart =
            organs[0].nodes.iter().zip(&organs[1].nodes).map(|(a, b)| mesh::distance(*a, *b)).fold(0.0, f64::max);
        assert!(apart < 1e-6, "the two set-ups' nodes lie up to {:.3} mm apart", mm(apart));
    }

    #[test]
    fn a_broken_export_is_rebuilt_and_its_defect_named_in_the_file_s_unit() {
        let dir = tempfile::tempdir().unwrap();
        let export = Path::new(env!("CARGO_MANIFEST_DIR")).join("../mesh/tests/data/broken_export.obj");
        write_points_csv(&dir.path().join("attach.csv"), &[[0.0, 0.0, -60.0], [70.0, 0.0, -40.0], [-42.0, 0.0, -42.0]])
            .unwrap();
        write_points_csv(&dir.path().join("targets.csv"), &[[0.0, 0.0, 0.0], [70.0, 0.0, 0.0]]).unwrap();
        let mut options = PrepareOptions::new(
            export.clone(),
            [0.0, 0.0, 300.0],
            dir.path().join("attach.csv"),
            dir.path().join("targets.csv"),
        );
        options.units = Some(LengthUnit::Millimetre);
        options.tets = 800;
        let (lines, ..) = organ_step(&options, dir.path()).unwrap();
        // The defect as local repair names it on the file as read (mm), not on the surface in metres.
        let as_read = mesh::io::read_surface(&export).unwrap();
        let Err(mesh::MeshError::Invalid(defect)) = mesh::repair::repair_surface(&as_read, &Default::default()) else {
            panic!("local repair mends the broken export")
        };
        let route = format!("repair: route: volumetric (local repair cannot mend it: {defect})");
        assert!(lines.contains(&route), "{route} expected in {lines:?}");
        assert!(lines.iter().any(|l| l == "targets: 2 inside the organ"), "{lines:?}");
        assert!(!lines.iter().any(|l| l.contains("the camera at")), "{lines:?}");
        // A camera given in µm where the surface is in mm: 1,000 times too far, named.
        options.camera = [0.0, 0.0, 300_000.0].into();
        let (lines, ..) = organ_step(&options, dir.path()).unwrap();
        assert!(
            lines.iter().any(|l| l.starts_with("warning: the camera at (0, 0, 300000) mm lies")
                && l.ends_with("is it given in the inputs' unit (mm)?")),
            "{lines:?}"
        );
    }

    /// A surface whose header names no frame is in the frame given (`--frame`), points files
    /// naming the other brought into it; without it, the first file that names one gives it.
    #[test]
    fn the_frame_given_is_the_header_less_surface_s() {
        let dir = tempfile::tempdir().unwrap();
        let surface = dir.path().join("organ.obj");
        let mut ball = mesh::generate::icosphere(80.0, 2);
        ball.transform([-100.0, -50.0, 0.0], 1.0);
        mesh::io::write_surface(&surface, &ball).unwrap();
        write_points_csv(&dir.path().join("attach.csv"), &[[100.0, 50.0, -80.0]]).unwrap();
        let ras = dir.path().join("targets.mrk.json");
        let json = r#"{"markups": [{"coordinateSystem": "RAS", "controlPoints": [{"position": [-110, -40, 5]}]}]}"#;
        std::fs::write(&ras, json).unwrap();
        let mut options = PrepareOptions::new(surface, [100.0, 50.0, 200.0], dir.path().join("attach.csv"), ras);
        options.units = Some(LengthUnit::Millimetre);
        let read = |options: &PrepareOptions| {
            let mut lines = Vec::new();
            let inputs = read_inputs(options, &mut lines).unwrap();
            (inputs.surface.vertices[0], inputs.targets.points[0], lines)
        };
        // Taken as RAS, the targets file's: the surface is brought to the set-up's LPS with them.
        let (vertex, target, _) = read(&options);
        assert_eq!(vertex, [-ball.vertices[0][0], -ball.vertices[0][1], ball.vertices[0][2]]);
        assert!(mesh::norm(mesh::sub(target, [0.11, 0.04, 0.005])) < 1e-12, "{target:?}");
        // Given as LPS: the surface stays, the targets alone are brought to it.
        options.frame = Some(Frame::Lps);
        let (vertex, target, lines) = read(&options);
        assert_eq!(vertex, ball.vertices[0]);
        assert!(mesh::norm(mesh::sub(target, [0.11, 0.04, 0.005])) < 1e-12, "{target:?}");
        assert!(lines.iter().any(|l| l == "frame: LPS (given; the surface's header names none)"), "{lines:?}");
    }

    /// An attachment distance that holds nothing is refused before any step, in the length's
    /// own words; one given, as a length, holds the nodes within it.
    #[test]
    fn the_attachment_distance_is_a_positive_length() {
        let dir = tempfile::tempdir().unwrap();
        let mut given = options(dir.path(), "liver_labels.nii.gz", "5", false);
        given.attach_distance = Some("-5mm".parse().unwrap());
        let error = absolute(&given).unwrap_err().to_string();
        assert_eq!(error, "the attachment distance must be positive, got -5 mm");
        given.attach_distance = Some("2.5cm".parse().unwrap());
        let organ = mesh::box_tet([0.0; 3], [0.1; 3], [2, 2, 2]).unwrap();
        assert_eq!(hold_distance(&absolute(&given).unwrap(), &organ, &[[0.0; 3]]).unwrap(), 0.025);
    }

    #[test]
    fn organs_are_named_after_their_files() {
        for (file, name) in
            [("a/liver.stl", "liver"), ("seg.nii.gz", "seg"), ("Liver.seg.nrrd", "Liver"), (".nii.gz", "organ")]
        {
            assert_eq!(organ_name(Path::new(file)), name);
        }
    }

    /// The warnings that doubt the organ (its unit, its cut by the image's border) are told apart
    /// from the others: an error of the organ's step is said as likely caused by them alone.
    #[test]
    fn the_organ_s_doubts_are_told_apart() {
        let lines: Vec<String> = [
            "units: m (given)",
            "warning: in m the organ is 6483 mm across, where organs are 20 to 600 mm: is the unit right?",
            "warning: the camera, looking along (0, 0, -1), sees 45 of the 58 held nodes",
            "warning: the organ reaches the image's border (i = 112, left): it is cut there, flat where the image ends",
            "warning: `tumour`: 39 of its 162 vertices lie outside the organ",
            "warning: the file places its voxels nowhere (a NIfTI without qform and sform)",
        ]
        .map(String::from)
        .to_vec();
        let doubts: Vec<bool> = lines.iter().map(|l| l.strip_prefix("warning: ").is_some_and(is_organ_doubt)).collect();
        assert_eq!(doubts, [false, true, false, true, false, true]);
    }

    #[test]
    fn targets_in_the_wrong_frame_and_a_wrong_unit_are_refused_or_named() {
        let dir = tempfile::tempdir().unwrap();
        // RAS targets for an LPS segmentation: outside the organ.
        let wrong = options(dir.path(), "liver_labels.seg.nrrd", "liver", true);
        write_points_csv(&wrong.targets, &[[-45.0, 30.0, -140.0]]).unwrap();
        let error = format!("{:#}", organ_step(&wrong, dir.path()).unwrap_err());
        assert!(error.starts_with("the organ read from the labelmap's label 5 ('liver'): "), "{error}");
        assert!(error.contains("the targets of"), "{error}");
        // A NIfTI whose header names mm, given in metres: read so, as a header may name the wrong unit,
        // its points too (the unit given is theirs), and said, with the size it makes.
        let mut metres = options(dir.path(), "liver_labels.nii.gz", "5", false);
        metres.units = Some(LengthUnit::Metre);
        let (lines, _, unit) = organ_step(&metres, dir.path()).unwrap();
        assert_eq!(unit, LengthUnit::Metre);
        let said = |text: &str| lines.iter().any(|l| l.starts_with("warning: ") && l.contains(text));
        assert!(said("names its unit, millimetres; read in metres as given instead (--units): 1,000 times larger"));
        assert!(said("no organ's size"), "{lines:?}");
        let mut surface = options(dir.path(), "liver_labels.nii.gz", "5", false);
        surface.surface = Path::new(env!("CARGO_MANIFEST_DIR")).join("../mesh/tests/data/liver.obj");
        let error = organ_step(&surface, dir.path()).unwrap_err().to_string();
        assert!(error.contains("--label 5 chooses a label of a labelmap"), "{error}");
        // A unit that makes the organ metres across: the error that follows names it first.
        let giant = PrepareOptions { label: None, units: Some(LengthUnit::Metre), ..surface };
        let error = format!("{:#}", organ_step(&giant, dir.path()).unwrap_err());
        assert!(
            error.starts_with("in m the organ is 6483 mm across")
                && error.contains("(likely the cause of what follows): "),
            "{error}"
        );
    }
}
