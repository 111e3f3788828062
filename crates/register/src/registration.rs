//! Registration of a sequence of frames: each frame warm-started from the previous one, the
//! targets carried along, their registration errors (TRE) where the truth is known, and the
//! summary of the run.
//!
//! With a rigid pre-alignment ([`RegistrationOptions::rigid`]) the cloud is moved onto the organ
//! (the transform estimated on a frame and kept for the next ones while they register without a
//! warning), registered there, and
//! the registered targets are moved back: targets and errors are in the cloud's frame.

use mesh::io::{Frame, GivenCoordinates};
use mesh::length::mm;
use mesh::stats::{max, mean, ms};
use mesh::{Point, TriSurface};
use serde::Serialize;

use crate::frame::{register_frame_begun, Deformer, FrameResult, RegistrationOptions};
use crate::organ::{displaced, moved_surface, Organ, Stencil};
use crate::rigid::{in_cloud_frame, rigid_align, RigidResult, RigidSummary};
use crate::{RegisterError, Result, Structure};

/// Names a structure cannot take: those of what a registration writes and of the server's
/// messages.
pub const RESERVED_NAMES: [&str; 12] = [
    "organ",
    "targets",
    "rigid",
    "status",
    "cloud",
    "features",
    "estimate",
    "warning",
    "reset",
    "registration",
    "displacement",
    "summary",
];

/// One registered frame.
#[derive(Clone, Debug)]
pub struct FrameOutcome {
    /// The registration (displacement in the organ's frame, iterations, residual, time: the
    /// rigid alignment's included on the frame that estimated it).
    pub registration: FrameResult,
    /// Registered target positions, in the cloud's frame.
    pub targets: Vec<Point>,
    /// Distance of each registered target from its true position (m), when the truth is known.
    pub errors: Option<Vec<f64>>,
    /// Distance of each rest target (moved by the rigid alignment, if any) from its true position
    /// (m): the error of not deforming.
    pub rest_errors: Option<Vec<f64>>,
    /// The rigid pre-alignment, when the options ask for one.
    pub rigid: Option<RigidResult>,
    /// The predicted standard deviation of each target's error (m), for a method that predicts
    /// one.
    pub target_std: Option<Vec<f64>>,
}

impl FrameOutcome {
    /// Mean and largest TRE of the frame (mm), when the truth is known.
    pub fn tre_mm(&self) -> Option<(f64, f64)> {
        self.errors.as_ref().filter(|e| !e.is_empty()).map(|e| (mm(mean(e)), mm(max(e))))
    }
}

/// A registration under way: an organ, what deforms it, targets inside it and the loop's
/// settings. Clouds are registered one after the other, each warm-started from the previous one's
/// displacement; with a rigid pre-alignment in the options, the cloud's pose is estimated (trimmed
/// ICP to the organ's rest surface) on a cloud and kept while the next ones register without a
/// warning (after a warning, the next cloud estimates it again); the targets are carried along
/// in the cloud's frame. What `augsim register`, `augsim serve` (one per client), the Python
/// `Registration` and the experiments run.
pub struct Registration {
    organ: Organ,
    deformer: Box<dyn Deformer + Send>,
    method: String,
    targets: Vec<Point>,
    labels: Vec<String>,
    frame: Option<Frame>,
    stencils: Vec<Stencil>,
    options: RegistrationOptions,
    warnings: Vec<String>,
    warm: Option<Vec<f64>>,
    rigid: Option<RigidResult>,
    structures: Vec<Structure>,
    surface: Option<Structure>,
    /// The factor on the method's σ at the targets ([`Registration::calibrate_sigma`]).
    sigma_factor: f64,
}

/// The longest name of a structure (bytes): a structure streams under its name as an
/// OpenIGTLink device name, a field of 20 bytes.
pub const STRUCTURE_NAME_BYTES: usize = 20;

/// Refuses a structure's name that is empty, longer than [`STRUCTURE_NAME_BYTES`], `taken` by
/// another, one of [`RESERVED_NAMES`], or ends in [`crate::IMPLAUSIBLE`] (the names of an
/// implausible result's answers).
pub fn check_structure_name(name: &str, taken: &[&str]) -> Result<()> {
    if name.len() > STRUCTURE_NAME_BYTES {
        return Err(RegisterError::Invalid(format!(
            "a structure's name `{name}` is longer than {STRUCTURE_NAME_BYTES} bytes, an OpenIGTLink device name's \
             field: give a shorter one (NAME=SOURCE)"
        )));
    }
    let reserved = RESERVED_NAMES.contains(&name) || name.ends_with(crate::IMPLAUSIBLE);
    if name.is_empty() || reserved || taken.contains(&name) {
        return Err(RegisterError::Invalid(format!(
            "a structure cannot be named `{name}`: names are unique, none of {} and none ends in {} (give another: \
             NAME=SOURCE)",
            RESERVED_NAMES.join(", "),
            crate::IMPLAUSIBLE
        )));
    }
    Ok(())
}

/// A registered cloud's figures in the coordinates its clouds are given in
/// ([`Tracked::given_back`]).
#[derive(Clone, Debug, PartialEq)]
pub struct GivenBack {
    /// The registered targets.
    pub targets: Vec<Point>,
    /// The predicted standard deviation of each target's error, for a method that predicts one.
    pub target_std: Option<Vec<f64>>,
    /// The mean distance from the cloud to the registered surface.
    pub surface_residual: f64,
    /// The rigid pre-alignment, organ to cloud (homogeneous 4 × 4, rows), when there is one.
    pub organ_to_cloud: Option<[[f64; 4]; 4]>,
}

/// One cloud registered by a [`Registration`].
#[derive(Clone, Debug)]
pub struct Tracked {
    /// The registration (displacement in the organ's frame, iterations, residual, time: the
    /// rigid alignment's included on the cloud that estimated it).
    pub registration: FrameResult,
    /// The registered targets, in the cloud's frame.
    pub targets: Vec<Point>,
    /// The rigid pre-alignment, when the options ask for one.
    pub rigid: Option<RigidResult>,
    /// The predicted standard deviation of each target's error (m), for a method that predicts
    /// one.
    pub target_std: Option<Vec<f64>>,
}

impl Tracked {
    /// The frame's outcome; with `(truth, rest)`, the targets' true positions and their rest
    /// positions (both in the cloud's frame), its errors and those of not deforming.
    pub fn into_outcome(self, truth: Option<(&[Point], &[Point])>) -> FrameOutcome {
        let Tracked { registration, targets, rigid, target_std } = self;
        FrameOutcome {
            errors: truth.map(|(t, _)| target_errors(&targets, t)),
            rest_errors: truth.map(|(t, rest)| target_errors(rest, t)),
            targets,
            registration,
            rigid,
            target_std,
        }
    }

    /// What a front (a stream's answer, Python's result) gives back of it in the coordinates the
    /// clouds are `given` in: the targets, their σ, the surface residual and the pose.
    pub fn given_back(&self, given: GivenCoordinates) -> GivenBack {
        GivenBack {
            targets: self.targets.iter().map(|&p| given.point_out(p)).collect(),
            target_std: self.target_std.as_ref().map(|s| s.iter().map(|&v| given.length_out(v)).collect()),
            surface_residual: given.length_out(self.registration.surface_residual),
            organ_to_cloud: self
                .rigid
                .as_ref()
                .map(|r| given.transform_out(r.organ_to_cloud().homogeneous(mesh::length::LengthUnit::Metre))),
        }
    }

    /// The registered organ surface, in the cloud's frame ([`Registration::deformed_surface`]).
    pub fn organ_surface(&self, registration: &Registration) -> mesh::TriSurface {
        registration.deformed_surface(&self.registration.u, self.rigid.as_ref())
    }
}

impl Registration {
    /// The registration of `organ` by `deformer` (`method`: its name in words) of the `targets`
    /// (rest positions, m; `labels`: one each, a targets file's, "" where it gives none, or none
    /// at all) with `options`. An error for invalid options, no target, a number of labels other
    /// than the targets', or a target outside the organ (naming it, and the likely unit mistake
    /// when the targets fit the organ read in the other unit); a set of targets much smaller than
    /// the organ is accepted with a warning ([`Registration::warnings`]).
    pub fn new(
        organ: Organ,
        deformer: Box<dyn Deformer + Send>,
        method: impl Into<String>,
        targets: Vec<Point>,
        labels: Vec<String>,
        options: RegistrationOptions,
    ) -> Result<Registration> {
        options.validate()?;
        if targets.is_empty() {
            return Err(RegisterError::Invalid("no targets".into()));
        }
        let labels = if labels.is_empty() { vec![String::new(); targets.len()] } else { labels };
        if labels.len() != targets.len() {
            return Err(RegisterError::Invalid(format!("{} labels for {} targets", labels.len(), targets.len())));
        }
        let (stencils, warnings) = organ.locate_targets(&targets, &labels)?;
        Ok(Registration {
            organ,
            deformer,
            method: method.into(),
            labels,
            targets,
            frame: None,
            stencils,
            options,
            warnings,
            warm: None,
            rigid: None,
            structures: Vec::new(),
            surface: None,
            sigma_factor: 1.0,
        })
    }

    /// Gives the organ's own surface (a segmentation's, finer than its mesh's boundary: m, the
    /// organ's frame), which [`Registration::deformed_surface`] then gives back moved with the
    /// organ in place of its mesh's boundary. Its vertices outside the mesh (a mesh smooths what
    /// is thinner than its cells) move as the mesh's nearest surface point.
    pub fn set_surface(&mut self, surface: TriSurface) -> Result<()> {
        let (surface, _outside) = Structure::new(&self.organ, "organ", surface)?;
        self.surface = Some(surface);
        Ok(())
    }

    /// Scales the σ the method gives at the targets by `factor` (positive and finite): its
    /// calibration on registrations whose truth is known (a patient's validation).
    pub fn calibrate_sigma(&mut self, factor: f64) -> Result<()> {
        crate::checks::check_setting("sigma factor", factor, factor > 0.0, "positive and finite")?;
        self.sigma_factor = factor;
        Ok(())
    }

    /// The organ's own surface at rest, when given ([`Registration::set_surface`]).
    pub fn own_surface(&self) -> Option<&TriSurface> {
        self.surface.as_ref().map(Structure::rest)
    }

    /// The organ's surface displaced by `u`, in the cloud's frame (moved by `rigid`, if any): its
    /// own ([`Registration::set_surface`]) when given, else its mesh's boundary.
    pub fn deformed_surface(&self, u: &[f64], rigid: Option<&RigidResult>) -> TriSurface {
        match &self.surface {
            Some(surface) => surface.deformed(u, rigid),
            None => moved_surface(self.organ.surface(), self.organ.surface_stencils(), u, rigid),
        }
    }

    /// Each structure with its surface moved with the organ by `u`, in the cloud's frame (moved by
    /// `rigid`, if any; [`Structure::deformed`]).
    pub fn structure_surfaces(&self, u: &[f64], rigid: Option<&RigidResult>) -> Vec<(&str, TriSurface)> {
        self.structures.iter().map(|s| (s.name(), s.deformed(u, rigid))).collect()
    }

    /// Adds a structure that moves with the organ (a tumour, vessels: [`Structure::new`]), named
    /// `name`, its surface in m in the organ's frame; its warnings join the registration's. An
    /// error for a name already taken, or one of the server's messages' (`organ`, `targets`…).
    pub fn add_structure(&mut self, name: &str, surface: TriSurface) -> Result<()> {
        self.add_structure_of(name, surface, false)
    }

    /// [`Registration::add_structure`] for a surface known to be in the organ's frame
    /// ([`Structure::in_organ_frame`]).
    pub fn add_structure_in_organ_frame(&mut self, name: &str, surface: TriSurface) -> Result<()> {
        self.add_structure_of(name, surface, true)
    }

    /// [`Registration::add_structure`], `in_organ_frame` or not.
    fn add_structure_of(&mut self, name: &str, surface: TriSurface, in_organ_frame: bool) -> Result<()> {
        let taken: Vec<&str> = self.structures.iter().map(Structure::name).collect();
        check_structure_name(name, &taken)?;
        let (structure, warnings) = match in_organ_frame {
            true => Structure::in_organ_frame(&self.organ, name, surface)?,
            false => Structure::new(&self.organ, name, surface)?,
        };
        self.structures.push(structure);
        self.warnings.extend(warnings);
        Ok(())
    }

    /// The structures that move with the organ, in the order added.
    pub fn structures(&self) -> &[Structure] {
        &self.structures
    }

    /// The organ (its mesh and surface, in m, at rest).
    pub fn organ(&self) -> &Organ {
        &self.organ
    }

    /// The organ, the registration ended.
    pub fn into_organ(self) -> Organ {
        self.organ
    }

    /// The method in words (e.g. `FEM, Corotational (Standard elements)`).
    pub fn method(&self) -> &str {
        &self.method
    }

    /// The targets' rest positions (m).
    pub fn targets(&self) -> &[Point] {
        &self.targets
    }

    /// The same registration, its organ and targets in `frame` (RAS or LPS), where known.
    pub fn in_frame(self, frame: Option<Frame>) -> Registration {
        Registration { frame, ..self }
    }

    /// The targets' labels, in order ("" for a target not named: [`Registration::new`]).
    pub fn target_labels(&self) -> &[String] {
        &self.labels
    }

    /// The targets' names, in order: each one's label, `target-N` (from 1) for one not named; what
    /// 3D Slicer shows beside a control point, in files and on a stream alike.
    pub fn target_names(&self) -> Vec<String> {
        let name = |(k, label): (usize, &String)| match label.is_empty() {
            true => format!("target-{}", k + 1),
            false => label.clone(),
        };
        self.labels.iter().enumerate().map(name).collect()
    }

    /// The frame (RAS or LPS) of the organ and its targets, `None` when unknown.
    pub fn frame(&self) -> Option<Frame> {
        self.frame
    }

    /// The loop's settings.
    pub fn options(&self) -> &RegistrationOptions {
        &self.options
    }

    /// Why the targets or structures may not be what was meant (e.g. a set of targets far smaller
    /// than the organ: a unit mistake; a structure leaving the organ); empty when they look right.
    pub fn warnings(&self) -> &[String] {
        &self.warnings
    }

    /// Adds a warning about the targets, one found where they were read (e.g. points of their
    /// file left out).
    pub fn warn(&mut self, warning: impl Into<String>) {
        self.warnings.push(warning.into());
    }

    /// Registers `cloud` (m, in its own frame), starting from the previous cloud's displacement,
    /// which it then replaces; a failed cloud leaves the warm start and the pose as they were. The
    /// pose, when rigid pre-alignment is on, is estimated on a cloud and kept for the next ones
    /// while they register plausibly ([`FrameResult::plausible`]: a frame stopped by its time
    /// budget keeps it): a cloud with another warning has the next one estimate it again, and a
    /// cloud that leaves the organ distorted ([`FrameResult::distorted`]), lies on it in the
    /// other frame ([`FrameResult::other_frame`]) or spans under a tenth of it
    /// ([`FrameResult::small_view`]: centimetres read as millimetres) has it start from rest.
    pub fn register(&mut self, cloud: &[Point]) -> Result<Tracked> {
        let began = std::time::Instant::now();
        // The pose, estimated on this cloud or kept; when estimated, whether the cloud fits the
        // organ in the other frame (a turn by 180° that the alignment cannot find) is asked first.
        let estimated = self.options.rigid.is_some() && self.rigid.is_none();
        let (rigid, mut mix_up) = match (&self.options.rigid, &self.rigid) {
            (Some(rigid_options), None) => {
                // A cloud in another unit is named as such, before an alignment it would defeat.
                crate::plausibility::check_extent(&self.organ, cloud)?;
                let mix_up = crate::plausibility::frame_mix_up(&self.organ, cloud);
                match (rigid_align(self.organ.surface(), cloud, rigid_options), mix_up) {
                    (Err(e), Some(hint)) => return Err(RegisterError::Invalid(format!("{e}; {hint}"))),
                    (aligned, mix_up) => (Some(aligned?), Some(mix_up)),
                }
            }
            (_, known) => (known.clone(), None),
        };
        let moved: Vec<Point>;
        let in_organ = match &rigid {
            Some(r) => {
                moved = cloud.iter().map(|&p| r.cloud_to_organ.apply(p)).collect();
                &moved
            }
            None => cloud,
        };
        let mut registration = register_frame_begun(
            began,
            &self.organ,
            self.deformer.as_mut(),
            in_organ,
            self.warm.as_deref(),
            &self.options,
        )?;
        if let Some(r) = rigid.as_ref().filter(|r| estimated && !r.converged) {
            registration.warnings.push(format!(
                "the rigid pre-alignment did not converge in {} iterations: its pose may be wrong",
                r.iterations
            ));
        }
        // Without a pre-alignment the frame's verdict asks itself; in a kept pose, a frame with a
        // warning asks here, of the cloud as given.
        if rigid.is_some() && mix_up.is_none() && !registration.warnings.is_empty() {
            mix_up = Some(crate::plausibility::frame_mix_up(&self.organ, cloud));
        }
        if let Some(hint) = mix_up.flatten() {
            registration.other_frame = true;
            registration.warnings.push(hint);
        }
        let targets = in_cloud_frame(displaced(&self.targets, &self.stencils, &registration.u), rigid.as_ref());
        // σ is part of the frame's work, and of its time (not cut by its budget).
        let target_std = self.deformer.uncertainty(&self.stencils).transpose()?;
        let target_std = target_std.map(|std| std.into_iter().map(|s| s * self.sigma_factor).collect());
        registration.time = began.elapsed();
        // A cloud only partly fitted is still the best start for the next (a stream tracks a hard
        // push better than a frame from rest); a distorted organ, a cloud in another frame or unit,
        // is not (docs/method.md, 6.6).
        let no_start = registration.distorted || registration.other_frame || registration.small_view;
        self.warm = (!no_start).then(|| registration.u.clone());
        self.rigid = if registration.plausible() { rigid.clone() } else { None };
        Ok(Tracked { registration, targets, rigid, target_std })
    }

    /// Forgets the previous cloud and the pose: the next cloud starts from rest.
    pub fn reset(&mut self) {
        self.warm = None;
        self.rigid = None;
    }

    /// Registers each cloud of `frames` in turn, each starting from the previous one's
    /// displacement; `truths` (one list per frame, in the order of the targets, in the cloud's
    /// frame) are the targets' true deformed positions. `on_frame` sees each frame, with the
    /// organ, as soon as it is registered (to print or write it).
    pub fn register_sequence(
        &mut self,
        frames: impl IntoIterator<Item = Result<Vec<Point>>>,
        truths: Option<&[Vec<Point>]>,
        mut on_frame: impl FnMut(usize, &Organ, &FrameOutcome) -> Result<()>,
    ) -> Result<Vec<FrameOutcome>> {
        let n = self.targets.len();
        if let Some((i, t)) = truths.into_iter().flatten().enumerate().find(|(_, t)| t.len() != n) {
            return Err(RegisterError::Invalid(format!(
                "the truth of frame {i} has {} points for {n} targets",
                t.len()
            )));
        }
        let mut outcomes: Vec<FrameOutcome> = Vec::new();
        for (i, cloud) in frames.into_iter().enumerate() {
            let cloud = cloud?;
            let truth = match truths {
                Some(t) => Some(
                    t.get(i)
                        .ok_or_else(|| RegisterError::Invalid(format!("no truth for frame {i} ({} given)", t.len())))?,
                ),
                None => None,
            };
            let tracked = self.register(&cloud)?;
            let rest = in_cloud_frame(self.targets.clone(), tracked.rigid.as_ref());
            let outcome = tracked.into_outcome(truth.map(|t| (t.as_slice(), rest.as_slice())));
            on_frame(i, &self.organ, &outcome)?;
            outcomes.push(outcome);
        }
        if let Some(t) = truths.filter(|t| t.len() != outcomes.len()) {
            return Err(RegisterError::Invalid(format!("{} truth lists for {} frames", t.len(), outcomes.len())));
        }
        Ok(outcomes)
    }
}

/// Per-target distances (m) between two lists of positions of the same length.
pub fn target_errors(registered: &[Point], truth: &[Point]) -> Vec<f64> {
    mesh::distances(registered, truth)
}

/// The share of the target `errors` within twice their predicted standard deviation `std` (a
/// Gaussian's: 95 %); `None` when there are none, or they do not pair up.
pub fn within_two_std(errors: &[f64], std: &[f64]) -> Option<f64> {
    (!errors.is_empty() && errors.len() == std.len())
        .then(|| errors.iter().zip(std).filter(|(e, s)| **e <= 2.0 * **s).count() as f64 / errors.len() as f64)
}

/// One frame's line of summary.json.
#[derive(Clone, Debug, Serialize)]
pub struct FrameSummary {
    /// The cloud's file (or name).
    pub cloud: String,
    /// Points in the cloud.
    pub points: usize,
    /// Points matched (outliers rejected) in the last iteration.
    pub inliers: usize,
    /// Match-and-deform iterations.
    pub iterations: usize,
    /// Mean distance from the matched points to the registered surface (mm).
    pub surface_residual_mm: f64,
    /// Wall time (ms).
    pub time_ms: f64,
    /// Why the result may not be believed; empty when plausible.
    pub warnings: Vec<String>,
    /// Mean TRE (mm), when the truth is known.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub tre_mean_mm: Option<f64>,
    /// Largest TRE (mm), when the truth is known.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub tre_max_mm: Option<f64>,
    /// The predicted standard deviation σ of each target's error (mm), for a method that
    /// predicts one.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub target_sigma_mm: Option<Vec<f64>>,
}

impl FrameSummary {
    /// The line of the frame registered from `cloud`.
    pub fn new(cloud: String, o: &FrameOutcome) -> FrameSummary {
        let (r, tre) = (&o.registration, o.tre_mm());
        FrameSummary {
            cloud,
            points: r.points,
            inliers: r.inliers,
            iterations: r.iterations,
            surface_residual_mm: mm(r.surface_residual),
            time_ms: ms(r.time),
            warnings: r.warnings.clone(),
            tre_mean_mm: tre.map(|t| t.0),
            tre_max_mm: tre.map(|t| t.1),
            target_sigma_mm: o.target_std.as_ref().map(|s| s.iter().map(|&v| mm(v)).collect()),
        }
    }
}

/// The figures of a registration run, over all its frames.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Summary {
    /// The method (deformer) that registered.
    pub method: String,
    /// Frames registered.
    pub frames: usize,
    /// Targets per frame.
    pub targets: usize,
    /// Mean TRE over all targets and frames (mm), when the truth is known.
    pub tre_mean_mm: Option<f64>,
    /// Largest TRE (mm), when the truth is known.
    pub tre_max_mm: Option<f64>,
    /// Mean distance of the rest targets (rigidly aligned, if asked) from the truth (mm): the TRE
    /// without deformation.
    pub no_deformation_tre_mean_mm: Option<f64>,
    /// Largest distance of a rest target from the truth (mm).
    pub no_deformation_tre_max_mm: Option<f64>,
    /// Mean distance from the cloud to the registered surface (mm), mean over frames.
    pub surface_residual_mm: f64,
    /// Wall time per frame (ms), matching included, mean over frames.
    pub time_ms: f64,
    /// Median wall time per frame (ms).
    pub time_median_ms: f64,
    /// 95th percentile of the wall time per frame (ms, [`mesh::stats::percentile`]).
    pub time_p95_ms: f64,
    /// Match-and-deform iterations per frame, mean over frames.
    pub iterations: f64,
    /// The last frame's rigid pre-alignment (organ → cloud transform, ICP figures), when there
    /// was one (the pose estimated last: the results' own).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub rigid: Option<RigidSummary>,
    /// Whether every frame's result is plausible ([`crate::plausibility`]).
    pub plausible: bool,
    /// The frames' warnings, each once, in order of first appearance (prefixed by the frame when
    /// there are several); a run's summary.json puts its set-up's (targets, structures, the truth)
    /// before them.
    pub warnings: Vec<String>,
    /// The mean predicted standard deviation σ of the targets' error (mm), for a method that
    /// predicts one.
    #[serde(skip_serializing_if = "Option::is_none", rename = "target_sigma_mean_mm")]
    pub target_std_mean_mm: Option<f64>,
    /// The share of the targets whose error was within 2σ, when the truth is known and the method
    /// predicts σ (a Gaussian's: 95 %).
    #[serde(skip_serializing_if = "Option::is_none", rename = "within_two_sigma")]
    pub within_two_std: Option<f64>,
}

impl Summary {
    /// The summary of `outcomes` (at least one frame) registered by `method`.
    pub fn new(method: impl Into<String>, outcomes: &[FrameOutcome]) -> Result<Summary> {
        let n = outcomes.len();
        if n == 0 {
            return Err(RegisterError::Invalid("no frame was registered".into()));
        }
        let all = |f: fn(&FrameOutcome) -> &Option<Vec<f64>>| -> Option<Vec<f64>> {
            outcomes.iter().map(|o| f(o).clone()).collect::<Option<Vec<_>>>().map(|v| v.concat())
        };
        let in_mm =
            |v: &Option<Vec<f64>>, stat: fn(&[f64]) -> f64| v.as_ref().filter(|v| !v.is_empty()).map(|v| mm(stat(v)));
        let (errors, rest, std) = (all(|o| &o.errors), all(|o| &o.rest_errors), all(|o| &o.target_std));
        let within = errors.as_deref().zip(std.as_deref()).and_then(|(e, s)| within_two_std(e, s));
        let per_frame = |f: fn(&FrameOutcome) -> f64| outcomes.iter().map(f).sum::<f64>() / n as f64;
        let mut times: Vec<f64> = outcomes.iter().map(|o| ms(o.registration.time)).collect();
        Ok(Summary {
            method: method.into(),
            frames: n,
            targets: outcomes[0].targets.len(),
            tre_mean_mm: in_mm(&errors, mean),
            tre_max_mm: in_mm(&errors, max),
            no_deformation_tre_mean_mm: in_mm(&rest, mean),
            no_deformation_tre_max_mm: in_mm(&rest, max),
            surface_residual_mm: mm(per_frame(|o| o.registration.surface_residual)),
            time_ms: per_frame(|o| ms(o.registration.time)),
            time_p95_ms: mesh::stats::percentile(&times, 95.0),
            time_median_ms: mesh::stats::median(&mut times),
            iterations: per_frame(|o| o.registration.iterations as f64),
            rigid: outcomes[n - 1].rigid.as_ref().map(RigidSummary::from),
            plausible: outcomes.iter().all(|o| o.registration.plausible()),
            target_std_mean_mm: in_mm(&std, mean),
            within_two_std: within,
            warnings: {
                let mut seen = Vec::new();
                for (k, o) in outcomes.iter().enumerate() {
                    for w in &o.registration.warnings {
                        let w = if n > 1 { format!("frame {k}: {w}") } else { w.clone() };
                        if !seen.contains(&w) {
                            seen.push(w);
                        }
                    }
                }
                seen
            },
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frame::tests::Creeping;
    use crate::frame::Observations;

    /// A deformer that never moves the organ.
    struct Still;

    impl Deformer for Still {
        fn deform(&mut self, _: &Observations, previous: &[f64], _: usize) -> Result<Vec<f64>> {
            Ok(vec![0.0; previous.len()])
        }
    }

    /// A 5 cm cube at the origin, registered by [`Still`] to the given targets (m).
    fn cube_with(targets: Vec<Point>) -> Result<Registration> {
        let organ = Organ::new(mesh::box_tet([0.0; 3], [0.05; 3], [3, 3, 3]).unwrap(), None).unwrap();
        Registration::new(organ, Box::new(Still), "still", targets, Vec::new(), RegistrationOptions::default())
    }

    /// A depth camera's full frame is matched on [`crate::MAX_POINTS`] of its points by default,
    /// spread over the whole of it.
    #[test]
    fn a_large_cloud_is_matched_on_a_subset() {
        let mut r = cube_with(vec![[0.02; 3]]).unwrap();
        let n = 3 * crate::MAX_POINTS;
        // The top face, row by row.
        let cloud: Vec<Point> =
            (0..n).map(|k| [0.05 * (k % 300) as f64 / 300.0, 0.05 * (k / 300) as f64 / 100.0, 0.05]).collect();
        let result = r.register(&cloud).unwrap().registration;
        assert_eq!(result.points, crate::MAX_POINTS);
        assert!(result.plausible() && result.surface_residual < 1e-9, "{:?}", result.warnings);
    }

    #[test]
    fn targets_in_the_organ_are_accepted_without_warning() {
        let r = cube_with(vec![[0.01, 0.02, 0.03], [0.04, 0.01, 0.02]]).unwrap();
        assert!(r.warnings().is_empty(), "{:?}", r.warnings());
        assert_eq!(r.targets().len(), 2);
        assert_eq!((r.target_labels(), r.frame()), (&[String::new(), String::new()][..], None), "not named");
        assert_eq!(r.target_names(), ["target-1", "target-2"]);
        let organ = Organ::new(mesh::box_tet([0.0; 3], [0.05; 3], [3, 3, 3]).unwrap(), None).unwrap();
        let labelled = |labels: Vec<String>, targets: Vec<Point>| {
            let options = RegistrationOptions::default();
            Registration::new(organ.clone(), Box::new(Still), "still", targets, labels, options)
        };
        let two = vec![[0.01, 0.02, 0.03], [0.04, 0.01, 0.02]];
        let named = labelled(vec!["A".into(), "B".into()], two.clone()).unwrap().in_frame(Some(Frame::Lps));
        assert_eq!((named.target_labels(), named.frame()), (&["A".to_string(), "B".to_string()][..], Some(Frame::Lps)));
        assert_eq!(named.target_names(), ["A", "B"]);
        let one_label = labelled(vec!["A".into()], two.clone()).err().expect("a label short").to_string();
        assert!(one_label.contains("1 labels for 2 targets"), "{one_label}");
        // A target outside is named by its label too.
        let outside = labelled(vec!["A".into(), "B".into()], vec![two[0], [0.2, 0.0, 0.0]]).err().expect("outside");
        assert!(outside.to_string().starts_with("target 2 (`B`) at (200, 0, 0) mm is outside"), "{outside}");
    }

    /// Structures join the registration, their warnings with them; a name taken, one of the
    /// server's messages', one an implausible result's answers take, or one too long to stream,
    /// is refused.
    #[test]
    fn structures_are_named_apart() {
        let mut r = cube_with(vec![[0.01, 0.02, 0.03]]).unwrap();
        let mut ball = mesh::generate::icosphere(0.01, 1);
        ball.transform([-0.045, -0.025, -0.025], 1.0);
        r.add_structure("vessel", ball.clone()).unwrap();
        assert_eq!(r.structures().iter().map(Structure::name).collect::<Vec<_>>(), ["vessel"]);
        assert!(r.warnings()[0].starts_with("`vessel`: "), "{:?}", r.warnings());
        for taken in ["vessel", "organ", "targets", "", "vessel_implausible"] {
            let e = r.add_structure(taken, ball.clone()).unwrap_err().to_string();
            assert!(e.contains(&format!("a structure cannot be named `{taken}`")), "{e}");
        }
        // A name streams as an OpenIGTLink device name: 20 bytes fit, 21 do not.
        r.add_structure("portal_vein_branch_2", ball.clone()).unwrap();
        let e = r.add_structure("portal_vein_branch_2b", ball.clone()).unwrap_err().to_string();
        assert!(e.contains("longer than 20 bytes"), "{e}");
        assert_eq!(r.structures().len(), 2);
    }

    /// A structure wholly outside the organ, beside it, is asked whether it was segmented apart
    /// from it; one partly outside is not.
    #[test]
    fn a_structure_beside_the_organ_is_asked_if_segmented_apart() {
        let warning = |centre: Point| {
            let mut r = cube_with(vec![[0.01, 0.02, 0.03]]).unwrap();
            let mut ball = mesh::generate::icosphere(0.01, 1);
            ball.transform(centre.map(|x| -x), 1.0);
            r.add_structure("tumour", ball).unwrap();
            r.warnings().join("; ")
        };
        let beside = warning([-0.012, 0.025, 0.025]);
        assert!(
            beside.starts_with("`tumour`: 42 of its 42 vertices lie outside") && beside.contains("segmented apart"),
            "{beside}"
        );
        let across = warning([0.0, 0.025, 0.025]);
        assert!(across.contains("lie outside") && !across.contains("segmented apart"), "{across}");
        assert_eq!(warning([0.025; 3]), "");
    }

    #[test]
    fn millimetres_given_as_metres_are_refused_naming_the_unit() {
        let e = cube_with(vec![[10.0, 20.0, 30.0], [40.0, 10.0, 20.0]]).err().expect("targets outside");
        let message = e.to_string();
        assert!(message.contains("outside the organ"), "{message}");
        assert!(message.contains("given in mm where m were expected"), "{message}");
    }

    #[test]
    fn metres_read_as_millimetres_are_refused() {
        // 10 mm and 40 mm given in m but read as mm: 1,000 times too small, near the origin.
        let e = cube_with(vec![[1e-5, 2e-5, 3e-5], [4e-5, 1e-5, 2e-5]]).err().expect("targets shrunk").to_string();
        assert!(e.contains("under 1 % of the organ"), "{e}");
        assert!(e.contains("given in m where mm were expected"), "{e}");
        // Close together inside the organ, in its unit: warned about only.
        let r = cube_with(vec![[0.02, 0.02, 0.02], [0.0201, 0.02, 0.02]]).unwrap();
        assert!(r.warnings().join("; ").contains("under 1 % of the organ"), "{:?}", r.warnings());
    }

    /// Targets just outside an organ about the origin, inside it with x and y negated: the frame is
    /// named, though they lie near it.
    #[test]
    fn targets_near_the_organ_in_the_other_frame_are_refused_naming_the_frame() {
        let organ = Organ::new(mesh::box_tet([-0.005, -0.005, 0.0], [0.05; 3], [3, 3, 3]).unwrap(), None).unwrap();
        let targets = vec![[-0.008, -0.006, 0.02], [0.002, 0.003, 0.02]];
        let e = Registration::new(organ, Box::new(Still), "still", targets, Vec::new(), RegistrationOptions::default())
            .err()
            .expect("a target outside")
            .to_string();
        assert!(e.contains("with x and y negated every target lies inside"), "{e}");
    }

    #[test]
    fn targets_in_the_other_frame_are_refused_naming_the_frame() {
        let e = cube_with(vec![[-0.01, -0.02, 0.03], [-0.04, -0.01, 0.02]]).err().expect("targets outside");
        let message = e.to_string();
        assert!(message.contains("with x and y negated") && message.contains("LPS"), "{message}");
        assert!(!message.contains("expected?"), "no unit hint: {message}");
    }

    /// Targets 30 cm off, read 1,000 times smaller, all fall near the origin, inside the cube:
    /// that says nothing of their unit (read 10 times smaller they lie across the cube, which is
    /// asked).
    #[test]
    fn targets_shifted_away_get_no_unit_hint() {
        let message = cube_with(vec![[0.01, 0.02, 0.33], [0.04, 0.01, 0.32]]).err().expect("outside").to_string();
        assert!(message.contains("outside the organ") && !message.contains("1,000 times"), "{message}");
    }

    /// A target just outside the organ (as in a part its mesh leaves out) is no unit mistake,
    /// though read 10 times smaller it would lie inside, as any point near the origin would.
    #[test]
    fn targets_just_outside_get_no_unit_hint() {
        let message = cube_with(vec![[0.051, 0.02, 0.03], [0.04, 0.01, 0.02]]).err().expect("outside").to_string();
        assert!(message.contains("outside the organ") && !message.contains("times smaller"), "{message}");
    }

    /// With rigid pre-alignment, a plausible cloud's pose is kept for the next clouds; a cloud that
    /// registers with a warning has the next one estimate it again. A cloud in another unit is
    /// named as such before an alignment.
    #[test]
    fn the_pose_is_kept_while_the_clouds_are_plausible() {
        let organ = Organ::new(mesh::box_tet([0.0; 3], [0.05; 3], [3, 3, 3]).unwrap(), None).unwrap();
        let options = RegistrationOptions { rigid: Some(crate::rigid::RigidOptions::default()), ..Default::default() };
        let mut r =
            Registration::new(organ.clone(), Box::new(Still), "still", vec![[0.02; 3]], Vec::new(), options).unwrap();
        // Points spread through a box three times the cube's: no view of it.
        let spread: Vec<Point> =
            (0..200).map(|k| [(k % 6) as f64 * 0.03, (k / 6 % 6) as f64 * 0.03, (k / 36) as f64 * 0.03]).collect();
        let first = r.register(&spread).unwrap();
        assert!(!first.registration.warnings.is_empty(), "a cloud that does not fit is flagged");
        assert!(first.registration.warnings.iter().any(|w| w.contains("rigid pre-alignment may have failed")));
        let shift = [0.003, -0.004, 0.002];
        let view: Vec<Point> =
            organ.surface().vertices.iter().map(|p| std::array::from_fn(|d| p[d] + shift[d])).collect();
        let second = r.register(&view).unwrap();
        assert!(second.registration.warnings.is_empty(), "{:?}", second.registration.warnings);
        let pose = second.rigid.clone().expect("a pose").cloud_to_organ;
        assert!((0..3).all(|d| (pose.apply(shift)[d]).abs() < 1e-5), "the shift undone: {:?}", pose.apply(shift));
        let third = r.register(&spread).unwrap();
        assert_eq!(third.rigid.expect("the pose kept").cloud_to_organ, pose, "kept, not estimated again");
        // That cloud's warning has the next one estimate the pose again: another shift is (mostly)
        // undone, where the kept pose would leave it all.
        let shift = [-0.002, 0.003, 0.001];
        let view: Vec<Point> =
            organ.surface().vertices.iter().map(|p| std::array::from_fn(|d| p[d] + shift[d])).collect();
        let again = r.register(&view).unwrap().rigid.expect("a pose").cloud_to_organ;
        let left = |t: &crate::RigidTransform| mesh::norm(t.apply(shift));
        assert!(left(&again) < 0.5 * left(&pose), "estimated again: {} m left, {} m kept", left(&again), left(&pose));
        let millimetres: Vec<Point> = organ.surface().vertices.iter().map(|p| p.map(|c| 1e3 * c)).collect();
        r.reset();
        let e = r.register(&millimetres).expect_err("mm refused").to_string();
        assert!(e.contains("Is it in millimetres?"), "{e}");
        // Without a pre-alignment, a handful of points is flagged too.
        let few = cube_with(vec![[0.02; 3]]).unwrap().register(&organ.surface().vertices[..4].repeat(25)).unwrap();
        assert!(few.registration.warnings.iter().any(|w| w.contains("4 distinct point(s), fewer than 10")), "{few:?}");
    }

    /// A view in the other frame (x and y negated, RAS for LPS) is said to be so, with or without
    /// a rigid pre-alignment (a turn by 180° is beyond its reach); the view as given is not.
    #[test]
    fn a_view_in_the_other_frame_is_named_so() {
        let organ = Organ::new(mesh::box_tet([0.02, 0.01, 0.0], [0.1, 0.05, 0.04], [8, 4, 4]).unwrap(), None).unwrap();
        let seen = |p: &&Point| p[2] > 0.039 || p[1] < 0.011 || p[0] > 0.099;
        let view: Vec<Point> = organ.surface().vertices.iter().filter(seen).copied().collect();
        let negated: Vec<Point> = view.iter().map(|p| [-p[0], -p[1], p[2]]).collect();
        for rigid in [None, Some(crate::rigid::RigidOptions::default())] {
            let options = RegistrationOptions { rigid: rigid.clone(), ..Default::default() };
            let mut r = Registration::new(
                organ.clone(),
                Box::new(Still),
                "still",
                vec![[0.05, 0.03, 0.02]],
                Vec::new(),
                options,
            )
            .unwrap();
            let named = |w: &[String]| {
                w.iter().any(|w| w.starts_with("with x and y negated the cloud lies on the organ"))
                    && !w.iter().any(|w| w.contains("--rigid"))
            };
            match r.register(&negated) {
                Ok(wrong) => assert!(named(&wrong.registration.warnings) && !wrong.registration.plausible()),
                Err(e) => assert!(rigid.is_some() && named(&[e.to_string().split("; ").last().unwrap().into()]), "{e}"),
            }
            r.reset();
            let right = r.register(&view).unwrap().registration;
            assert!(right.warnings.is_empty(), "rigid {}: {:?}", rigid.is_some(), right.warnings);
        }
    }

    /// A frame stopped by its time budget is plausible otherwise: the next goes on from it, in
    /// its pose (a frame with another warning has the next estimate the pose again: above).
    #[test]
    fn a_frame_out_of_time_is_built_upon_in_its_pose() {
        let organ = Organ::new(mesh::box_tet([0.0; 3], [0.05; 3], [3, 3, 3]).unwrap(), None).unwrap();
        let rigid = Some(crate::rigid::RigidOptions::default());
        let options = RegistrationOptions { iterations: 3, time_budget_ms: Some(1e-9), rigid, ..Default::default() };
        let mut r =
            Registration::new(organ.clone(), Box::new(Creeping), "creeping", vec![[0.02; 3]], Vec::new(), options)
                .unwrap();
        let shifted = |shift: Point| -> Vec<Point> {
            organ.surface().vertices.iter().map(|p| std::array::from_fn(|d| p[d] + shift[d])).collect()
        };
        let first = r.register(&shifted([0.003, -0.004, 0.002])).unwrap();
        let result = &first.registration;
        assert!(result.out_of_time && result.plausible(), "{:?}", result.warnings);
        assert_eq!(result.iterations, 1, "stopped by the budget");
        let second = r.register(&shifted([-0.002, 0.003, 0.001])).unwrap();
        assert_eq!(second.rigid.unwrap().cloud_to_organ, first.rigid.unwrap().cloud_to_organ, "the pose kept");
        assert!((second.registration.u[0] - 2e-4).abs() < 1e-12, "went on: {}", second.registration.u[0]);
    }

    /// A deformer that scales the organ about the origin by its factor, recording at each frame's
    /// start whether the frame was warm-started.
    struct Scaling(f64, Vec<Point>, std::sync::Arc<std::sync::Mutex<Vec<bool>>>);

    impl Deformer for Scaling {
        fn deform(&mut self, _: &Observations, _: &[f64], _: usize) -> Result<Vec<f64>> {
            Ok(self.1.iter().flat_map(|p| p.map(|x| (self.0 - 1.0) * x)).collect())
        }

        fn start_frame(&mut self, warm: bool) {
            self.2.lock().unwrap().push(warm);
        }
    }

    /// Registers `clouds` in turn with a [`Scaling`] deformer of `factor` on a 5 cm cube; returns
    /// the frames and whether each was warm-started.
    fn scaled_stream(factor: f64, clouds: &[Vec<Point>]) -> (Vec<FrameResult>, Vec<bool>) {
        let organ = Organ::new(mesh::box_tet([0.0; 3], [0.05; 3], [3, 3, 3]).unwrap(), None).unwrap();
        let starts = std::sync::Arc::new(std::sync::Mutex::new(Vec::new()));
        let deformer = Box::new(Scaling(factor, organ.mesh().nodes.clone(), starts.clone()));
        let options = RegistrationOptions { iterations: 2, ..Default::default() };
        let mut r = Registration::new(organ, deformer, "scaling", vec![[0.02; 3]], Vec::new(), options).unwrap();
        let frames = clouds.iter().map(|c| r.register(c).unwrap().registration).collect();
        let starts = starts.lock().unwrap().clone();
        (frames, starts)
    }

    /// A frame that leaves the organ distorted (a cloud in another frame or unit) is no start for
    /// the next: it starts from rest.
    #[test]
    fn a_distorted_organ_is_no_start_for_the_next_frame() {
        let view = mesh::boundary_surface(&mesh::box_tet([0.0; 3], [0.05; 3], [3, 3, 3]).unwrap()).vertices;
        let (frames, starts) = scaled_stream(0.5, &[view.clone(), view]);
        assert!(frames.iter().all(|f| f.distorted));
        assert_eq!(starts, [false, false], "the second frame from rest too");
    }

    /// A cloud in centimetres read as millimetres (a tenth of its size) is no start for the next
    /// frame, even when it leaves the organ undistorted: the next frame starts from rest.
    #[test]
    fn a_cloud_a_tenth_of_its_size_is_no_start_for_the_next_frame() {
        let view = mesh::boundary_surface(&mesh::box_tet([0.0; 3], [0.05; 3], [3, 3, 3]).unwrap()).vertices;
        let tenth: Vec<Point> = view.iter().map(|p| p.map(|x| x / 10.0)).collect();
        let (frames, starts) = scaled_stream(1.0, &[tenth, view.clone(), view]);
        assert!(frames[0].small_view && !frames[0].distorted, "{:?}", frames[0].warnings);
        assert!(frames[0].warnings.iter().any(|w| w.contains("if it is in centimetres")));
        assert!(frames[1].plausible() && frames[1].from_rest && !frames[2].from_rest);
        assert_eq!(starts, [false, false, true]);
    }

    /// A cloud in the other frame (x and y negated) that leaves the organ undistorted is no start
    /// for the next frame either: the next, in the right frame, starts from rest, and the one
    /// after it from that.
    #[test]
    fn a_cloud_in_the_other_frame_is_no_start_for_the_next_frame() {
        let view = mesh::boundary_surface(&mesh::box_tet([0.0; 3], [0.05; 3], [3, 3, 3]).unwrap()).vertices;
        let other: Vec<Point> = view.iter().map(|p| [-p[0], -p[1], p[2]]).collect();
        let (frames, starts) = scaled_stream(1.0, &[other, view.clone(), view]);
        assert!(frames[0].other_frame && !frames[0].distorted, "{:?}", frames[0].warnings);
        assert!(frames[0].warnings.iter().any(|w| w.contains("with x and y negated")));
        assert!(frames[1].plausible() && frames[1].from_rest && !frames[2].from_rest);
        assert_eq!(starts, [false, false, true]);
    }

    /// A deformer that moves the organ by its frame's translation, as a warm-started FEM fits a
    /// cloud in the other frame within a few iterations.
    struct Translating(Vec<Point>, usize);

    impl Deformer for Translating {
        fn deform(&mut self, _: &Observations, u: &[f64], _: usize) -> Result<Vec<f64>> {
            Ok((0..u.len()).map(|d| self.0[self.1 - 1][d % 3]).collect())
        }

        fn start_frame(&mut self, _: bool) {
            self.1 += 1;
        }
    }

    /// A cloud in the other frame that a warm-started frame fits, undistorted and not far moved,
    /// is named all the same.
    #[test]
    fn a_cloud_in_the_other_frame_is_named_mid_stream() {
        let cube = mesh::box_tet([-0.01, -0.01, 0.0], [0.04, 0.04, 0.05], [3, 3, 3]).unwrap();
        let view = mesh::boundary_surface(&cube).vertices;
        let other: Vec<Point> = view.iter().map(|p| [-p[0], -p[1], p[2]]).collect();
        let deformer = Box::new(Translating(vec![[0.0; 3], [-0.03, -0.03, 0.0]], 0));
        let options = RegistrationOptions { iterations: 2, ..Default::default() };
        let mut r = Registration::new(
            Organ::new(cube, None).unwrap(),
            deformer,
            "translating",
            vec![[0.02; 3]],
            Vec::new(),
            options,
        )
        .unwrap();
        assert!(r.register(&view).unwrap().registration.plausible());
        let mirrored = r.register(&other).unwrap().registration;
        let fits = mirrored.far_share < crate::plausibility::SUSPECT_FAR_SHARE && !mirrored.distorted;
        assert!(!mirrored.from_rest && fits, "{mirrored:?}");
        assert!(mirrored.other_frame && mirrored.warnings.iter().any(|w| w.contains("with x and y negated")));
    }

    /// A deformer that finds nothing to follow.
    struct Lost;

    impl Deformer for Lost {
        fn deform(&mut self, _: &Observations, _: &[f64], _: usize) -> Result<Vec<f64>> {
            Err(RegisterError::Invalid("no cloud point matches the model's input".into()))
        }
    }

    /// A deformer's refusal of a cloud a tenth of the organ's size (centimetres read as
    /// millimetres) says what the cloud may be.
    #[test]
    fn a_refused_small_cloud_is_asked_whether_it_is_in_centimetres() {
        let organ = Organ::new(mesh::box_tet([0.0; 3], [0.05; 3], [3, 3, 3]).unwrap(), None).unwrap();
        let options = RegistrationOptions { iterations: 2, ..Default::default() };
        let mut r = Registration::new(organ, Box::new(Lost), "lost", vec![[0.02; 3]], Vec::new(), options).unwrap();
        let small: Vec<Point> = (0..25).map(|i| [0.001 * (i % 5) as f64, 0.001 * (i / 5) as f64, 0.05]).collect();
        let Err(message) = r.register(&small).map(|_| ()) else { panic!("a lost deformer registered") };
        let message = message.to_string();
        assert!(message.contains("no cloud point matches") && message.contains("if it is in centimetres"), "{message}");
        let view = mesh::boundary_surface(&mesh::box_tet([0.0; 3], [0.05; 3], [3, 3, 3]).unwrap()).vertices;
        let Err(message) = r.register(&view).map(|_| ()) else { panic!("a lost deformer registered") };
        let message = message.to_string();
        assert!(!message.contains("centimetres"), "{message}");
    }

    #[test]
    fn targets_far_outside_in_any_unit_are_refused_without_a_hint() {
        let message = cube_with(vec![[-5.0, 0.0, 0.0]]).err().expect("outside").to_string();
        assert!(message.contains("outside the organ") && !message.contains("expected"), "{message}");
        assert!(cube_with(Vec::new()).is_err(), "no target");
    }
}
