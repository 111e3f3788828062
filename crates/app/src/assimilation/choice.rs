//! The user's choices of an assimilation run, as `augsim assimilate` takes them: the scenario,
//! the settings that override the scenario file's, and the track files.

use std::path::PathBuf;

use anyhow::Result;
use filter::{Discrepancy, Execution, SigmaPointSet};
use mesh::length::LengthUnit;
use scenario::AssimilationScenario;

use super::{Experiment, ObservationFiles, OnlineFilter};

/// The user's choices of an assimilation run: the arguments of `augsim assimilate` (its scenario
/// and what overrides the scenario's settings). [`AssimilationChoice::scenario`] applies them.
#[derive(Debug, Clone, Default, clap::Args)]
pub struct AssimilationChoice {
    /// Assimilation scenario: a TOML file, or the name of a built-in one (e.g. roukf_young).
    pub scenario: PathBuf,
    /// Number of filter iterations (default: the scenario's; with --observations, all frames).
    #[arg(long)]
    pub iterations: Option<usize>,
    /// Evaluate the sigma points one after the other instead of in parallel.
    #[arg(long)]
    pub sequential: bool,
    /// Output directory, new or empty (one holding an earlier run's results or other files is
    /// refused); default a fresh numbered
    /// folder under `out/<name>` (`001`, `002`, …). `--out` as every command writing a folder
    /// names it (`--output` also taken).
    #[arg(short, long = "out", alias = "output")]
    pub output: Option<PathBuf>,
    /// Tracked features instead of synthetic ones: CSV `frame,id,x,y,z` (in --units, or x_mm, y_mm, z_mm; frame 0 =
    /// rest, frame k = step k).
    #[arg(long)]
    pub observations: Option<PathBuf>,
    /// Rest positions of the tracked features: CSV `id,x,y,z` (default: their frame-0 rows).
    #[arg(long, requires = "observations")]
    pub features: Option<PathBuf>,
    /// Tracked tool features (CSV `frame,id,x,y,z`): displacement prescribed on the nearest free surface node.
    #[arg(long, requires = "observations")]
    pub controls: Option<PathBuf>,
    /// Tracked assessment points (CSV `frame,id,x,y,z`): the estimated deformation's error is reported there.
    #[arg(long, requires = "observations")]
    pub assessment: Option<PathBuf>,
    /// The scenario's parameter values are the truth behind the tracks (e.g. tracks of a synthetic run on a finer
    /// mesh): report the estimate's error against them.
    #[arg(long, requires = "observations")]
    pub known_truth: bool,
    /// Unit of the track files whose header names none: m (the default, as on every front).
    #[arg(long, default_value_t = LengthUnit::DEFAULT, requires = "observations")]
    pub units: LengthUnit,
    /// Forgetting factor in (0, 1]: the parameter covariance is divided by it before every step (default: the
    /// scenario's filter.forgetting, else 1 = none).
    #[arg(long, value_parser = crate::values::factor)]
    pub forgetting: Option<f64>,
    /// Sigma points: `simplex` (p + 1) or `star` (2p + 1) (default: the scenario's filter.sigma_points, else
    /// simplex).
    #[arg(long, value_name = "SET")]
    pub sigma_points: Option<SigmaPointSet>,
    /// Allowance for model error in the reported σ: `none`, `independent` (the misfit beyond the observation noise
    /// as extra white noise) or `systematic` (a model error that may lie along the parameters' sensitivity)
    /// (default: the scenario's filter.discrepancy, else none).
    #[arg(long, value_name = "KIND")]
    pub discrepancy: Option<Discrepancy>,
    /// Degrees of freedom d ≥ 1 of a systematic discrepancy (default: the scenario's filter.discrepancy_dof, else 1).
    #[arg(long, value_name = "D", value_parser = crate::values::at_least_one)]
    pub discrepancy_dof: Option<f64>,
    /// Validation gate G: a tracked component farther from the filter's prediction than G predicted standard
    /// deviations is left out of that step, as a tracking failure (default: the scenario's filter.gate, else none).
    #[arg(long, value_name = "G", value_parser = crate::values::positive)]
    pub gate: Option<f64>,
    /// Write the estimated deformation every N steps, and the last one's (default: the scenario's output.every,
    /// else 1).
    #[arg(long)]
    pub every: Option<usize>,
}

impl AssimilationChoice {
    /// The scenario (with the directory its paths are relative to), the choices that override
    /// its settings applied.
    pub fn scenario(&self) -> Result<(AssimilationScenario, PathBuf)> {
        let (mut sc, dir) = AssimilationScenario::load(&self.scenario)?;
        // Track files are filtered to their last frame unless --iterations says otherwise: the
        // scenario's own count is that of its synthetic run.
        if self.iterations.is_some() || self.observations.is_some() {
            sc.iterations = self.iterations;
        }
        if self.sequential {
            sc.filter.execution = Execution::Sequential;
        }
        if let Some(rho) = self.forgetting {
            sc.filter.forgetting = rho;
        }
        if let Some(set) = self.sigma_points {
            sc.filter.sigma_points = set;
        }
        if let Some(kind) = self.discrepancy {
            sc.filter.discrepancy = kind;
        }
        if let Some(d) = self.discrepancy_dof {
            sc.filter.discrepancy_dof = d;
        }
        if self.every == Some(0) {
            anyhow::bail!("--every must be at least 1");
        }
        if self.every.is_some() {
            sc.output.every = self.every;
        }
        if self.gate.is_some() {
            sc.filter.gate = self.gate;
        }
        Ok((sc, dir))
    }

    /// The filter of the scenario chosen on a stream, one step per set of observed features, with
    /// its experiment (prepared: its reference run of synthetic observations made), which builds
    /// more such filters ([`OnlineFilter::new`]).
    pub fn online(&self) -> Result<(Experiment, OnlineFilter)> {
        let (scenario, dir) = self.scenario()?;
        let experiment = Experiment::prepare(scenario, &dir, None)?;
        let filter = OnlineFilter::new(&experiment)?;
        Ok((experiment, filter))
    }

    /// The experiment chosen, prepared (its reference run made, or its track files read), with
    /// where it writes and the lines that say what it is set up to do.
    pub fn prepare(&self) -> Result<PreparedAssimilation> {
        let (sc, dir) = self.scenario()?;
        // Never two runs' files in one folder: `--out` refused once used, else numbered folders.
        let (out_dir, own) = crate::output::run_dir(self.output.as_deref(), &sc.output_dir())?;
        let files = self.files();
        let described = if sc.description.is_empty() { String::new() } else { format!(": {}", sc.description) };
        let mut lines = vec![format!("scenario     {}{described}", sc.name)];
        let sigma_points = sc.filter.sigma_points;
        let prepared = Experiment::prepare(sc, &dir, files.as_ref()).map_err(anyhow::Error::from);
        let experiment = crate::output::tidy_failed_run(&out_dir, own, prepared)?;
        lines.extend(experiment.setup().lines(sigma_points, files.as_ref()));
        Ok(PreparedAssimilation { experiment, out_dir, own, synthetic: files.is_none(), lines })
    }

    /// The track files that replace the synthetic observations, when given.
    pub fn files(&self) -> Option<ObservationFiles> {
        self.observations.as_ref().map(|observations| ObservationFiles {
            observations: observations.clone(),
            features: self.features.clone(),
            controls: self.controls.clone(),
            assessment: self.assessment.clone(),
            known_truth: self.known_truth,
            units: self.units,
        })
    }
}

/// An assimilation run prepared ([`AssimilationChoice::prepare`]), to be run.
pub struct PreparedAssimilation {
    experiment: Experiment,
    out_dir: PathBuf,
    /// Whether the folder is the run's own, removed again when the run fails before writing.
    own: bool,
    /// Whether its observations are synthetic (written as track files by the run).
    synthetic: bool,
    /// What it is set up to do, a line each.
    pub lines: Vec<String>,
}

impl PreparedAssimilation {
    /// Runs the filter, telling each iteration to `progress`, and writes its results; returns
    /// them in words, with what was written.
    pub fn run(&self, progress: &dyn learn::Progress) -> Result<Vec<String>> {
        let report = self.experiment.run(&self.out_dir, progress).map_err(anyhow::Error::from);
        let report = crate::output::tidy_failed_run(&self.out_dir, self.own, report)?;
        let mut lines = report.lines();
        lines.push(format!(
            "wrote        {}/{{trace.csv, trace.json, summary.json, deformation.pvd ({} step{}), *.png}}{}",
            self.out_dir.display(),
            report.deformation_frames,
            if report.deformation_frames == 1 { "" } else { "s" },
            if self.synthetic { ", tracks/*.csv (the synthetic observations)" } else { "" }
        ));
        Ok(lines)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_choices_override_the_scenario_settings() {
        let choice = AssimilationChoice {
            scenario: PathBuf::from("roukf_young"),
            iterations: Some(3),
            sequential: true,
            output: None,
            observations: None,
            features: None,
            controls: None,
            assessment: None,
            known_truth: false,
            units: LengthUnit::Millimetre,
            forgetting: Some(0.9),
            sigma_points: Some(SigmaPointSet::Star),
            discrepancy: None,
            discrepancy_dof: Some(2.0),
            gate: Some(30.0),
            every: Some(5),
        };
        let (sc, _) = choice.scenario().unwrap();
        assert_eq!((sc.iterations, sc.output.every), (Some(3), Some(5)));
        assert_eq!(sc.filter.execution, Execution::Sequential);
        assert_eq!((sc.filter.forgetting, sc.filter.discrepancy_dof, sc.filter.gate), (0.9, 2.0, Some(30.0)));
        assert_eq!(sc.filter.sigma_points, SigmaPointSet::Star);
        assert!(choice.files().is_none());
        let tracked = AssimilationChoice { observations: Some("obs.csv".into()), known_truth: true, ..choice };
        let files = tracked.files().unwrap();
        assert!(files.known_truth && files.observations == std::path::Path::new("obs.csv"));
        assert_eq!(files.units, LengthUnit::Millimetre);
        // Track files are filtered to their last frame, not to the scenario's synthetic run's 600.
        assert_eq!(tracked.scenario().unwrap().0.iterations, Some(3));
        let all = AssimilationChoice { iterations: None, ..tracked };
        assert_eq!(all.scenario().unwrap().0.iterations, None);
    }
}
