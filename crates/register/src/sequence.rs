//! Registration of a sequence of frames: each frame warm-started from the previous one, the
//! targets carried along, their registration errors (TRE) where the truth is known, and the
//! summary of the run.

use mesh::Point;
use serde::Serialize;

use crate::organ::{displaced, Organ};
use crate::register::{distance, register_frame, Deformer, FrameResult, RegistrationOptions};
use crate::{RegisterError, Result};

/// One registered frame.
#[derive(Clone, Debug)]
pub struct FrameOutcome {
    /// The registration (displacement, iterations, residual, time).
    pub registration: FrameResult,
    /// Registered target positions.
    pub targets: Vec<Point>,
    /// Distance of each registered target from its true position (m), when the truth is known.
    pub errors: Option<Vec<f64>>,
    /// Distance of each rest target from its true position (m): the error of not deforming.
    pub rest_errors: Option<Vec<f64>>,
}

impl FrameOutcome {
    /// Mean and largest TRE of the frame (mm), when the truth is known.
    pub fn tre_mm(&self) -> Option<(f64, f64)> {
        self.errors.as_ref().filter(|e| !e.is_empty()).map(|e| (mean(e) * 1e3, max(e) * 1e3))
    }
}

/// Registers `organ` to each cloud of `frames` in turn, each frame starting from the previous
/// one's displacement; `targets` are rest positions inside the organ, `truths` (one list per
/// frame, in the order of `targets`) their true deformed positions. `on_frame` sees each
/// frame as soon as it is registered (to print or write it).
pub fn register_sequence(
    organ: &Organ,
    deformer: &mut dyn Deformer,
    frames: impl IntoIterator<Item = Result<Vec<Point>>>,
    targets: &[Point],
    truths: Option<&[Vec<Point>]>,
    options: &RegistrationOptions,
    mut on_frame: impl FnMut(usize, &FrameOutcome) -> Result<()>,
) -> Result<Vec<FrameOutcome>> {
    let stencils = organ.locate(targets, "target")?;
    if let Some((i, t)) = truths.into_iter().flatten().enumerate().find(|(_, t)| t.len() != targets.len()) {
        return Err(RegisterError::Invalid(format!(
            "the truth of frame {i} has {} points for {} targets",
            t.len(),
            targets.len()
        )));
    }
    let mut outcomes: Vec<FrameOutcome> = Vec::new();
    for (i, cloud) in frames.into_iter().enumerate() {
        let truth = match truths {
            Some(t) => Some(
                t.get(i)
                    .ok_or_else(|| RegisterError::Invalid(format!("no truth for frame {i} ({} given)", t.len())))?,
            ),
            None => None,
        };
        let start = outcomes.last().map(|o| o.registration.u.as_slice());
        let registration = register_frame(organ, deformer, &cloud?, start, options)?;
        let registered = displaced(targets, &stencils, &registration.u);
        let outcome = FrameOutcome {
            errors: truth.map(|t| target_errors(&registered, t)),
            rest_errors: truth.map(|t| target_errors(targets, t)),
            targets: registered,
            registration,
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
    registered.iter().zip(truth).map(|(a, b)| distance(*a, *b)).collect()
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
    /// Mean distance of the rest targets from the truth (mm): the TRE without deformation.
    pub no_deformation_tre_mean_mm: Option<f64>,
    /// Largest distance of a rest target from the truth (mm).
    pub no_deformation_tre_max_mm: Option<f64>,
    /// Mean distance from the cloud to the registered surface (mm), mean over frames.
    pub surface_residual_mm: f64,
    /// Wall time per frame (ms), matching included, mean over frames.
    pub time_ms: f64,
    /// Match-and-deform iterations per frame, mean over frames.
    pub iterations: f64,
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
            iterations: per_frame(|o| o.registration.iterations as f64),
        })
    }
}

fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len() as f64
}

fn max(v: &[f64]) -> f64 {
    v.iter().copied().fold(0.0, f64::max)
}
