//! A comparison case run end to end, as `augsim register --demo` and `--case` run it: the case
//! simulated and written, registered by each of its methods, the comparison written.

use std::path::{Path, PathBuf};

use anyhow::{bail, Result};
use learn::{Model, Progress};
use scenario::registration::MethodKind;
use scenario::{CaseScenario, DatasetScenario};

use crate::case::{ar_scenario, case_methods, compare, shipped_models, synthetic_case, Compared};
use crate::models::Network;
use crate::output::{write_case, write_comparison};
use crate::printout::{case_files_lines, case_lines, comparison_table, rigid_lines};

/// The learned models a comparison registers with: `model` (default: the shipped U-Net and
/// reduced-order model, [`shipped_models`]), trained on the dataset scenario `scenario`
/// (default: [`ar_scenario`]).
#[derive(Clone, Copy, Debug, Default)]
pub struct LearnedModels<'a> {
    /// The model's directory or model.json.
    pub model: Option<&'a Path>,
    /// The dataset scenario it was trained on (TOML).
    pub scenario: Option<&'a Path>,
}

/// Runs the comparison of `scenario` into `out`: simulates its case and writes it to `out/case`,
/// registers it with each of its methods (the learned ones with `learned`: a model given must be
/// there, a shipped one not found is skipped with a line saying so), writes `comparison.csv`, `summary.json` and each
/// method's files. Its lines (the case, its files, the rigid part, the table, what it wrote) go to
/// `progress.line` as they come; `progress` advances over the methods. Returns the comparison's
/// rows (a method that failed carries its error).
pub fn run_comparison(
    scenario: &CaseScenario,
    learned: LearnedModels,
    out: &Path,
    progress: &dyn Progress,
) -> Result<Vec<Compared>> {
    let wants_network =
        scenario.models.method.iter().any(|m| matches!(m.kind, MethodKind::Network | MethodKind::Hybrid));
    if !wants_network && learned.model.is_some() {
        bail!("--model: the case scenario has no network or hybrid method to register with it");
    }
    let lines = |lines: Vec<String>| lines.iter().for_each(|l| progress.line(l));
    lines(case_lines(scenario));
    let case = synthetic_case(scenario)?;
    let dir = out.join("case");
    write_case(&dir, &case)?;
    lines(case_files_lines(&case, &dir));

    let (models, skipped) = match (wants_network, learned.model) {
        (false, _) => (Vec::new(), Vec::new()),
        (true, Some(path)) => (vec![Model::load(path)?], Vec::new()),
        (true, None) => shipped_models()?,
    };
    for line in skipped {
        progress.line(&format!("model      {line} (give --model)"));
    }
    let (network_scenario, network_dir) = match learned.scenario {
        Some(path) => DatasetScenario::load(path)?,
        None => (ar_scenario(), PathBuf::new()),
    };
    let networks = Network::each(&models, &network_scenario, &network_dir);
    let methods = case_methods(scenario, &networks)?;
    if methods.is_empty() {
        bail!("no method to compare");
    }
    let total = methods.len() as u64;
    let mut rows = Vec::with_capacity(methods.len());
    for (i, method) in methods.iter().enumerate() {
        progress.advance(i as u64, total, &method.name);
        rows.extend(compare(&case, std::slice::from_ref(method)));
    }
    progress.advance(total, total, "");
    let first = rows.iter().find_map(|r| r.result.as_ref().ok());
    if let Some(r) = first.and_then(|r| r.outcomes[0].rigid.as_ref()) {
        lines(rigid_lines(r, Some(&case.pose)));
    }
    lines(comparison_table(&rows));
    write_comparison(out, &case, &rows)?;
    let peak = if case.frames.len() > 1 { ", of the peak frame" } else { "" };
    progress.line("");
    progress.line(&format!(
        "wrote      {} (comparison.csv, summary.json; per method{peak}: organ.vtu, targets.csv, registration.png and \
         .html)",
        out.display()
    ));
    Ok(rows)
}
