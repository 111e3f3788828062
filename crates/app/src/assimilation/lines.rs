//! The lines a front prints for an assimilation: its set-up before the run and its results after.

use filter::{Execution, SigmaPointSet};
use mesh::length::mm;

use super::report::YoungReport;
use super::{ObservationFiles, Report, Setup};

impl Setup {
    /// The set-up in words: mesh, constraints and points, and where the observations come from
    /// (the reference run, or the track files `files`); `sigma` is the filter's sigma-point set.
    pub fn lines(&self, sigma: SigmaPointSet, files: Option<&ObservationFiles>) -> Vec<String> {
        let s = self;
        let mut lines = vec![
            format!("mesh         {} nodes, {} {} cells", s.nodes, s.cells, s.cell_kind),
            format!(
                "setup        {} constrained nodes ({} tool, {} tracked tool), {} feature points, {} assessment \
                 points, {} parameter(s), {} {sigma} sigma points",
                s.constrained_nodes,
                s.tool_nodes,
                s.control_nodes,
                s.features,
                s.assessment_points,
                s.parameters,
                s.sigma_points,
            ),
        ];
        match (&s.reference, files) {
            (Some(r), _) => lines.push(format!(
                "reference    {} steps in {:.2} s, max |u| = {:.2} mm, on {}",
                s.iterations,
                r.seconds,
                mm(r.max_displacement),
                if r.inverse_crime {
                    "the filter's own model (an inverse crime: add a [reference] section with another mesh)".to_string()
                } else {
                    format!(
                        "a reference of its own: {} nodes, {} cells, {} ({} tracked points located on the \
                         model's surface, keeping their offset, at most {:.2} mm)",
                        r.nodes,
                        r.cells,
                        r.law.display_name(),
                        s.projected,
                        mm(s.max_projection)
                    )
                }
            )),
            (None, Some(f)) => {
                lines.push(format!(
                    "tracks       {} frames from {}, {} occluded feature observations, {} points outside the mesh \
                     located on its surface, keeping their offset (at most {:.2} mm)",
                    s.iterations,
                    f.observations.display(),
                    s.occluded,
                    s.projected,
                    mm(s.max_projection)
                ));
                if let Some((id, depth)) = s.deep_features.iter().max_by(|a, b| a.1.total_cmp(&b.1)) {
                    lines.push(format!(
                        "warning      {} feature(s) lie deeper than an element below the mesh's surface (`{id}` {:.1} \
                         mm): a camera tracks the surface; is it a wrong position, or another organ's?",
                        s.deep_features.len(),
                        mm(*depth)
                    ));
                }
                if let (Some((count, farthest)), Some(features)) = (s.rest_disagreement, &f.features) {
                    lines.push(format!(
                        "warning      {count} feature(s) of {} lie at frame 0 more than the observation noise from \
                         their rest positions in {} (at most {:.2} mm): frame 0 is not read when a features file \
                         gives the rest; is it the same features' rest, in the same frame and unit?",
                        f.observations.display(),
                        features.display(),
                        mm(farthest)
                    ));
                }
                if s.blind_frames > 0 {
                    lines.push(format!(
                        "warning      {} of the {} frames have no row: every feature occluded, the filter only \
                         predicts there (is the frame column a frame number?)",
                        s.blind_frames, s.iterations
                    ));
                }
            }
            (None, None) => {}
        }
        lines
    }
}

impl Report {
    /// The results in words: the filter's speed and where its time went, the estimates (against
    /// the truth when known), the assessment errors and the wall time.
    pub fn lines(&self) -> Vec<String> {
        let r = self;
        let t = &r.filter_times;
        let mut lines = vec![
            format!(
                "filter       {} iterations in {:.2} s, {:.2} s of them the filter's steps: {:.2} ms per step (median \
                 {:.2} ms), {:.2} Newton iterations per solve, the sigma points {}",
                r.iterations,
                r.filter_seconds,
                r.seconds_per_iteration_mean * r.iterations as f64,
                1e3 * r.seconds_per_iteration_mean,
                1e3 * r.seconds_per_iteration_median,
                r.newton_iterations_per_solve,
                match r.execution {
                    Execution::Parallel => "in parallel",
                    Execution::Sequential => "one after the other",
                }
            ),
            format!(
                "time         FEM solves {:.2} s summed over the sigma points (assembly {:.2} s, {:.2} \
                 factorisations per solve {:.2} s, triangular solves {:.2} s), writing the deformation {:.2} s",
                t.solves, t.assembly, t.factorizations_per_solve, t.factorization, t.triangular_solves, t.writing
            ),
        ];
        lines.extend(r.young.iter().flat_map(YoungReport::lines));
        if let Some(s) = &r.springs {
            let n = s.stiffness.len() as f64;
            let truth = match (&s.truth, s.rms_error) {
                (Some(t), Some(rms)) => format!(
                    ": RMS error {rms:.1} N/m (true values 0..{:.1} N/m; {} of {} within 2σ)",
                    t.iter().copied().fold(0.0, f64::max),
                    s.stiffness.iter().zip(&s.std).zip(t).filter(|((k, sd), t)| (*k - *t).abs() <= 2.0 * *sd).count(),
                    t.len()
                ),
                _ => String::new(),
            };
            lines.push(format!(
                "springs      {} stiffnesses{truth}, mean {:.1} N/m, mean σ {:.1} N/m",
                s.stiffness.len(),
                s.stiffness.iter().sum::<f64>() / n,
                s.std.iter().sum::<f64>() / n
            ));
        }
        for c in &r.assessment {
            lines.push(format!(
                "assessment   {:<10} mean error {:.3} mm (max {:.3} mm)",
                c.label,
                mm(c.mean_error),
                mm(c.max_error)
            ));
        }
        if r.largest_feature_motion < STILL_NOISES * r.observation_std {
            lines.push(format!(
                "warning      the features hardly move: at most {:.3} mm from rest, under {STILL_NOISES} times the \
                 observation noise ({:.3} mm): there is no motion to identify the tissue from",
                mm(r.largest_feature_motion),
                mm(r.observation_std)
            ));
        }
        let gated_share = r.gated_components as f64 / r.measured_components.max(1) as f64;
        if gated_share > GATED_SHARE {
            lines.push(format!(
                "warning      the validation gate left out {} of the {} tracked components ({:.0} %): the \
                 estimate rests on the {} it kept; a camera that moved, tracks offset (in another frame or unit?), \
                 or a gate too tight (--gate)",
                r.gated_components,
                r.measured_components,
                100.0 * gated_share,
                r.measured_components.saturating_sub(r.gated_components)
            ));
        }
        if let (components, steps @ 1..) = (r.gated_components, r.gated_steps) {
            let most: Vec<String> = r.gated_features.iter().take(3).map(|(id, n)| format!("`{id}` {n}")).collect();
            lines.push(format!(
                "gate         {components} tracked components left out of {steps} steps, farther from the \
                 prediction than the validation gate allows (trace.json: gated_components); steps left out, most \
                 often: {}{}",
                most.join(", "),
                if r.gated_features.len() > 3 {
                    format!(" (of {} features)", r.gated_features.len())
                } else {
                    String::new()
                }
            ));
        }
        lines.push(format!("wall time    {:.2} s in all", r.total_seconds));
        lines
    }
}

impl YoungReport {
    /// The estimate in words (against the truth when known), with what makes its σ doubtful.
    fn lines(&self) -> Vec<String> {
        let truth = match self.truth {
            Some(t) => format!(
                " (truth {t:.0} Pa, error {:+.2} %, {:.1} σ), within 1 % {}",
                100.0 * (self.mean - t) / t,
                (self.mean - t).abs() / self.std,
                match (self.within_1_percent_from_iteration, self.within_1_percent_after_seconds) {
                    (Some(k), Some(t)) => format!("from iteration {k} on ({t:.2} s of filter time)"),
                    (Some(k), None) => format!("from iteration {k} on"),
                    _ => "never (so far)".to_string(),
                }
            ),
            None => String::new(),
        };
        let mut lines = vec![format!("young        μ = {:.1} ± {:.1} Pa{truth}", self.mean, self.std)];
        let data_std = self.noise_std.unwrap_or(self.std);
        if data_std > PRIOR_LEFT * self.prior_std {
            lines.push(format!(
                "warning      the observations told the filter little: σ from them is {:.0} % of the prior's \
                 ({:.1} Pa), so the estimate is mostly the prior (few frames, features that barely move, or a \
                 prior far from the tissue's stiffness?)",
                100.0 * data_std / self.prior_std,
                self.prior_std
            ));
        }
        if let Some((steps, change)) = self.drift.filter(|(_, change)| change.abs() > self.std) {
            lines.push(format!(
                "warning      the estimate still moves: {change:+.1} Pa over the last {steps} iterations, {:.1} \
                 times its σ, which does not say where more iterations would take it (--iterations)",
                change.abs() / self.std
            ));
        }
        if let (Some(noise), Some(misfit)) = (self.noise_std, self.misfit) {
            lines.push(format!(
                "discrepancy  σ = {:.1} Pa from the observation noise alone; misfit χ²/ν = {misfit:.3} \
                 (effective observation noise {:.2} × nominal)",
                noise,
                misfit.sqrt()
            ));
            lines.extend(misfit_warning(misfit));
        }
        if let (Some(noise), None) = (self.noise_std, self.misfit) {
            lines.push(format!(
                "warning      the misfit could not be measured: no frame's sigma points came near the final \
                 estimate (it jumped away from where the frames were taken: a gate leaving most out, tracks \
                 that do not fit the model?); σ = {noise:.1} Pa is the observation noise's alone"
            ));
        }
        lines
    }
}

/// The share of its prior's σ above which an estimate's σ from the observations says they told
/// the filter little.
const PRIOR_LEFT: f64 = 0.5;

/// The observation noises a feature must move beyond, somewhere in the run, for the tracks to
/// show a motion.
const STILL_NOISES: f64 = 3.0;

/// The share of the tracked components beyond which the gate is said to have left out the data.
const GATED_SHARE: f64 = 0.1;

/// The reduced misfit χ²/ν beyond which (or under whose inverse) the observations are said not to
/// fit the model with their nominal noise: an effective noise twice the nominal, or half.
const MISFIT_BOUND: f64 = 4.0;

/// A warning when the reduced misfit χ²/ν of a run lies outside [1/[`MISFIT_BOUND`],
/// [`MISFIT_BOUND`]]: the noise said, the load or the model are then wrong, and σ is not the
/// estimate's.
fn misfit_warning(misfit: f64) -> Option<String> {
    let (how, what) = if misfit > MISFIT_BOUND {
        ("farther", "the observation noise is larger than said, or the model (its load, its mesh, its law) differs from what was observed")
    } else if misfit < 1.0 / MISFIT_BOUND {
        ("closer", "the observation noise is smaller than said")
    } else {
        return None;
    };
    Some(format!(
        "warning      the observations lie {:.1} × {how} from the model than their nominal noise says \
         (χ²/ν = {misfit:.3}): {what}; σ is then not the estimate's",
        if misfit > 1.0 { misfit.sqrt() } else { 1.0 / misfit.sqrt() }
    ))
}

#[cfg(test)]
mod tests {
    use super::misfit_warning;

    /// A misfit near 1 passes; one of an effective noise over twice or under half the nominal is
    /// warned about, saying which way.
    #[test]
    fn a_misfit_far_from_one_is_warned_about() {
        assert_eq!(misfit_warning(1.3), None);
        let large = misfit_warning(12.2).unwrap();
        assert!(
            large.contains("3.5 × farther from the model than their nominal noise says (χ²/ν = 12.200)"),
            "{large}"
        );
        let small = misfit_warning(0.015).unwrap();
        assert!(small.contains("8.2 × closer") && small.contains("smaller than said"), "{small}");
    }
}
