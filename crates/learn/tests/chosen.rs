//! σ-chosen draws: the highest-σ candidates are chosen, never held out, the uniform draws stay
//! those of a uniform dataset, and an interrupted run resumes to the same dataset.

mod common;

use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::Path;

use augsim_learn::data::generate::{DatasetConfig, Generator, Input, Load};
use augsim_learn::rom::{fit, Context, ReducedModel, RomConfig};
use augsim_learn::{merge_datasets, ChoiceRecipe, Dataset, Silent, SplitPolicy, CANDIDATE_BASE, MODEL_FILE};
use common::Lines;
use fem::{Law, Material, SolverOptions};
use mesh::NodeSelection;

const UNIFORM: usize = 40;
const PER_ROUND: usize = 3;
const CANDIDATES: usize = 30;
const ROUNDS: usize = 2;

/// A beam fixed at one end, pushed on its top face; force inputs on the lattice of its nodes.
fn generator(samples: usize, seed: u64) -> Generator {
    let mesh = mesh::box_hex([0.0; 3], [4.0, 1.0, 1.0], [8, 2, 2]).unwrap();
    let top = NodeSelection::Box { min: [1.0, -1e-6, 1.0 - 1e-6], max: [4.0 + 1e-6, 1.0 + 1e-6, 1.0 + 1e-6] };
    let config = DatasetConfig {
        samples,
        seed,
        shard_size: 2,
        grid: None,
        fixed: vec![NodeSelection::Box { min: [-1e-6; 3], max: [1e-6, 1.0 + 1e-6, 1.0 + 1e-6] }],
        attachment: vec![],
        load: Load::PatchForce { centres: Some(top), radius: 0.6, magnitude: [0.0, 0.3], cone: Some(60.0) },
        gravity: None,
        input: Input::Force,
    };
    Generator::new(mesh, Material::new(Law::NeoHookean, 300.0, 0.3), SolverOptions::default(), config).unwrap()
}

/// Runs `f` in a rayon pool of two threads.
fn in_pool<T: Send>(f: impl FnOnce() -> T + Send) -> T {
    rayon::ThreadPoolBuilder::new().num_threads(2).build().unwrap().install(f)
}

/// The uniform dataset of `g` in `dir` and a reduced-order model (with the physics prior) trained
/// on it, saved in `model_dir`.
fn uniform_dataset_and_model(g: &Generator, dir: &Path, model_dir: &Path) {
    in_pool(|| g.run(dir, "beam", None, &Silent)).unwrap();
    let dataset = Dataset::open(dir).unwrap();
    let all = dataset.load_all().unwrap();
    let (split, [train, validation, _]) = SplitPolicy::default().apply(&all).unwrap();
    let context = Context::of_dataset(dataset.manifest(), split);
    let mut prior = g.rest_response().unwrap();
    let (model, _) = fit(&train, &validation, &RomConfig::default(), context, Some(&mut prior)).unwrap();
    model.save(model_dir).unwrap();
}

/// The mean σ over the organ's nodes that `model` predicts for draw `index` of `g`.
fn sigma(g: &Generator, model: &ReducedModel, index: u64) -> Option<f64> {
    let input = g.draw_input(index).ok()?;
    let std = model.predict_with_std(&input).unwrap().std;
    Some(model.nodes().iter().map(|&n| f64::from(std[n])).sum::<f64>() / model.nodes().len() as f64)
}

/// Every file under `dir` with its bytes, but the refitted models' `model.json` (which records
/// its fit's time) without its seconds.
fn files(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for entry in std::fs::read_dir(d).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                stack.push(path);
                continue;
            }
            let mut bytes = std::fs::read(&path).unwrap();
            if path.ends_with(MODEL_FILE) {
                let mut json: serde_json::Value = serde_json::from_slice(&bytes).unwrap();
                json["rom"]["seconds"] = serde_json::Value::Null;
                bytes = json.to_string().into_bytes();
            }
            out.push((path.strip_prefix(dir).unwrap().display().to_string(), bytes));
        }
    }
    out.sort();
    out
}

#[test]
fn the_most_uncertain_candidates_are_solved_and_never_held_out() {
    let g = generator(UNIFORM, 5);
    let tmp = tempfile::tempdir().unwrap();
    let (dir, model_dir, plain) = (tmp.path().join("data"), tmp.path().join("rom"), tmp.path().join("plain"));
    uniform_dataset_and_model(&g, &dir, &model_dir);
    in_pool(|| g.run(&plain, "beam", None, &Silent)).unwrap();
    let recipe = ChoiceRecipe::new(&model_dir, PER_ROUND, CANDIDATES, ROUNDS).unwrap();
    let lines = Lines::default();
    let manifest = in_pool(|| g.run_chosen(&dir, "beam", &recipe, &lines)).unwrap();
    assert!(manifest.complete);
    let chosen = manifest.chosen.clone().unwrap();
    assert_eq!(chosen.rounds.len(), ROUNDS);
    assert_eq!(lines.0.lock().unwrap().len(), ROUNDS + 1, "a line for the draws held, one per round");

    // Each round's choice: its model's highest-σ candidates, with their σ.
    for round in &chosen.rounds {
        let path = if round.round == 1 { model_dir.clone() } else { dir.join(&round.model) };
        assert_eq!(round.model.ends_with("round_2"), round.round == 2);
        let model = ReducedModel::load(&path.join(MODEL_FILE)).unwrap();
        let candidates: Vec<(u64, f64)> =
            (round.candidates[0]..round.candidates[1]).filter_map(|i| sigma(&g, &model, i).map(|s| (i, s))).collect();
        assert_eq!((candidates.len(), round.indices.len()), (round.ranked, PER_ROUND));
        assert!(candidates.iter().all(|&(i, _)| i >= CANDIDATE_BASE));
        let lowest_chosen = round.scores.iter().copied().fold(f64::INFINITY, f64::min);
        for &(i, s) in &candidates {
            match round.indices.iter().position(|&c| c == i) {
                Some(k) => {
                    assert!((s - round.scores[k]).abs() <= 1e-12 * s, "draw {i}: σ {s} recorded {}", round.scores[k])
                }
                None => assert!(s <= lowest_chosen, "candidate {i} (σ {s}) beats a chosen one ({lowest_chosen})"),
            }
        }
        assert!(round.median_score < lowest_chosen);
        for &i in &round.indices {
            assert_eq!(chosen.round_of(i).map(|r| r.round), Some(round.round));
        }
    }
    // The refit trained on the uniform training draws and the first round's.
    let refit = ReducedModel::load(&dir.join(&chosen.rounds[1].model).join(MODEL_FILE)).unwrap();
    let start = ReducedModel::load(&model_dir.join(MODEL_FILE)).unwrap();
    let solved_first =
        chosen.rounds[0].indices.iter().filter(|&&i| !manifest.failed.iter().any(|f| f.index == i)).count();
    assert_eq!(refit.info.train_samples, start.info.train_samples + solved_first);
    assert_eq!(
        (&refit.info.split.validation, &refit.info.split.test),
        (&start.info.split.validation, &start.info.split.test)
    );

    // The uniform draws are those of the uniform dataset; the chosen ones all train.
    let all = Dataset::open(&dir).unwrap().load_all().unwrap();
    let uniform = Dataset::open(&plain).unwrap().load_all().unwrap();
    let positions: Vec<usize> = (0..uniform.len()).collect();
    assert_eq!(all.select(&positions).unwrap(), uniform);
    assert!(all.indices[uniform.len()..].iter().all(|&i| i >= CANDIDATE_BASE));
    assert!(all.len() > uniform.len());
    // Held out as from the uniform dataset alone (the same fractions of its draws).
    let (split, [train, validation, test]) = SplitPolicy::default().apply(&all).unwrap();
    let uniform_split = SplitPolicy::default().split(&uniform).unwrap();
    assert_eq!((&split.validation, &split.test), (&uniform_split.validation, &uniform_split.test));
    assert!(validation.indices.iter().chain(&test.indices).all(|&i| i < CANDIDATE_BASE));
    assert_eq!(train.len() + validation.len() + test.len(), all.len());
    assert!(all.indices.iter().filter(|&&i| i >= CANDIDATE_BASE).all(|i| train.indices.contains(i)));

    // Asking for a third round adds one; the first two stay.
    let more = ChoiceRecipe::new(&model_dir, PER_ROUND, CANDIDATES, ROUNDS + 1).unwrap();
    let grown = in_pool(|| g.run_chosen(&dir, "beam", &more, &Silent)).unwrap();
    let grown_chosen = grown.chosen.unwrap();
    assert_eq!(grown_chosen.rounds[..ROUNDS], chosen.rounds[..]);
    assert_eq!(grown_chosen.rounds.len(), ROUNDS + 1);
}

/// Runs the choice of `recipe` into `dir`, killed (its progress report panics) where `stop` says,
/// and leaves the dataset unfinished.
fn killed(g: &Generator, dir: &Path, recipe: &ChoiceRecipe, stop: impl Fn(u64, u64, &str) -> bool + Sync) {
    let progress = |done: u64, all: u64, note: &str| {
        if stop(done, all, note) {
            panic!("simulated kill")
        }
    };
    let result = catch_unwind(AssertUnwindSafe(|| in_pool(|| g.run_chosen(dir, "beam", recipe, &progress))));
    assert!(result.is_err());
    assert!(!Dataset::open(dir).unwrap().manifest().complete);
}

#[test]
fn an_interrupted_choice_resumes_to_the_same_dataset() {
    let g = generator(UNIFORM, 6);
    let tmp = tempfile::tempdir().unwrap();
    let model_dir = tmp.path().join("rom");
    let whole = tmp.path().join("whole");
    uniform_dataset_and_model(&g, &whole, &model_dir);
    let resumed = tmp.path().join("resumed");
    std::fs::create_dir(&resumed).unwrap();
    for entry in std::fs::read_dir(&whole).unwrap() {
        let from = entry.unwrap().path();
        let to = resumed.join(from.file_name().unwrap());
        if from.is_dir() {
            std::fs::create_dir(&to).unwrap();
            for f in std::fs::read_dir(&from).unwrap() {
                let f = f.unwrap().path();
                std::fs::copy(&f, to.join(f.file_name().unwrap())).unwrap();
            }
        } else {
            std::fs::copy(&from, &to).unwrap();
        }
    }
    let recipe = ChoiceRecipe::new(&model_dir, PER_ROUND, CANDIDATES, ROUNDS).unwrap();
    in_pool(|| g.run_chosen(&whole, "beam", &recipe, &Silent)).unwrap();
    let reference = files(&whole);
    // Killed with the first round's last draw solved but not committed, then after the refit
    // before the second round's choice is recorded.
    let total = (PER_ROUND * ROUNDS) as u64;
    killed(&g, &resumed, &recipe, |done, all, note| all == total && done == PER_ROUND as u64 && note.is_empty());
    killed(&g, &resumed, &recipe, |_, _, note| note.starts_with("round 2: ranking"));
    in_pool(|| g.run_chosen(&resumed, "beam", &recipe, &Silent)).unwrap();
    assert!(files(&resumed) == reference, "a resumed choice must give the dataset of an uninterrupted one");
}

#[test]
fn bad_choices_are_refused_with_a_reason() {
    let g = generator(UNIFORM, 7);
    let tmp = tempfile::tempdir().unwrap();
    let (dir, model_dir) = (tmp.path().join("data"), tmp.path().join("rom"));
    uniform_dataset_and_model(&g, &dir, &model_dir);
    let error = |r: augsim_learn::Result<augsim_learn::Manifest>| r.unwrap_err().to_string();
    assert!(ChoiceRecipe::new(&model_dir, 5, 4, 1).unwrap_err().to_string().contains("candidates"));
    assert!(ChoiceRecipe::new(&model_dir, 0, 4, 1).is_err());
    let message = ChoiceRecipe::new(&dir.join("manifest.json"), 1, 4, 1).unwrap_err().to_string();
    assert!(message.contains("not a reduced-order model"), "{message}");
    assert!(ChoiceRecipe::new(&tmp.path().join("nothing"), 1, 4, 1).is_err());
    // A model of another dataset (another seed).
    let other = generator(UNIFORM, 8);
    let recipe = ChoiceRecipe::new(&model_dir, 2, 10, 1).unwrap();
    let message = error(in_pool(|| other.run_chosen(&tmp.path().join("other"), "beam", &recipe, &Silent)));
    assert!(message.contains("not on this dataset's draws"), "{message}");
    // Chosen draws are not merged, and their dataset's uniform draws do not grow.
    in_pool(|| g.run_chosen(&dir, "beam", &recipe, &Silent)).unwrap();
    let message = merge_datasets(std::slice::from_ref(&dir), &tmp.path().join("merged"), None).unwrap_err().to_string();
    assert!(message.contains("σ-chosen"), "{message}");
    // Refused, the dataset is left as it was (complete, no lock left), and no resumption is told.
    let lines = Lines::default();
    let before = files(&dir);
    let message = error(in_pool(|| generator(UNIFORM + 5, 7).run(&dir, "beam", None, &lines)));
    assert!(message.contains("cannot grow"), "{message}");
    // Another recipe, or fewer rounds than the dataset holds, do not go on from this one.
    let another = ChoiceRecipe::new(&model_dir, 3, 10, 1).unwrap();
    let message = error(in_pool(|| g.run_chosen(&dir, "beam", &another, &lines)));
    assert!(message.contains("another model or count"), "{message}");
    assert!(files(&dir) == before, "a refused run writes nothing");
    in_pool(|| g.run_chosen(&dir, "beam", &ChoiceRecipe::new(&model_dir, 2, 10, 2).unwrap(), &Silent)).unwrap();
    let before = files(&dir);
    let message = error(in_pool(|| g.run_chosen(&dir, "beam", &recipe, &lines)));
    assert!(message.contains("holds 2 rounds of σ-chosen draws, more than the 1 asked"), "{message}");
    assert!(files(&dir) == before, "a refused run writes nothing");
    assert!(before.iter().all(|(name, _)| name != augsim_learn::data::dataset::WRITER_LOCK));
    assert!(lines.0.lock().unwrap().is_empty(), "{:?}", lines.0.lock().unwrap());
}
