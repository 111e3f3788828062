//! Registration of a sequence of frames: each frame warm-started from the previous one, the
//! targets carried along, their registration errors (TRE) where the truth is known, and the
//! summary of the run.
//!
//! With a rigid pre-alignment ([`RegistrationOptions::rigid`]) the cloud is moved onto the organ
//! (the transform estimated on the first frame, kept for the sequence), registered there, and
//! the registered targets are moved back: targets and errors are in the cloud's frame.

use mesh::stats::{max, mean};
use mesh::Point;
use serde::Serialize;

use crate::organ::{displaced, Organ, Stencil};
use crate::register::{register_frame, Deformer, FrameResult, RegistrationOptions};
use crate::rigid::{rigid_align, RigidResult, RigidSummary};
use crate::{RegisterError, Result};

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
        self.errors.as_ref().filter(|e| !e.is_empty()).map(|e| (mean(e) * 1e3, max(e) * 1e3))
    }
}

/// Clouds registered one after the other: each warm-started from the previous one's
/// displacement; with a rigid pre-alignment in the options, the cloud's pose estimated on the
/// first cloud (trimmed ICP to the organ's rest surface) and kept; the targets carried along in the
/// cloud's frame. What [`register_sequence`] and a streaming server do per client.
pub struct Tracker {
    stencils: Vec<Stencil>,
    targets: Vec<Point>,
    warm: Option<Vec<f64>>,
    rigid: Option<RigidResult>,
}

/// One cloud registered by a [`Tracker`].
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

impl Tracker {
    /// Locates `targets` (rest positions) in `organ`; an error names a target outside it.
    pub fn new(organ: &Organ, targets: &[Point]) -> Result<Tracker> {
        Ok(Tracker { stencils: organ.locate(targets, "target")?, targets: targets.to_vec(), warm: None, rigid: None })
    }

    /// Registers `cloud` (in its own frame), starting from the previous cloud's displacement,
    /// which it then replaces; a failed cloud leaves the warm start and the pose as they were.
    pub fn register(
        &mut self,
        organ: &Organ,
        deformer: &mut dyn Deformer,
        cloud: &[Point],
        options: &RegistrationOptions,
    ) -> Result<Tracked> {
        let (rigid, rigid_time) = match (&options.rigid, &self.rigid) {
            (Some(rigid_options), None) => {
                let r = rigid_align(organ.surface(), cloud, rigid_options)?;
                let time = r.time;
                (Some(r), time)
            }
            (_, known) => (known.clone(), std::time::Duration::ZERO),
        };
        let moved: Vec<Point>;
        let in_organ = match &rigid {
            Some(r) => {
                moved = cloud.iter().map(|&p| r.cloud_to_organ.apply(p)).collect();
                &moved
            }
            None => cloud,
        };
        let mut registration = register_frame(organ, deformer, in_organ, self.warm.as_deref(), options)?;
        registration.time += rigid_time;
        let mut targets = displaced(&self.targets, &self.stencils, &registration.u);
        if let Some(r) = &rigid {
            let to_cloud = r.organ_to_cloud();
            targets.iter_mut().for_each(|p| *p = to_cloud.apply(*p));
        }
        let target_std = deformer.uncertainty(&self.targets).transpose()?;
        self.warm = Some(registration.u.clone());
        self.rigid = rigid.clone();
        Ok(Tracked { registration, targets, rigid, target_std })
    }

    /// Forgets the previous cloud and the pose: the next cloud starts from rest.
    pub fn reset(&mut self) {
        self.warm = None;
        self.rigid = None;
    }
}

/// Registers `organ` to each cloud of `frames` in turn, each frame starting from the previous
/// one's displacement; `targets` are rest positions inside the organ, `truths` (one list per
/// frame, in the order of `targets`, in the cloud's frame) their true deformed positions.
/// `on_frame` sees each frame as soon as it is registered (to print or write it).
pub fn register_sequence(
    organ: &Organ,
    deformer: &mut dyn Deformer,
    frames: impl IntoIterator<Item = Result<Vec<Point>>>,
    targets: &[Point],
    truths: Option<&[Vec<Point>]>,
    options: &RegistrationOptions,
    mut on_frame: impl FnMut(usize, &FrameOutcome) -> Result<()>,
) -> Result<Vec<FrameOutcome>> {
    if let Some((i, t)) = truths.into_iter().flatten().enumerate().find(|(_, t)| t.len() != targets.len()) {
        return Err(RegisterError::Invalid(format!(
            "the truth of frame {i} has {} points for {} targets",
            t.len(),
            targets.len()
        )));
    }
    let mut outcomes: Vec<FrameOutcome> = Vec::new();
    let mut tracker = Tracker::new(organ, targets)?;
    for (i, cloud) in frames.into_iter().enumerate() {
        let cloud = cloud?;
        let truth = match truths {
            Some(t) => Some(
                t.get(i)
                    .ok_or_else(|| RegisterError::Invalid(format!("no truth for frame {i} ({} given)", t.len())))?,
            ),
            None => None,
        };
        let Tracked { registration, targets: registered, rigid, target_std } =
            tracker.register(organ, deformer, &cloud, options)?;
        let mut rest = targets.to_vec();
        if let Some(r) = &rigid {
            let to_cloud = r.organ_to_cloud();
            rest.iter_mut().for_each(|p| *p = to_cloud.apply(*p));
        }
        let outcome = FrameOutcome {
            errors: truth.map(|t| target_errors(&registered, t)),
            rest_errors: truth.map(|t| target_errors(&rest, t)),
            targets: registered,
            registration,
            rigid,
            target_std,
        };
        on_frame(i, &outcome)?;
        outcomes.push(outcome);
    }
    if let Some(t) = truths.filter(|t| t.len() != outcomes.len()) {
        return Err(RegisterError::Invalid(format!("{} truth lists for {} frames", t.len(), outcomes.len())));
    }
    Ok(outcomes)
}

/// Per-target distances (m) between two lists of positions of the same length.
pub fn target_errors(registered: &[Point], truth: &[Point]) -> Vec<f64> {
    mesh::distances(registered, truth)
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
    /// The rigid pre-alignment (organ → cloud transform, ICP figures), when there was one.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub rigid: Option<RigidSummary>,
    /// Whether every frame's result is plausible ([`crate::plausibility`]).
    pub plausible: bool,
    /// The frames' warnings, each once, in order of first appearance (prefixed by the frame when
    /// there are several).
    pub warnings: Vec<String>,
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
        let mm =
            |v: &Option<Vec<f64>>, stat: fn(&[f64]) -> f64| v.as_ref().filter(|v| !v.is_empty()).map(|v| stat(v) * 1e3);
        let (errors, rest) = (all(|o| &o.errors), all(|o| &o.rest_errors));
        let per_frame = |f: fn(&FrameOutcome) -> f64| outcomes.iter().map(f).sum::<f64>() / n as f64;
        let mut times: Vec<f64> = outcomes.iter().map(|o| o.registration.time.as_secs_f64() * 1e3).collect();
        Ok(Summary {
            method: method.into(),
            frames: n,
            targets: outcomes[0].targets.len(),
            tre_mean_mm: mm(&errors, mean),
            tre_max_mm: mm(&errors, max),
            no_deformation_tre_mean_mm: mm(&rest, mean),
            no_deformation_tre_max_mm: mm(&rest, max),
            surface_residual_mm: per_frame(|o| o.registration.surface_residual) * 1e3,
            time_ms: per_frame(|o| o.registration.time.as_secs_f64()) * 1e3,
            time_p95_ms: mesh::stats::percentile(&times, 95.0),
            time_median_ms: mesh::stats::median(&mut times),
            iterations: per_frame(|o| o.registration.iterations as f64),
            rigid: outcomes[0].rigid.as_ref().map(RigidSummary::from),
            plausible: outcomes.iter().all(|o| o.registration.warnings.is_empty()),
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
