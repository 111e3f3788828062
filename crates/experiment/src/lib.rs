//! The published experiments of augsim, each against its published figures: ([`run`], [`Name`])
//! each generates its data, trains, identifies or registers, evaluates on data that played no
//! part in producing the model, and writes `DIR/<name>/result.json` with its figures beside the
//! published ones, plus PNG figures. [`report`] gathers the results into `DIR/report.md`,
//! `DIR/report.html`, `docs/results.md` and the README's headline table. They run on the
//! application layer (`augsim-app`); only the command line links them.
//!
//! Every step of an experiment resumes after a kill: datasets and training resume from what is
//! on disk, and an experiment whose `result.json` was written at the requested size by this very
//! build ([`BUILD`]) is not run again.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context, Result};
use serde::{Deserialize, Serialize};

pub mod bench;
pub mod calculix;
mod fem_convergence;
mod fem_peer;
mod fem_speed;
mod held_out;
mod identification;
mod learning;
mod loads;
mod reference;
mod registration;
pub mod report;
mod stream;
mod transfer;

/// How large an experiment is run.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Size {
    /// Minutes on 2 cores: fewer samples, steps and filter iterations.
    Quick,
    /// The published data sizes (training budgets stay within a CPU's reach: see each result's notes).
    Paper,
}

/// One experiment per published result.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Name {
    /// Static FEM solve times on the liver (published: SVK 1,550 ms, co-rotational 25 ms).
    FemSpeed,
    /// Convergence of the elements under mesh refinement (error versus dofs and time).
    FemConvergence,
    /// The static solver against CalculiX on the same problems (needs `ccx`).
    FemPeer,
    /// Young's modulus of the liver identified by the ROUKF from tracked surface points.
    Young,
    /// Hidden boundary springs identified by the ROUKF.
    Springs,
    /// U-Net from nodal forces to the liver's displacement.
    LiverForces,
    /// Registration to a partial point cloud, TRE at internal markers.
    LiverAr,
    /// Beam: pre-trained on other boundary conditions and fine-tuned on 100 samples.
    BeamTransfer,
    /// Beam with sparse, noisy imposed displacements.
    BeamSparse,
    /// Registration on a stream over OpenIGTLink: latency, frame rate and TRE per frame.
    Stream,
    /// Registration on held-out cases: the shipped network and the FEM, TRE and time per frame.
    HeldOut,
}

impl Name {
    /// Every experiment, in the order `all` runs them.
    pub const ALL: [Name; 11] = [
        Name::FemSpeed,
        Name::FemConvergence,
        Name::FemPeer,
        Name::Young,
        Name::Springs,
        Name::LiverForces,
        Name::LiverAr,
        Name::BeamTransfer,
        Name::BeamSparse,
        Name::Stream,
        Name::HeldOut,
    ];

    /// The command-line and directory name.
    pub fn as_str(self) -> &'static str {
        match self {
            Name::FemSpeed => "fem-speed",
            Name::FemConvergence => "fem-convergence",
            Name::FemPeer => "fem-peer",
            Name::Young => "young",
            Name::Springs => "springs",
            Name::LiverForces => "liver-forces",
            Name::LiverAr => "liver-ar",
            Name::BeamTransfer => "beam-transfer",
            Name::BeamSparse => "beam-sparse",
            Name::Stream => "stream",
            Name::HeldOut => "held-out",
        }
    }

    /// The heading of its report section.
    pub fn title(self) -> &'static str {
        match self {
            Name::FemSpeed => "Static FEM on the liver: solve times",
            Name::FemConvergence => "FEM convergence under mesh refinement",
            Name::FemPeer => "Static FEM against CalculiX",
            Name::Young => "ROUKF: Young's modulus",
            Name::Springs => "ROUKF: hidden boundary springs",
            Name::LiverForces => "U-Net: liver, nodal forces → displacement",
            Name::LiverAr => "Registration for augmented reality (TRE)",
            Name::BeamTransfer => "U-Net: beam, transfer learning to a hidden boundary condition",
            Name::BeamSparse => "U-Net: beam, sparse visible displacement",
            Name::Stream => "Live registration over OpenIGTLink (press and release)",
            Name::HeldOut => "Registration on held-out cases",
        }
    }

    /// Parses a command-line name.
    pub fn parse(s: &str) -> Result<Name> {
        Name::ALL.into_iter().find(|n| n.as_str() == s).with_context(|| {
            let names: Vec<&str> = Name::ALL.iter().map(|n| n.as_str()).collect();
            format!("unknown experiment '{s}' (one of: {}, all)", names.join(", "))
        })
    }

    /// The experiments `s` names: one by its name, or `all` of them.
    pub fn chosen(s: &str) -> Result<Vec<Name>> {
        match s {
            "all" => Ok(Name::ALL.to_vec()),
            one => Ok(vec![Name::parse(one)?]),
        }
    }
}

impl Size {
    /// Its name: `quick` or `paper`.
    pub fn as_str(self) -> &'static str {
        match self {
            Size::Quick => "quick",
            Size::Paper => "paper",
        }
    }
}

impl std::str::FromStr for Size {
    type Err = String;

    fn from_str(s: &str) -> std::result::Result<Size, String> {
        match s {
            "quick" => Ok(Size::Quick),
            "paper" => Ok(Size::Paper),
            other => Err(format!("must be quick or paper, got '{other}'")),
        }
    }
}

/// One figure of a result: ours beside the published one, of the experiment as a whole or of one
/// variant of it (a mesh, a method, a case). The reports show the rows without a variant as a table
/// of quantities, and the rows of each [`Row::table`] as a table with one line per variant and one
/// column per quantity ([`report`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Row {
    /// What is measured.
    pub quantity: String,
    /// Our value, formatted with its unit.
    pub ours: String,
    /// The published value, formatted, or empty where none was published.
    pub published: String,
    /// The variant measured (e.g. "11k model"), or empty for the experiment as a whole.
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub variant: String,
    /// The table of variants the row belongs to, named by the heading of its variant column (e.g.
    /// "filter run"); empty without a variant.
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub table: String,
}

impl Row {
    /// A row; `published` may be empty.
    pub fn new(quantity: impl Into<String>, ours: impl Into<String>, published: impl Into<String>) -> Row {
        Row {
            quantity: quantity.into(),
            ours: ours.into(),
            published: published.into(),
            variant: String::new(),
            table: String::new(),
        }
    }

    /// The row as the figure of `variant` in the table `table` (the heading of its variant column).
    pub fn of(mut self, table: impl Into<String>, variant: impl Into<String>) -> Row {
        self.table = table.into();
        self.variant = variant.into();
        self
    }

    /// What the row measures, in words: its quantity, after its variant where it has one.
    pub fn label(&self) -> String {
        if self.variant.is_empty() {
            self.quantity.clone()
        } else {
            format!("{}: {}", self.variant, self.quantity)
        }
    }
}

/// Whether our figure is better than the published one.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Verdict {
    /// Better by more than [`ON_PAR`].
    Better,
    /// Within [`ON_PAR`] of it (or, for a qualitative finding, the same finding).
    OnPar,
    /// Worse by more than [`ON_PAR`] (or, for a qualitative finding, not found).
    Worse,
    /// Measured where nothing was published.
    Unpublished,
}

impl Verdict {
    /// The word shown in the summaries.
    pub fn word(self) -> &'static str {
        match self {
            Verdict::Better => "better",
            Verdict::OnPar => "on par",
            Verdict::Worse => "worse",
            Verdict::Unpublished => "measured",
        }
    }
}

/// Relative difference within which two figures are on par.
pub const ON_PAR: f64 = 0.05;

/// Ours against a reference where lower is better: on par within [`ON_PAR`], worse when not finite.
fn lower_verdict(ours: f64, reference: f64) -> Verdict {
    if !ours.is_finite() || ours > reference * (1.0 + ON_PAR) {
        Verdict::Worse
    } else if ours < reference * (1.0 - ON_PAR) {
        Verdict::Better
    } else {
        Verdict::OnPar
    }
}

/// A headline figure of an experiment: ours beside the published one, with the verdict.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Headline {
    /// What is compared (one line).
    pub figure: String,
    /// Our value, formatted.
    pub ours: String,
    /// The published value, formatted.
    pub published: String,
    /// Ours against the published one.
    pub verdict: Verdict,
}

impl Headline {
    /// A figure where lower is better (an error, a time): ours and the published one in `unit`,
    /// shown with `digits` decimals.
    pub fn lower_is_better(figure: impl Into<String>, ours: f64, published: f64, digits: usize, unit: &str) -> Self {
        Headline {
            figure: figure.into(),
            ours: fmt(ours, digits, unit),
            published: fmt(published, digits, unit),
            verdict: lower_verdict(ours, published),
        }
    }

    /// An aim stated in words (`aim`, e.g. "as accurate as the FEM"), met when `ours` is no more than
    /// `reference` (lower is better): better, on par or worse by the same [`ON_PAR`] rule as
    /// [`Headline::lower_is_better`]; `shown` is how both figures read in the summary.
    pub fn aim_lower(
        figure: impl Into<String>,
        shown: impl Into<String>,
        aim: impl Into<String>,
        ours: f64,
        reference: f64,
    ) -> Self {
        Headline {
            figure: figure.into(),
            ours: shown.into(),
            published: aim.into(),
            verdict: lower_verdict(ours, reference),
        }
    }

    /// A figure of ours with no published counterpart.
    pub fn measured(figure: impl Into<String>, ours: impl Into<String>) -> Self {
        Headline { figure: figure.into(), ours: ours.into(), published: "—".into(), verdict: Verdict::Unpublished }
    }

    /// A qualitative finding of the publication (`published`) that our run reproduces or not.
    pub fn finding(
        figure: impl Into<String>,
        ours: impl Into<String>,
        published: impl Into<String>,
        holds: bool,
    ) -> Self {
        let verdict = if holds { Verdict::OnPar } else { Verdict::Worse };
        Headline { figure: figure.into(), ours: ours.into(), published: published.into(), verdict }
    }
}

/// What an experiment produced.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ExperimentResult {
    /// The experiment.
    pub name: Name,
    /// The size it ran at.
    pub size: Size,
    /// Wall time of the run that finished it (s; steps resumed from disk are not counted).
    pub seconds: f64,
    /// The build that made it ([`BUILD`]; empty in results written before builds were named).
    #[serde(default)]
    pub build: String,
    /// The headline figures, for the summaries (README, `docs/results.md`).
    #[serde(default)]
    pub headlines: Vec<Headline>,
    /// The table.
    pub rows: Vec<Row>,
    /// Figures (PNG) and 3D viewers (HTML), relative to the experiment's directory.
    pub figures: Vec<String>,
    /// Those of the figures also shown on the results page (`docs/results.md`), copied beside it.
    #[serde(default)]
    pub page_figures: Vec<String>,
    /// What the figures are conditional on (splits, load ranges, failed samples, budgets).
    pub notes: Vec<String>,
    /// The raw numbers behind the table, by name (SI units unless the name says otherwise).
    pub values: serde_json::Map<String, serde_json::Value>,
}

impl ExperimentResult {
    /// The result in words, as printed after a run: its time, then each row's figure beside the
    /// published one (labels in a column as wide as the longest).
    pub fn lines(&self) -> Vec<String> {
        let labels: Vec<String> = self.rows.iter().map(|r| r.label()).collect();
        let width = labels.iter().map(|l| l.chars().count()).max().unwrap_or(0);
        let mut lines = vec![format!("{}: {:.0} s", self.name.title(), self.seconds)];
        for (row, label) in self.rows.iter().zip(&labels) {
            let published =
                if row.published.is_empty() { String::new() } else { format!("   (published: {})", row.published) };
            lines.push(format!("{label:<width$}  {}{published}", row.ours));
        }
        lines
    }
}

/// The result file of an experiment.
pub const RESULT_FILE: &str = "result.json";

/// This build: the commit its sources were built from, with a digest of their uncommitted changes
/// (`+changes-…`), or "unknown" outside a git checkout.
pub const BUILD: &str = env!("AUGSIM_BUILD");

/// augsim's version and build, as `--version` prints them.
pub const VERSION: &str = concat!(env!("CARGO_PKG_VERSION"), " (", env!("AUGSIM_BUILD"), ")");

/// Whether a result already written, `done`, stands for a run at `size` by `build`: made at that
/// size by that very build (one that can be told: not "unknown").
fn reusable(done: &ExperimentResult, size: Size, build: &str) -> bool {
    done.size == size && done.build == build && build != "unknown"
}

/// Where a long run reports: its lines (the CLI prints them) and the advance of its trainings.
pub type Progress<'a> = &'a dyn learn::Progress;

/// Reports the advance of a long part of a run (a dataset, a filter run) as a line at every tenth
/// of it: `label: done/total unit note`.
struct Tenths<'a> {
    progress: Progress<'a>,
    label: String,
    unit: &'static str,
    next: std::sync::atomic::AtomicU64,
}

impl<'a> Tenths<'a> {
    fn new(progress: Progress<'a>, label: String, unit: &'static str) -> Self {
        Tenths { progress, label, unit, next: std::sync::atomic::AtomicU64::new(0) }
    }
}

impl learn::Progress for Tenths<'_> {
    fn advance(&self, done: u64, total: u64, note: &str) {
        use std::sync::atomic::Ordering::Relaxed;
        let tenth = total.div_ceil(10).max(1);
        if done > 0 && (done >= self.next.load(Relaxed).max(tenth) || done == total) {
            self.next.store(done + tenth, Relaxed);
            let note = if note.is_empty() { String::new() } else { format!(" {note}") };
            self.progress.line(&format!("{}: {done}/{total} {}{note}", self.label, self.unit));
        }
    }

    fn line(&self, text: &str) {
        self.progress.line(text);
    }
}

/// Runs experiment `name` at `size` under `root/<name>/` (resuming what is there) and writes
/// its `result.json`. A result already written at the same size by this build ([`BUILD`]), its
/// figures there, is returned as it is; one made by another build, or missing a figure, is made
/// again; one of the other size is refused (a quick run would replace hours of a paper one).
pub fn run(name: Name, size: Size, root: &Path, progress: Progress) -> Result<ExperimentResult> {
    let dir = root.join(name.as_str());
    if let Some(done) = load(&dir)? {
        let file = dir.join(RESULT_FILE);
        if done.size != size {
            bail!(
                "{}: {} holds its {} result, which a {} run would replace: give another --out, or remove it to run \
                 it again",
                name.as_str(),
                file.display(),
                done.size.as_str(),
                size.as_str()
            );
        }
        let missing = done.figures.iter().find(|f| !dir.join(f).exists());
        match (missing, reusable(&done, size, BUILD)) {
            (None, true) => {
                progress.line(&format!(
                    "{}: already done at this size by this build ({})",
                    name.as_str(),
                    file.display()
                ));
                return Ok(done);
            }
            (Some(figure), _) => progress.line(&format!(
                "{}: {figure}, a figure of {}, is missing: running it again on the folder's data",
                name.as_str(),
                file.display()
            )),
            (None, false) => {
                let made_by = if done.build.is_empty() { "an unnamed build".to_string() } else { done.build };
                progress.line(&format!(
                    "{}: {} was made by {made_by}, this is {BUILD}: running it again on the folder's data",
                    name.as_str(),
                    file.display()
                ));
            }
        }
    }
    let resumed = holds_earlier_work(&dir);
    mesh::io::create_folder(&dir)?;
    let start = Instant::now();
    let mut result = match name {
        Name::FemSpeed => fem_speed::run(size, &dir, progress)?,
        Name::FemConvergence => fem_convergence::run(size, &dir, progress)?,
        Name::FemPeer => fem_peer::run(size, &dir, progress)?,
        Name::Young => identification::young(size, &dir, progress)?,
        Name::Springs => identification::springs(size, &dir, progress)?,
        Name::LiverForces => learning::liver_forces(size, &dir, progress)?,
        Name::LiverAr => registration::liver_ar(size, &dir, progress)?,
        Name::BeamTransfer => transfer::beam_transfer(size, &dir, progress)?,
        Name::BeamSparse => learning::beam_sparse(size, &dir, progress)?,
        Name::Stream => stream::run(size, &dir, progress)?,
        Name::HeldOut => held_out::run(size, &dir, progress)?,
    };
    result.seconds = start.elapsed().as_secs_f64();
    result.build = BUILD.to_string();
    // Results made at different times may sit on one page: each says when, and by which build.
    result.notes.push(format!("Made on {} (UTC) by augsim {VERSION}.", today()));
    if resumed {
        result.notes.push(format!(
            "Its folder held an earlier run's work when this run started: what it could reuse from there \
             (draws, a network's checkpoint) is not counted in its {:.0} s.",
            result.seconds
        ));
    }
    let json = serde_json::to_string_pretty(&result)?;
    mesh::io::write_atomic_bytes(&dir.join(RESULT_FILE), json.as_bytes())?;
    Ok(result)
}

/// Today's date (UTC) as YYYY-MM-DD, from the system clock (the proleptic Gregorian calendar).
fn today() -> String {
    let secs = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_secs());
    civil_date(secs.div_euclid(86_400) as i64)
}

/// The date `days` after 1970-01-01 as YYYY-MM-DD (Hinnant's `civil_from_days`).
fn civil_date(days: i64) -> String {
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = doy - (153 * mp + 2) / 5 + 1;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    let year = yoe + era * 400 + i64::from(month <= 2);
    format!("{year:04}-{month:02}-{day:02}")
}

/// Whether `dir` holds anything (an earlier run's work, which the steps that resume reuse).
fn holds_earlier_work(dir: &Path) -> bool {
    std::fs::read_dir(dir).is_ok_and(|mut entries| entries.next().is_some())
}

/// The result in `dir`, if one was written.
pub fn load(dir: &Path) -> Result<Option<ExperimentResult>> {
    let path = dir.join(RESULT_FILE);
    if !path.exists() {
        return Ok(None);
    }
    let text = std::fs::read_to_string(&path).with_context(|| format!("reading {}", path.display()))?;
    serde_json::from_str(&text).map(Some).with_context(|| format!("{}: not an experiment result", path.display()))
}

/// Every result under `root`, in [`Name::ALL`] order.
pub fn load_all(root: &Path) -> Result<Vec<ExperimentResult>> {
    let mut out = Vec::new();
    for name in Name::ALL {
        if let Some(r) = load(&root.join(name.as_str()))? {
            out.push(r);
        }
    }
    if out.is_empty() {
        bail!("no experiment result under {}", root.display());
    }
    Ok(out)
}

/// The built-in scenario `name` written into `dir` as `<name>.toml` (so that the run records
/// what it used): its path and text.
fn write_scenario(dir: &Path, name: &str) -> Result<(PathBuf, &'static str)> {
    let text = scenario::builtin(name).with_context(|| format!("no built-in scenario {name}"))?;
    let path = dir.join(format!("{name}.toml"));
    mesh::io::write_atomic_bytes(&path, text.as_bytes())?;
    Ok((path, text))
}

/// `v` formatted with `digits` decimals and `unit`.
fn fmt(v: f64, digits: usize, unit: &str) -> String {
    format!("{v:.digits$} {unit}").trim_end().to_string()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Dates against Python's `datetime` (days since 1970-01-01): a leap day, the day before the
    /// epoch, a century that is no leap year.
    #[test]
    fn days_since_the_epoch_are_told_as_calendar_dates() {
        assert_eq!(civil_date(0), "1970-01-01");
        assert_eq!(civil_date(-1), "1969-12-31");
        assert_eq!(civil_date(11_016), "2000-02-29");
        assert_eq!(civil_date(20_794), "2026-12-07");
        assert_eq!(civil_date(47_541), "2100-03-01");
    }

    /// A result stands for a run only at its size and by its very build; a build that cannot be
    /// told (no git) and a result from before builds were named are made again.
    #[test]
    fn a_result_is_reused_only_at_its_size_by_its_own_build() {
        let made = |build: &str| -> ExperimentResult {
            serde_json::from_value(serde_json::json!({
                "name": "springs", "size": "quick", "seconds": 1.0, "build": build,
                "rows": [], "figures": [], "notes": [], "values": {}
            }))
            .unwrap()
        };
        assert!(reusable(&made("c2ffc33ed92f"), Size::Quick, "c2ffc33ed92f"));
        assert!(!reusable(&made("c2ffc33ed92f"), Size::Paper, "c2ffc33ed92f"));
        assert!(!reusable(&made("c2ffc33ed92f"), Size::Quick, "c2ffc33ed92f+changes-0a1b2c3d"));
        assert!(!reusable(&made("c2ffc33ed92f+changes-0a1b2c3d"), Size::Quick, "c2ffc33ed92f+changes-9f8e7d6c"));
        assert!(!reusable(&made("unknown"), Size::Quick, "unknown"));
        let unnamed: ExperimentResult = serde_json::from_str(
            r#"{"name": "springs", "size": "quick", "seconds": 1.0, "rows": [], "figures": [], "notes": [], "values": {}}"#,
        )
        .unwrap();
        assert!(unnamed.build.is_empty() && !reusable(&unnamed, Size::Quick, BUILD));
        // This build's own name: a 12-digit commit, with a digest of its changes, or "unknown".
        let (commit, changes) = BUILD.split_once("+changes-").unwrap_or((BUILD, "00000000"));
        let hex = |s: &str, n: usize| s.len() == n && s.chars().all(|c| c.is_ascii_hexdigit());
        assert!(BUILD == "unknown" || (hex(commit, 12) && hex(changes, 8)), "{BUILD}");
    }

    #[test]
    fn a_folder_with_files_holds_earlier_work_an_empty_or_missing_one_not() {
        let root = tempfile::tempdir().unwrap();
        let dir = root.path().join("liver-ar");
        assert!(!holds_earlier_work(&dir));
        std::fs::create_dir(&dir).unwrap();
        assert!(!holds_earlier_work(&dir));
        std::fs::write(dir.join("liver_ar_t10.toml"), "").unwrap();
        assert!(holds_earlier_work(&dir));
    }
}
