//! A dataset generated as `augsim generate` asks: a dataset scenario's uniform draws, whole or
//! one part of them, and then, if asked, draws chosen where a reduced-order model is least sure.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Result;
use learn::data::chosen::is_uniform;
use learn::{ChoiceRecipe, DatasetPart, Progress};
use scenario::DatasetScenario;

/// The arguments of `augsim generate`.
#[derive(Debug, Clone, clap::Args)]
pub struct GenerateArgs {
    /// Dataset scenario: a TOML file, or the name of a built-in one (e.g. liver_forces).
    pub scenario: PathBuf,
    /// Output directory; default `out/<name>` (or `out/<name>.part<i>of<n>`).
    #[arg(short, long)]
    pub out: Option<PathBuf>,
    /// Generate only part i of n (e.g. 0/8), for array jobs; join with `merge`.
    #[arg(long, value_parser = parse_part)]
    pub shard: Option<DatasetPart>,
    /// Override the number of samples; more than a dataset in --out was made for grows it (a rerun
    /// without it keeps the count the dataset was made for).
    #[arg(long)]
    pub samples: Option<usize>,
    /// After the uniform draws, draws where this reduced-order model (trained on them: `augsim
    /// train DIR --method rom`) is least sure: each round ranks --candidates drawn loads by its
    /// predicted σ (the mean over the organ's grid nodes), solves the --chosen highest, and fits
    /// the model again (its own settings; kept in DIR/chosen) for the next round. Force inputs.
    #[arg(long, value_name = "MODEL_DIR", conflicts_with = "shard")]
    pub chosen_by: Option<PathBuf>,
    /// With --chosen-by: draws chosen, and solved, per round.
    #[arg(long, default_value_t = 100, requires = "chosen_by")]
    pub chosen: usize,
    /// With --chosen-by: rounds (rerun with more to add rounds).
    #[arg(long, default_value_t = 1, requires = "chosen_by")]
    pub rounds: usize,
    /// With --chosen-by: candidates ranked per round [default: 20 per chosen draw].
    #[arg(long, requires = "chosen_by")]
    pub candidates: Option<usize>,
}

/// Parses `i/n`, part `i` of `n`.
fn parse_part(s: &str) -> Result<DatasetPart, String> {
    let (i, n) = s.split_once('/').ok_or_else(|| format!("expected i/n (e.g. 0/8), got '{s}'"))?;
    let number = |t: &str| t.trim().parse::<usize>().map_err(|e| format!("'{t}' in '{s}': {e}"));
    let part = DatasetPart { index: number(i)?, count: number(n)? };
    if part.count == 0 || part.index >= part.count {
        return Err(format!("{s}: need 0 ≤ i < n"));
    }
    Ok(part)
}

/// Generates the dataset `args` asks for, resuming one left unfinished; reports to `progress` the
/// scenario, mesh and grid in lines, the draws, and each round of chosen draws. Returns the
/// summary in lines.
pub fn generate(args: &GenerateArgs, progress: &dyn Progress) -> Result<Vec<String>> {
    let (mut scenario, dir) = DatasetScenario::load(&args.scenario)?;
    // Where the dataset goes, refused before its mesh and grid are built.
    let out = args.out.clone().unwrap_or_else(|| match &args.shard {
        None => PathBuf::from(format!("out/{}", scenario.name)),
        Some(p) => PathBuf::from(format!("out/{}.part{}of{}", scenario.name, p.index, p.count)),
    });
    // A dataset resumed keeps the count it was made for, unless --samples grows it: a bare rerun
    // must not turn a finished dataset of 60 draws into an unfinished one of the scenario's thousands.
    let existing = learn::Dataset::open(&out).ok();
    let made_for = existing.as_ref().and_then(|d| d.manifest().spec().requested_samples());
    match (args.samples, made_for) {
        (Some(n), _) => scenario.dataset.samples = n,
        (None, Some(n)) => scenario.dataset.samples = n as usize,
        (None, None) => {}
    }
    let recipe = match &args.chosen_by {
        Some(model) => {
            let candidates = args.candidates.unwrap_or(20 * args.chosen);
            Some(ChoiceRecipe::new(model, args.chosen, candidates, args.rounds)?)
        }
        None => None,
    };
    if out.join(learn::MODEL_FILE).exists() {
        anyhow::bail!(
            "{} holds a model ({}): a dataset written there would mix their files; give another --out",
            out.display(),
            learn::MODEL_FILE
        );
    }
    progress.line(&format!("scenario   {}: {}", scenario.name, scenario.description));
    if let (None, Some(n)) = (args.samples, made_for) {
        progress.line(&format!("samples    {n}, the count {} was made for (--samples grows it)", out.display()));
    }
    let generator = scenario.generator(&dir)?;
    let mesh = generator.mesh();
    progress.line(&format!(
        "mesh       {} nodes, {} {} cells",
        mesh.num_nodes(),
        mesh.cells.len(),
        mesh.cells.kind_name()
    ));
    let (grid, inside) = (generator.grid(), generator.mask().iter().filter(|&&m| m == 1).count());
    progress.line(&format!("grid       {} × {} × {} ({inside} nodes inside)", grid.nx, grid.ny, grid.nz));
    if inside == 0 {
        anyhow::bail!(
            "{}: no node of its [dataset] grid = [{}, {}, {}] lies inside the organ, so no draw would hold a \
             target: make the grid finer",
            args.scenario.display(),
            grid.nx,
            grid.ny,
            grid.nz
        );
    }
    // What the dataset held before this run (resumed, grown, or complete already); the generator
    // says it resumes once it has accepted the dataset.
    let held = existing.map_or(0, |d| d.manifest().num_samples + d.manifest().failed.len());
    let start = Instant::now();
    let manifest = match &recipe {
        None => generator.run(&out, &scenario.name, args.shard.clone(), progress)?,
        Some(recipe) => generator.run_chosen(&out, &scenario.name, recipe, progress)?,
    };
    let elapsed = start.elapsed();
    let secs = elapsed.as_secs_f64();
    let drawn = manifest.num_samples + manifest.failed.len();
    if let Some(first) = manifest.failed.first().filter(|_| manifest.num_samples == 0) {
        anyhow::bail!(
            "every one of its {} draws failed, so {} holds no sample (the first: {}; the others' reasons are in its \
             manifest): lighten the loads or check the scenario",
            manifest.failed.len(),
            out.display(),
            first.reason
        );
    }
    let mut lines = vec![match (&args.shard, drawn) {
        (Some(p), 0) => format!(
            "samples    none: draws are shared out in whole blocks, and {} draws leave part {}/{} without one \
             (fewer parts give each one)",
            scenario.dataset.samples, p.index, p.count
        ),
        _ => format!(
            "samples    {} written, {} failed (reasons in the manifest)",
            manifest.num_samples,
            manifest.failed.len()
        ),
    }];
    if let Some(chosen) = &manifest.chosen {
        let count: usize = chosen.rounds.iter().map(|r| r.indices.len()).sum();
        let failed = manifest.failed.iter().filter(|f| !is_uniform(f.index)).count();
        lines.push(format!(
            "chosen     {count} draws where the model was least sure, in {} rounds ({failed} of them failed)",
            chosen.rounds.len()
        ));
    }
    let per_draw = |n: usize| mesh::stats::ms(elapsed) / n as f64;
    lines.push(match (drawn.saturating_sub(held), held) {
        (0, 0) => format!("time       {secs:.1} s"),
        (0, _) => format!("time       {secs:.1} s: the dataset was complete, nothing drawn"),
        (now, 0) => format!("time       {secs:.1} s ({:.1} ms per draw)", per_draw(now)),
        (now, held) => {
            format!(
                "time       {secs:.1} s ({:.1} ms per draw; {now} drawn by this run after the {held} held)",
                per_draw(now)
            )
        }
    });
    lines.push(format!("wrote      {}", out.display()));
    Ok(lines)
}

/// `augsim merge`: the dataset parts `parts` (written with `generate --shard i/n`) merged into
/// `out`; the line that says so.
pub fn merge(out: &std::path::Path, parts: &[PathBuf]) -> Result<String> {
    let manifest = learn::merge_datasets(parts, out, None)?;
    Ok(format!(
        "merged {} part{}: {} samples, {} failed → {}",
        parts.len(),
        if parts.len() == 1 { "" } else { "s" },
        manifest.num_samples,
        manifest.failed.len(),
        out.display()
    ))
}
