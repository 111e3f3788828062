//! What a registration writes: the registered organ (organ.vtu, or organ.pvd and one .vtu per
//! frame of a sequence), targets.csv (rest and registered positions, with the predicted standard
//! deviation when the method gives one) and summary.json (the run's figures and each frame's),
//! all in the cloud's frame (the frame the clouds were given in, which targets.csv and
//! summary.json name when known); for 3D Slicer, the registered targets as markups (targets.mrk.json)
//! and the deformed organ's surface (organ_deformed.vtk) and structures (NAME_deformed.vtk), in
//! millimetres and naming their frame,
//! and the registration as a displacement-field transform (displacement.nrrd) that warps the CT
//! and its segmentations; and what a comparison of methods on a synthetic case writes; each
//! run in a folder of its own ([`run_dir`]).

use std::borrow::Cow;
use std::path::{Path, PathBuf};

use crate::meshing::write_surface_in_mm;
use anyhow::{Context, Result};
use mesh::io::points::{write_markups_json, LabelledPoints};
use mesh::io::{write_atomic_bytes, Field, Frame, FrameChange};
use mesh::length::{mm, LengthUnit};
use mesh::{Mesh, Point};
use register::cloud::read_frames;
use register::{
    in_cloud_frame, FrameOutcome, FrameSummary, Organ, Registration, RigidResult, RigidTransform, Summary, Tracked,
    WarpField,
};
use scenario::registration::slug;
use serde::Serialize;

use crate::case::{Compared, Registered, SyntheticCase};
use crate::picture::{frame_notes, RegisteredFrame};
use crate::points::PointInput;
use crate::printout::{comparison_rows, frame_line, rigid_lines, run_lines, setup_lines, COMPARISON_COLUMNS};
use crate::registration::RegistrationSpec;

/// The folder of a run's results: `out` when the user names one, refused when it already holds
/// anything ([`refuse_used_folder`]: an earlier run's results, a user's files); otherwise a
/// fresh numbered folder under `parent` (`001`, `002`, …: the first free number), created. The
/// flag says whether the folder is this run's own (a fresh numbered one, or an `out` that does not
/// exist yet), which a run that fails before writing into it removes again.
pub fn run_dir(out: Option<&Path>, parent: &Path) -> Result<(PathBuf, bool)> {
    if let Some(dir) = out {
        if dir.is_file() {
            anyhow::bail!("{} is a file, not a folder: give another --out", dir.display());
        }
        refuse_used_folder(dir)?;
        return Ok((dir.to_path_buf(), !dir.exists()));
    }
    mesh::io::create_folder(parent)?;
    for n in 1..=99_999 {
        let dir = parent.join(format!("{n:03}"));
        match std::fs::create_dir(&dir) {
            Ok(()) => return Ok((dir, true)),
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => continue,
            Err(e) => return Err(e).with_context(|| format!("creating {}", dir.display())),
        }
    }
    anyhow::bail!("{} holds 99,999 runs: give --out", parent.display())
}

/// Where `augsim register`'s runs go when no folder is named, each in a numbered folder of its own.
pub const REGISTER_RUNS: &str = "out/register";

/// `work` done in a run's folder ([`run_dir`] of `out`, else under `parent`), which is removed
/// again when the work fails before writing into it ([`tidy_failed_run`]).
pub fn in_run_dir<T>(out: Option<&Path>, parent: &Path, work: impl FnOnce(&Path) -> Result<T>) -> Result<T> {
    let (dir, own) = run_dir(out, parent)?;
    tidy_failed_run(&dir, own, work(&dir))
}

/// The file that holds a run's results, written last: a folder that has it holds a finished run.
pub const SUMMARY_FILE: &str = "summary.json";

/// Refuses a folder `dir` that holds the results of an earlier run (its summary.json), the
/// frames of one stopped before its summary (a registration's organ.vtu or organ_NNNN.vtu, an
/// assimilation's deformation/step_NNNNN.vtu), or any other file (a user's, a patient's set-up),
/// so that two runs' files are never mixed and a run's files replace none of the user's.
pub fn refuse_used_folder(dir: &Path) -> Result<()> {
    if dir.join(SUMMARY_FILE).exists() {
        anyhow::bail!(
            "{} holds the results of an earlier run (summary.json): give another --out, or remove it",
            dir.display()
        );
    }
    let is_frame = |name: &str| {
        name == "organ.vtu"
            || name
                .strip_prefix("organ_")
                .and_then(|n| n.strip_suffix(".vtu"))
                .is_some_and(|n| n.parse::<u32>().is_ok())
    };
    let count = |dir: &Path, is_frame: &dyn Fn(&str) -> bool| {
        std::fs::read_dir(dir)
            .into_iter()
            .flatten()
            .flatten()
            .filter(|e| is_frame(&e.file_name().to_string_lossy()))
            .count()
    };
    let is_step = |name: &str| name.starts_with("step_") && name.ends_with(".vtu");
    for (frames, files) in [
        (count(dir, &is_frame), "organ.vtu, organ_NNNN.vtu"),
        (count(&dir.join("deformation"), &is_step), "deformation/step_NNNNN.vtu"),
    ] {
        // (A patient's set-up holds its mesh as organ.vtu: said below.)
        if frames > 0 && !dir.join(crate::setup::PATIENT_FILE).exists() {
            anyhow::bail!(
                "{} holds {frames} frame(s) of an earlier run stopped before its summary ({files}): give another \
                 --out, or remove it",
                dir.display()
            );
        }
    }
    let mut held: Vec<String> = std::fs::read_dir(dir)
        .into_iter()
        .flatten()
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    held.sort();
    if !held.is_empty() {
        let shown = held.iter().take(3).cloned().collect::<Vec<_>>().join(", ");
        anyhow::bail!(
            "{} holds {} file(s) or folder(s) of its own ({shown}{}): the run's files could replace them; give a new \
             or empty --out",
            dir.display(),
            held.len(),
            if held.len() > 3 { ", …" } else { "" }
        );
    }
    Ok(())
}

/// Refuses an output folder `out` that holds one of a run's `inputs` (files or folders, each
/// compared as the file it names): the run's files could replace it, or be read as its input by
/// the next run.
pub fn refuse_inputs_inside(out: &Path, inputs: &[&Path]) -> Result<()> {
    let folder = mesh::io::file_key(out);
    if let Some(input) = inputs.iter().find(|p| mesh::io::file_key(p).starts_with(&folder)) {
        anyhow::bail!(
            "{} holds {}, which the run reads: the run's files could replace it; give another --out",
            out.display(),
            input.display()
        );
    }
    Ok(())
}

/// Passes `result` on; when it is a failure and the folder `dir` is the run's own (see
/// [`run_dir`]), removes the folder again if the run wrote nothing into it.
pub fn tidy_failed_run<T>(dir: &Path, own: bool, result: Result<T>) -> Result<T> {
    if result.is_err() && own {
        // Only an empty folder is removed.
        let _ = std::fs::remove_dir(dir);
    }
    result
}

/// summary.json: the run's figures and each frame's.
#[derive(Serialize)]
struct RunSummary<'a> {
    /// The frame of the results' coordinates, when known.
    #[serde(skip_serializing_if = "Option::is_none")]
    frame: Option<Frame>,
    #[serde(flatten)]
    summary: &'a Summary,
    per_frame: &'a [FrameSummary],
    /// What a user should know of the files written (or left out), a line each.
    #[serde(skip_serializing_if = "<[String]>::is_empty")]
    file_notes: &'a [String],
}

/// What [`write_registered_cloud`] wrote.
#[derive(Clone, Debug)]
pub struct Finished {
    /// The run's figures.
    pub summary: Summary,
    /// The files written for 3D Slicer, by name.
    pub for_slicer: Vec<String>,
    /// What a user should know of the files written or left out (displacement.nrrd of an organ
    /// registered with inverted elements), a line each; also in summary.json.
    pub notes: Vec<String>,
}

/// Writes a registration run into a directory, frame by frame, then its targets and summary.
struct RunWriter {
    dir: PathBuf,
    sequence: bool,
    /// The unit of targets.csv.
    unit: LengthUnit,
    /// The frame the clouds were given in (`--frame`), when given: the results' frame.
    given: Option<Frame>,
    /// The meshes' frame, when known at the start: the clouds', else the organ's.
    meshes: Option<Frame>,
    /// From the organ's frame to the results'.
    change: FrameChange,
    /// The organ moved by the rigid alignment, with the pose that moved it (moved anew when a
    /// frame estimates the pose again).
    moved: Option<(RigidTransform, Mesh)>,
    steps: Vec<(f64, String)>,
    rows: Vec<FrameSummary>,
    /// The run's warnings beside the registration's own ([`RunWriter::warn`]).
    warnings: Vec<String>,
}

impl RunWriter {
    /// A writer into `dir` (created), for a sequence of frames (organ.pvd and one organ_NNNN.vtu
    /// each) or a single cloud (organ.vtu), its targets.csv in `unit` (the organ's meshes stay in
    /// metres, the files for 3D Slicer in millimetres). `(organ, given)`: the organ's frame and
    /// the one the clouds were given in (`--frame`), each when known; the results are written in
    /// the clouds' frame, converted from the organ's (in the organ's when none was given).
    fn new(
        dir: &Path,
        sequence: bool,
        unit: LengthUnit,
        (organ, given): (Option<Frame>, Option<Frame>),
    ) -> Result<RunWriter> {
        mesh::io::create_folder(dir)?;
        let change = FrameChange::between(organ, given.or(organ));
        Ok(RunWriter {
            dir: dir.to_path_buf(),
            sequence,
            unit,
            given,
            meshes: given.or(organ),
            change,
            moved: None,
            steps: Vec::new(),
            rows: Vec::new(),
            warnings: Vec::new(),
        })
    }

    /// `points` from the organ's frame to the results'.
    fn converted(&self, points: &[Point]) -> Vec<Point> {
        points.iter().map(|&p| self.change.point(p)).collect()
    }

    /// Writes frame `i` (registered from `cloud`) of `organ`; returns its summary line.
    fn frame(&mut self, i: usize, cloud: String, organ: &Organ, outcome: &FrameOutcome) -> Result<&FrameSummary> {
        if let Some(r) = &outcome.rigid {
            if self.moved.as_ref().is_none_or(|(pose, _)| *pose != r.cloud_to_organ) {
                self.moved = Some((r.cloud_to_organ, r.organ_to_cloud().move_mesh(organ.mesh())));
            }
        }
        let name = if self.sequence { format!("organ_{i:04}.vtu") } else { "organ.vtu".into() };
        let moved = self.moved.as_ref().map(|(_, m)| m);
        let (m, u) = mesh_in_cloud_frame(organ.mesh(), moved, outcome.rigid.as_ref(), &outcome.registration.u);
        let (m, u) = if self.change.flips() {
            let mut m = m.into_owned();
            m.nodes = self.converted(&m.nodes);
            let u: Vec<f64> = u.chunks_exact(3).flat_map(|v| self.change.point([v[0], v[1], v[2]])).collect();
            (Cow::Owned(m), u)
        } else {
            (m, u)
        };
        mesh::io::write_mesh_in_frame(self.dir.join(&name), &m, &[Field::point("displacement", 3, u)], self.meshes)?;
        self.steps.push((i as f64, name));
        self.rows.push(FrameSummary::new(cloud, outcome));
        Ok(self.rows.last().expect("just pushed"))
    }

    /// Keeps a warning of the run (the truth's, the clouds' files') for summary.json, beside the
    /// registration's own.
    fn warn(&mut self, warning: impl Into<String>) {
        self.warnings.push(warning.into());
    }

    /// Writes organ.pvd (for a sequence), targets.csv (of the last frame of `registration`, with
    /// its targets' labels), the last frame for 3D Slicer (targets.mrk.json, organ_deformed.vtk,
    /// its registered surface, NAME_deformed.vtk for each of its structures, and
    /// displacement.nrrd, see [`write_warp`]; their names ending in [`register::IMPLAUSIBLE`] when the
    /// last frame is not plausible) and summary.json, all in the results' frame,
    /// which they name when known (the clouds' frame given, else `working`: the frame the
    /// registration worked in, once the organ or a file named one), and the last frame's
    /// pictures, registration.png and registration.html, in the organ's frame (`last`: its
    /// cloud and its targets' truth, when known, as registered).
    fn finish(
        self,
        registration: &Registration,
        working: Option<Frame>,
        outcomes: &[FrameOutcome],
        (cloud, truth): (&[Point], Option<&[Point]>),
    ) -> Result<Finished> {
        let frame = self.given.or(working);
        if self.sequence {
            mesh::io::write_pvd(self.dir.join("organ.pvd"), &self.steps)?;
        }
        let last = outcomes.last().context("no frame")?;
        let registered = self.converted(&last.targets);
        let sigma = last.target_std.as_deref();
        let labels = registration.target_labels();
        write_targets(
            &self.dir.join("targets.csv"),
            &self.converted(&in_cloud_frame(registration.targets().to_vec(), last.rigid.as_ref())),
            &registered,
            sigma,
            labels,
            (self.unit, frame),
        )?;
        // A result that is not plausible says so in the names 3D Slicer gives what it loads.
        let verdict = last.registration.verdict_suffix();
        let mut for_slicer = vec![format!("targets{verdict}.mrk.json")];
        let names = registration.target_names();
        write_targets_for_slicer(&self.dir.join(&for_slicer[0]), &registered, sigma, &names, frame)?;
        let mut surfaces = vec![(
            format!("organ_deformed{verdict}.vtk"),
            registration.deformed_surface(&last.registration.u, last.rigid.as_ref()),
        )];
        for (name, surface) in registration.structure_surfaces(&last.registration.u, last.rigid.as_ref()) {
            surfaces.push((format!("{name}_deformed{verdict}.vtk"), surface));
        }
        for (name, mut surface) in surfaces {
            surface.vertices = self.converted(&surface.vertices);
            write_surface_in_mm(&self.dir.join(&name), &surface, frame)?;
            for_slicer.push(name);
        }
        let mut notes = Vec::new();
        if let Some(rigid) = &last.rigid {
            let name = format!("rigid{verdict}.tfm");
            write_rigid_transform(&self.dir.join(&name), &rigid.cloud_to_organ, self.change, frame)?;
            for_slicer.push(name);
        }
        match WarpField::of_registration(registration.organ(), &last.registration.u, WARP_STEPS) {
            Ok(field) => {
                let name = format!("displacement{verdict}.nrrd");
                write_warp(&self.dir.join(&name), &field, self.change, frame)?;
                if field.inverted > 0 {
                    notes.push(format!(
                        "{name}: {} cell(s) of the registered organ inverted; where they fold over \
                         their neighbours, the field takes one of the rest positions folded there",
                        field.inverted
                    ));
                }
                let (folded, cells) =
                    (field.folded_cells(), field.dims.iter().map(|n| n.saturating_sub(1)).product::<usize>());
                if folded > 0 {
                    notes.push(format!(
                        "{name}: the field folds in {folded} of its {cells} grid cells (where the organ moves more than \
                         the space around it can follow); there 3D Slicer's inverse of it, which moves models and \
                         markups, is ambiguous"
                    ));
                }
                for_slicer.push(name);
            }
            Err(e) => notes.push(format!("no displacement.nrrd: {e}")),
        }
        let row = self.rows.last().context("no frame")?;
        let targets = (registration.targets(), last.targets.as_slice());
        let u = &last.registration.u;
        RegisteredFrame::new(registration.organ(), u, last.rigid.as_ref(), cloud, targets, truth).write(
            &self.dir.join("registration"),
            &format!("{}: {}", registration.method(), row.cloud),
            frame_notes(frame_line(outcomes.len() - 1, row), last.target_std.as_deref(), &last.registration.warnings),
        )?;
        let mut summary = Summary::new(registration.method(), outcomes)?;
        // The set-up's warnings (targets, structures, the truth, the clouds' files) first.
        let frames = std::mem::take(&mut summary.warnings);
        summary.warnings = registration.warnings().iter().chain(&self.warnings).cloned().chain(frames).collect();
        let run = RunSummary { frame, summary: &summary, per_frame: &self.rows, file_notes: &notes };
        write_atomic_bytes(&self.dir.join(SUMMARY_FILE), serde_json::to_string_pretty(&run)?.as_bytes())?;
        Ok(Finished { summary, for_slicer, notes })
    }
}

/// `augsim register CLOUD`: the cloud of `cloud` (a file, or a directory of frames registered in
/// turn, each from the last) registered as `spec` says, the targets' truth of `truth` (a file,
/// or one per frame) measured, the run written into `out` (frame by frame, then its targets, the
/// files for 3D Slicer and summary.json); each line for the user (the method, the organ, each
/// frame, the run, the files) goes to `say`, a warning's starting with `warning`. An error, once
/// written, when the last frame's result is not plausible.
pub fn register_files(
    spec: &RegistrationSpec,
    cloud: &Path,
    truth: Option<&Path>,
    out: &Path,
    say: &mut dyn FnMut(&str),
) -> Result<()> {
    let targets = match &spec.targets {
        crate::registration::TargetsSpec::File(path) => Some(path.as_path()),
        _ => None,
    };
    let structures = spec.structures.iter().map(|s| s.path.as_path());
    let inputs: Vec<&Path> =
        [cloud].into_iter().chain(truth).chain(targets).chain(structures).chain(spec.surface.as_deref()).collect();
    refuse_inputs_inside(out, &inputs)?;
    let mut registration = spec.build()?;
    let organ_frame = registration.frame();
    let mut input =
        PointInput::new(organ_frame, LengthUnit::Metre, spec.given_units).with_given_frame(spec.given_frame);
    let frames = read_frames(cloud)?;
    // A truth that does not fit the targets may be explained by how they were read (points left out).
    let truths =
        truth.map(|p| input.read_truths(p, frames.len(), registration.target_labels())).transpose().map_err(|e| {
            match registration.warnings() {
                [] => e,
                warnings => e.context(format!("the truth (--truth), after these warnings: {}", warnings.join("; "))),
            }
        })?;
    setup_lines(&registration, &spec.frame_line(&registration, input.named_frame())).iter().for_each(|l| say(l));
    let truth_warning = match truths.as_ref().and_then(|t| t.first()) {
        Some(truth) => register::plausibility::check_truth(registration.organ(), registration.targets(), truth)
            .context("the targets' truth (--truth)")?,
        None => None,
    };
    truth_warning.iter().for_each(|w| say(&format!("warning    {w}")));
    let sequence = frames.len() > 1;
    // Every frame read before any is written: a bad file late in a sequence leaves no half run.
    let clouds: Vec<Vec<Point>> = frames.iter().map(|f| input.read_cloud(f)).collect::<register::Result<_>>()?;
    let mut writer = RunWriter::new(out, sequence, spec.given_units, (organ_frame, spec.given_frame))?;
    truth_warning.into_iter().for_each(|w| writer.warn(w));
    let last_cloud = clouds.last().cloned().unwrap_or_default();
    let clouds = clouds.into_iter().map(Ok);
    let mut said_pose = None;
    let to_register_error = |e: anyhow::Error| register::RegisterError::Invalid(format!("{e:#}"));
    let outcomes = registration.register_sequence(clouds, truths.as_deref(), |i, organ, o| {
        if let Some(rigid) = o.rigid.as_ref().filter(|r| said_pose != Some(r.cloud_to_organ)) {
            rigid_lines(rigid, None).iter().for_each(|l| say(l));
            said_pose = Some(rigid.cloud_to_organ);
        }
        let row = writer.frame(i, frames[i].display().to_string(), organ, o).map_err(to_register_error)?;
        say(&frame_line(i, row));
        row.warnings.iter().for_each(|w| say(&format!("warning    frame {i}: {w}")));
        Ok(())
    })?;
    input.warnings.iter().for_each(|w| say(&format!("warning    {w}")));
    input.warnings.iter().for_each(|w| writer.warn(w.clone()));
    let last_truth = truths.as_ref().and_then(|t| t.last()).map(Vec::as_slice);
    let finished = writer.finish(&registration, input.frame, &outcomes, (&last_cloud, last_truth))?;
    run_lines(&outcomes, &finished.summary, spec.given_units).iter().for_each(|l| say(l));
    finished.notes.iter().for_each(|n| say(&format!("warning    {n}")));
    say(&format!(
        "wrote      {} ({}, targets.csv, summary.json, registration.png and .html; for 3D Slicer: {})",
        out.display(),
        if sequence { "organ.pvd" } else { "organ.vtu" },
        finished.for_slicer.join(", ")
    ));
    // A result flagged as not believable must not pass for one in a script's eyes.
    if outcomes.last().is_some_and(|o| !o.registration.plausible()) {
        anyhow::bail!(
            "the registration{} is not plausible (the warnings above; summary.json: \"plausible\": false): its \
             files in {} are kept to look at, not to navigate by (those for 3D Slicer named *{}.*)",
            if sequence { " of the last frame" } else { "" },
            out.display(),
            register::IMPLAUSIBLE
        );
    }
    Ok(())
}

/// Writes one registered `cloud` (in the organ's frame, m) into `dir` as [`register_files`] writes
/// a run of one frame, named `name`: in `unit` and in the clouds' frame of `(organ, given)` frames
/// (the organ's and the one the clouds were given in, each when known; the organ's when none was).
pub fn write_registered_cloud(
    dir: &Path,
    name: &str,
    registration: &Registration,
    (unit, (organ, given)): (LengthUnit, (Option<Frame>, Option<Frame>)),
    tracked: Tracked,
    cloud: &[Point],
) -> Result<Finished> {
    let outcome = tracked.into_outcome(None);
    let mut writer = RunWriter::new(dir, false, unit, (organ, given))?;
    writer.frame(0, name.into(), registration.organ(), &outcome)?;
    writer.finish(registration, organ, std::slice::from_ref(&outcome), (cloud, None))
}

/// Grid steps across the registered organ's largest extent, margins included, in displacement.nrrd.
const WARP_STEPS: usize = 64;

/// Writes a registration's displacement field (computed in the organ's frame, m) as 3D Slicer
/// loads a displacement-field transform (NRRD in LPS, mm; see
/// [`mesh::labelmap::write_displacement_nrrd`]): `change` takes it to the results' frame, named
/// `frame` (taken as LPS, Slicer's default for files, when unknown). Under this transform the
/// CT and its segmentations, at rest, appear as registered.
fn write_warp(path: &Path, field: &WarpField, change: FrameChange, frame: Option<Frame>) -> Result<()> {
    let to_lps = FrameChange::between(frame, Some(Frame::Lps));
    let lps = |p: Point| to_lps.point(change.point(p)).map(|x| LengthUnit::Millimetre.from_metres(x));
    let origin = lps(field.origin);
    let axes: [Point; 3] =
        std::array::from_fn(|c| lps(std::array::from_fn(|d| if d == c { field.spacing } else { 0.0 })));
    let affine = std::array::from_fn(|r| std::array::from_fn(|c| if c < 3 { axes[c][r] } else { origin[r] }));
    let vectors: Vec<Point> = field.vectors.iter().map(|&v| lps(v)).collect();
    Ok(mesh::labelmap::write_displacement_nrrd(path, field.dims, affine, &vectors)?)
}

/// Writes the rigid alignment `cloud_to_organ` (m, between the organ's frame and the cloud's
/// positions in it) as 3D Slicer loads a linear transform: an ITK transform file (LPS, mm), in
/// the resampling direction ITK files hold, from the parent (the cloud's frame) to the child (the
/// organ's, where displacement.nrrd lies); `change` takes the organ's frame to the results',
/// named `frame` (taken as LPS, Slicer's default for files, when unknown). Under it goes
/// displacement.nrrd, and under that the CT: everything then moves rigidly, however far from
/// the organ, and the organ as registered.
fn write_rigid_transform(
    path: &Path,
    cloud_to_organ: &register::RigidTransform,
    change: FrameChange,
    frame: Option<Frame>,
) -> Result<()> {
    let to_lps = FrameChange::between(frame, Some(Frame::Lps));
    // A sign change of x and y, or none: its own inverse.
    let lps = |p: Point| to_lps.point(change.point(p));
    let columns: [Point; 3] =
        std::array::from_fn(|c| lps(cloud_to_organ.rotate(lps(std::array::from_fn(|d| f64::from(u8::from(c == d)))))));
    let shift = lps(cloud_to_organ.translation).map(|x| LengthUnit::Millimetre.from_metres(x));
    let matrix = (0..3).flat_map(|r| columns.map(|column| column[r]));
    let parameters: Vec<String> = matrix.chain(shift).map(|x| x.to_string()).collect();
    let text = format!(
        "#Insight Transform File V1.0\n#Transform 0\nTransform: AffineTransform_double_3_3\nParameters: {}\n\
         FixedParameters: 0 0 0\n",
        parameters.join(" ")
    );
    Ok(write_atomic_bytes(path, text.as_bytes())?)
}

/// The organ mesh and a displacement in the cloud's frame: as given without a rigid alignment;
/// with one, the mesh moved by it (`moved`, when already computed with that alignment) and the
/// displacement rotated.
fn mesh_in_cloud_frame<'a>(
    organ: &'a Mesh,
    moved: Option<&'a Mesh>,
    rigid: Option<&RigidResult>,
    u: &[f64],
) -> (Cow<'a, Mesh>, Vec<f64>) {
    match rigid {
        None => (Cow::Borrowed(organ), u.to_vec()),
        Some(r) => {
            let t = r.organ_to_cloud();
            let m = match moved {
                Some(m) => Cow::Borrowed(m),
                None => Cow::Owned(t.move_mesh(organ)),
            };
            (m, t.rotate_field(u))
        }
    }
}

/// targets.csv: rest and registered position of each target (in `unit`, e.g. m: columns `x0_m,
/// y0_m, z0_m, x_m, y_m, z_m`), with the method's predicted standard deviation σ of each target's
/// error, when it predicts one, as a column `sigma_m`, and the targets' labels, when they have
/// any, as a last column `label`; a first line `# CoordinateSystem = RAS` (or LPS) names `frame`
/// when known, as 3D Slicer's files do.
fn write_targets(
    path: &Path,
    rest: &[Point],
    registered: &[Point],
    sigma: Option<&[f64]>,
    labels: &[String],
    (unit, frame): (LengthUnit, Option<Frame>),
) -> Result<()> {
    let labelled = labels.len() == rest.len() && labels.iter().any(|l| !l.is_empty());
    let symbol = unit.symbol();
    let mut header: Vec<String> = ["x0", "y0", "z0", "x", "y", "z"].iter().map(|c| format!("{c}_{symbol}")).collect();
    header.extend(sigma.map(|_| format!("sigma_{symbol}")));
    header.extend(labelled.then(|| "label".to_string()));
    let header: Vec<&str> = header.iter().map(String::as_str).collect();
    let rows = rest.iter().zip(registered).enumerate().map(|(i, (a, b))| {
        let values = a.iter().chain(b).chain(sigma.map(|s| &s[i]));
        let mut row: Vec<String> = values.map(|&v| unit.from_metres(v).to_string()).collect();
        row.extend(labelled.then(|| labels[i].clone()));
        row
    });
    let settings: Vec<String> = frame.map(|f| format!("CoordinateSystem = {f}")).into_iter().collect();
    Ok(mesh::io::csv::write_csv(path, &settings, &header, rows)?)
}

/// The registered targets as 3D Slicer markups (`.mrk.json`), in millimetres and in `frame` when
/// known: each target's name ([`register::Registration::target_names`]) and σ in its description.
fn write_targets_for_slicer(
    path: &Path,
    registered: &[Point],
    sigma: Option<&[f64]>,
    names: &[String],
    frame: Option<Frame>,
) -> Result<()> {
    let millimetres = LengthUnit::Millimetre;
    let points = LabelledPoints {
        points: registered.iter().map(|&p| millimetres.point_from_metres(p)).collect(),
        labels: names.to_vec(),
        descriptions: (0..registered.len())
            .map(|i| sigma.map_or(String::new(), |s| format!("sigma {:.2} mm", mm(s[i]))))
            .collect(),
        frame,
        unit: Some(millimetres),
        ..Default::default()
    };
    Ok(write_markups_json(path, &points)?)
}

/// Writes a synthetic case's files into `dir`: cloud.csv and truth.csv (of the peak frame),
/// targets_rest.csv and, for a case of several frames, clouds/cloud_NNNN.csv and
/// truths/truth_NNNN.csv of every frame, in metres, which their headers name (`x_m, y_m, z_m`).
pub fn write_case(dir: &Path, case: &SyntheticCase) -> Result<()> {
    let write = |path: PathBuf, points: &[Point]| -> Result<()> {
        let mut labelled = LabelledPoints::new(points.to_vec());
        labelled.unit = Some(LengthUnit::Metre);
        Ok(mesh::io::points::write_points(path, &labelled)?)
    };
    let peak = case.peak();
    write(dir.join("cloud.csv"), &peak.cloud)?;
    write(dir.join("targets_rest.csv"), &case.targets)?;
    write(dir.join("truth.csv"), &peak.truth)?;
    if case.frames.len() > 1 {
        for (k, frame) in case.frames.iter().enumerate() {
            write(dir.join("clouds").join(format!("cloud_{k:04}.csv")), &frame.cloud)?;
            write(dir.join("truths").join(format!("truth_{k:04}.csv")), &frame.truth)?;
        }
    }
    Ok(())
}

/// Writes a comparison of methods on a synthetic case into `dir`: comparison.csv (a row per
/// method, after the baseline of not deforming, or of the rigid alignment alone),
/// summary.json (each method's figures or error), and per registered method a directory (its
/// name's slug) with organ.vtu, targets.csv and registration.png (a side view of the peak frame
/// with the cloud, the registered targets and the truth).
pub fn write_comparison(dir: &Path, case: &SyntheticCase, rows: &[Compared]) -> Result<()> {
    let registered: Vec<&Registered> = rows.iter().filter_map(|r| r.result.as_ref().ok()).collect();
    let peak = case.peak();
    let header: Vec<&str> =
        std::iter::once("method").chain(COMPARISON_COLUMNS.map(|(column, _)| column)).chain(["error"]).collect();
    let table: Vec<Vec<String>> = comparison_rows(rows)
        .into_iter()
        .map(|(name, values, error)| {
            let fields = values.map(|v| v.map_or(String::new(), |v| v.to_string()));
            std::iter::once(name).chain(fields).chain([error]).collect()
        })
        .collect();
    for reg in &registered {
        let (s, outcome) = (&reg.summary, reg.peak(case));
        let method_dir = dir.join(slug(&s.method));
        mesh::io::create_folder(&method_dir)?;
        let u = &outcome.registration.u;
        let (m, u_cloud) = mesh_in_cloud_frame(reg.organ.mesh(), None, outcome.rigid.as_ref(), u);
        mesh::io::write_mesh(method_dir.join("organ.vtu"), &m, &[Field::point("displacement", 3, u_cloud)])?;
        let rest_targets = in_cloud_frame(case.targets.clone(), outcome.rigid.as_ref());
        let sigma = outcome.target_std.as_deref();
        let csv = method_dir.join("targets.csv");
        write_targets(&csv, &rest_targets, &outcome.targets, sigma, &[], (LengthUnit::Metre, None))?;
        // The picture's own frame's TRE: a sequence's mean over its frames is not what it shows.
        let tre = outcome.tre_mm().map_or(f64::NAN, |(mean, _)| mean);
        let frame = match case.frames.len() {
            1 => String::new(),
            n => format!(", frame {} of {n} (the peak)", case.peak_index() + 1),
        };
        let title = format!("{}: TRE mean {tre:.2} mm{frame}", s.method);
        let targets = (case.targets.as_slice(), outcome.targets.as_slice());
        RegisteredFrame::new(&reg.organ, u, outcome.rigid.as_ref(), &peak.cloud, targets, Some(&peak.truth)).write(
            &method_dir.join("registration"),
            &title,
            frame_notes(
                frame_line(case.peak_index(), &FrameSummary::new(String::new(), outcome)),
                outcome.target_std.as_deref(),
                &outcome.registration.warnings,
            ),
        )?;
    }
    mesh::io::create_folder(dir)?;
    mesh::io::csv::write_csv(&dir.join("comparison.csv"), &[], &header, table)?;
    let summaries: Vec<serde_json::Value> = rows
        .iter()
        .map(|r| match &r.result {
            Ok(reg) => serde_json::to_value(&reg.summary),
            Err(e) => Ok(serde_json::json!({ "method": r.method, "error": e.to_string() })),
        })
        .collect::<Result<_, _>>()?;
    write_atomic_bytes(&dir.join(SUMMARY_FILE), serde_json::to_string_pretty(&summaries)?.as_bytes())?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A field in RAS is written in LPS, the file's frame for Slicer: its origin and axes with x
    /// and y negated; in LPS, or in no known frame (Slicer's LPS), as it is; in mm.
    #[test]
    fn a_displacement_field_is_written_in_lps_millimetres() {
        let dir = tempfile::tempdir().unwrap();
        let field = WarpField {
            origin: [0.01, 0.02, 0.03],
            spacing: 0.005,
            dims: [2, 2, 2],
            vectors: vec![[0.0; 3]; 8],
            inverted: 0,
        };
        let header = |frame: Option<Frame>| {
            let path = dir.path().join("field.nrrd");
            write_warp(&path, &field, FrameChange::default(), frame).unwrap();
            let bytes = std::fs::read(&path).unwrap();
            let end = bytes.windows(2).position(|w| w == b"\n\n").unwrap();
            String::from_utf8(bytes[..end].to_vec()).unwrap()
        };
        let ras = header(Some(Frame::Ras));
        assert!(ras.contains("space origin: (-10,-20,30)"), "{ras}");
        assert!(ras.contains("space directions: none (-5,0,0) (0,-5,0) (0,0,5)"), "{ras}");
        assert!(ras.ends_with("\ndisplacement field type:=resampling"), "{ras}");
        for lps in [header(Some(Frame::Lps)), header(None)] {
            assert!(lps.contains("space origin: (10,20,30)"), "{lps}");
            assert!(lps.contains("space directions: none (5,0,0) (0,5,0) (0,0,5)"), "{lps}");
        }
    }

    /// The rigid alignment, written for 3D Slicer in LPS and mm, takes a point of the cloud's
    /// frame to the organ's as the alignment does, whatever frame the results are in.
    #[test]
    fn a_rigid_alignment_is_written_as_an_itk_transform_in_lps() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("rigid.tfm");
        let cloud_to_organ =
            register::RigidTransform::from_axis_angle([1.0, 2.0, 3.0], 0.4, [0.01, -0.02, 0.03]).unwrap();
        let cloud = [0.05, -0.01, 0.02];
        for frame in [Some(Frame::Ras), Some(Frame::Lps), None] {
            write_rigid_transform(&path, &cloud_to_organ, FrameChange::default(), frame).unwrap();
            let text = std::fs::read_to_string(&path).unwrap();
            assert!(text.starts_with("#Insight Transform File V1.0\n") && text.contains("FixedParameters: 0 0 0"));
            let line = text.lines().find_map(|l| l.strip_prefix("Parameters: ")).unwrap();
            let p: Vec<f64> = line.split(' ').map(|x| x.parse().unwrap()).collect();
            // Both points in LPS mm: RAS ones with x and y negated.
            let sign = if frame == Some(Frame::Ras) { [-1.0, -1.0, 1.0] } else { [1.0; 3] };
            let lps = |q: Point| std::array::from_fn::<f64, 3, _>(|d| 1e3 * sign[d] * q[d]);
            let x = lps(cloud);
            let image: Point = std::array::from_fn(|r| (0..3).map(|c| p[3 * r + c] * x[c]).sum::<f64>() + p[9 + r]);
            let expected = lps(cloud_to_organ.apply(cloud));
            assert!(mesh::distance(image, expected) < 1e-9, "{frame:?}: {image:?} vs {expected:?}");
        }
    }

    #[test]
    fn each_run_gets_a_folder_of_its_own() {
        let dir = tempfile::tempdir().unwrap();
        let parent = dir.path().join("runs");
        let (first, fresh) = run_dir(None, &parent).unwrap();
        assert!(fresh && first == parent.join("001") && first.is_dir());
        assert_eq!(run_dir(None, &parent).unwrap().0, parent.join("002"));
        let given = dir.path().join("mine");
        assert_eq!(run_dir(Some(&given), &parent).unwrap(), (given.clone(), true), "not there yet: the run's own");
        std::fs::create_dir_all(&given).unwrap();
        assert_eq!(run_dir(Some(&given), &parent).unwrap(), (given.clone(), false), "there already: the user's");
        // An assimilation stopped before its summary (its steps' deformations).
        let steps = dir.path().join("assimilation");
        std::fs::create_dir_all(steps.join("deformation")).unwrap();
        std::fs::write(steps.join("deformation/step_00003.vtu"), "").unwrap();
        let e = run_dir(Some(&steps), &parent).unwrap_err().to_string();
        assert!(e.contains("holds 1 frame(s) of an earlier run stopped") && e.contains("step_NNNNN.vtu"), "{e}");
        std::fs::write(given.join("organ_0007.vtu"), "").unwrap();
        let e = run_dir(Some(&given), &parent).unwrap_err().to_string();
        assert!(e.contains("holds 1 frame(s) of an earlier run stopped before its summary"), "{e}");
        std::fs::write(given.join("summary.json"), "{}").unwrap();
        let e = run_dir(Some(&given), &parent).unwrap_err().to_string();
        assert!(e.contains("holds the results of an earlier run"), "{e}");
        // A user's own files, which the run's of the same names would replace; a patient's set-up
        // (its mesh is organ.vtu, not a frame).
        let notes = dir.path().join("notes");
        std::fs::create_dir_all(&notes).unwrap();
        std::fs::write(notes.join("targets.csv"), "mine").unwrap();
        let e = run_dir(Some(&notes), &parent).unwrap_err().to_string();
        assert!(e.contains("holds 1 file(s) or folder(s) of its own (targets.csv)"), "{e}");
        let patient = dir.path().join("patient");
        std::fs::create_dir_all(&patient).unwrap();
        for file in [crate::setup::PATIENT_FILE, "organ.vtu"] {
            std::fs::write(patient.join(file), "").unwrap();
        }
        let e = run_dir(Some(&patient), &parent).unwrap_err().to_string();
        assert!(e.contains("holds 2 file(s) or folder(s) of its own (organ.vtu, registration.toml)"), "{e}");
    }

    /// Each frame's organ is moved by that frame's pose: a pose estimated again moves it anew.
    #[test]
    fn each_frame_s_organ_is_written_in_its_own_pose() {
        let dir = tempfile::tempdir().unwrap();
        let organ = Organ::new(mesh::box_tet([0.0; 3], [0.05; 3], [2, 2, 2]).unwrap(), None).unwrap();
        let n = organ.mesh().num_nodes();
        let outcome = |shift: Point| FrameOutcome {
            registration: register::FrameResult {
                u: vec![0.0; 3 * n],
                iterations: 1,
                from_rest: true,
                surface_residual: 0.0,
                far_share: 0.0,
                warnings: Vec::new(),
                distorted: false,
                other_frame: false,
                small_view: false,
                out_of_time: false,
                points: 100,
                inliers: 100,
                time: std::time::Duration::ZERO,
            },
            targets: Vec::new(),
            errors: None,
            rest_errors: None,
            rigid: Some(RigidResult {
                cloud_to_organ: RigidTransform::from_axis_angle([0.0, 0.0, 1.0], 0.0, shift).unwrap(),
                iterations: 1,
                converged: true,
                rms: 0.0,
                kept: 100,
                points: 100,
                time: std::time::Duration::ZERO,
            }),
            target_std: None,
        };
        let mut writer = RunWriter::new(dir.path(), true, LengthUnit::Metre, (None, None)).unwrap();
        let shifts = [[0.01, 0.0, 0.0], [0.01, 0.0, 0.0], [0.0, -0.02, 0.0]];
        for (i, &shift) in shifts.iter().enumerate() {
            writer.frame(i, format!("cloud {i}"), &organ, &outcome(shift)).unwrap();
            let written = mesh::io::read_mesh(dir.path().join(format!("organ_{i:04}.vtu"))).unwrap();
            for (w, p) in written.nodes.iter().zip(&organ.mesh().nodes) {
                // The organ goes to the cloud by the inverse of the cloud-to-organ shift.
                assert!((0..3).all(|d| (w[d] - (p[d] - shift[d])).abs() < 1e-12), "frame {i}: {w:?} for {p:?}");
            }
        }
    }

    #[test]
    fn targets_csv_names_its_unit_sigma_and_labels() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("targets.csv");
        let (rest, moved) = ([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]], [[0.0, 0.0, 0.5], [1.0, 0.0, 0.5]]);
        let labels = ["T1".to_string(), "deep, left".to_string()];
        write_targets(&path, &rest, &moved, Some(&[0.001, 0.002]), &labels, (LengthUnit::Metre, None)).unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        assert_eq!(
            text,
            "x0_m,y0_m,z0_m,x_m,y_m,z_m,sigma_m,label\n0,0,0,0,0,0.5,0.001,T1\n1,0,0,1,0,0.5,0.002,\"deep, left\"\n"
        );
        // Read back as points: the registered positions, in metres, with their labels.
        let back = mesh::io::points::read_points(&path).unwrap();
        assert_eq!((back.points, back.labels), (moved.to_vec(), vec!["T1".to_string(), "deep, left".to_string()]));
        write_targets(&path, &rest, &moved, None, &["".into(), "".into()], (LengthUnit::Metre, None)).unwrap();
        assert!(std::fs::read_to_string(&path).unwrap().starts_with("x0_m,y0_m,z0_m,x_m,y_m,z_m\n0,0,0,"));
        // In millimetres: the header names them, and the points read back are where they were.
        write_targets(&path, &rest, &moved, Some(&[0.001, 0.002]), &labels, (LengthUnit::Millimetre, None)).unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        assert!(text.starts_with("x0_mm,y0_mm,z0_mm,x_mm,y_mm,z_mm,sigma_mm,label\n0,0,0,0,0,500,1,T1\n"), "{text}");
        assert_eq!(mesh::io::points::read_points_csv(&path).unwrap(), moved);
        // A known frame is named on a first line, as 3D Slicer's files do, and read back.
        write_targets(&path, &rest, &moved, None, &labels, (LengthUnit::Millimetre, Some(Frame::Lps))).unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        assert!(text.starts_with("# CoordinateSystem = LPS\nx0_mm,"), "{text}");
        assert_eq!(mesh::io::points::read_points(&path).unwrap().frame, Some(Frame::Lps));
    }
}
