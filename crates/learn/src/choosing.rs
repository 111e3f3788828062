//! σ-chosen draws: after a dataset's uniform draws, draws where a reduced-order model is least sure
//! (active learning).
//!
//! Each round draws `candidates` candidate loads and encodes them without solving them (force
//! inputs: [`Generator::draw_input`]); a reduced-order model scores each by its predicted σ; the
//! FEM solves the `per_round` highest; then the model is fitted again on every draw of the dataset
//! but its own validation and test draws (with its own fit settings and physics prior), and ranks
//! the next round's candidates. The refitted models are kept in the dataset (`chosen/round_<r>`).
//!
//! Candidates are generation indices from [`CANDIDATE_BASE`] on, round after round: they never
//! meet the uniform draws `0..samples`, whose samples stay those of a dataset without chosen
//! draws. A candidate's loads depend on the seed and its index alone, as a uniform draw's do.
//!
//! The score of a candidate is the mean over the organ's grid nodes of the model's predicted
//! standard deviation ([`ReducedModel::predict_with_std`]): the error the model expects of that
//! draw, averaged over the nodes as a sample's test error is. Every node's σ grows with the one
//! predictive variance of the regression at the input, so the largest node σ would rank the
//! candidates alike.
//!
//! The manifest records the recipe and each round ([`ChosenDraws`]): which model ranked how many
//! candidates, which draws it chose, and their scores; every other draw is uniform. A dataset is
//! reproducible from its seed, the recipe and the starting model. An interrupted run resumes where
//! it stopped: a round's choice is recorded before its draws are solved, and they are solved in
//! blocks as uniform draws are, so that a resumed round gives the same samples. Validation and
//! test sets are made of uniform draws only ([`crate::Split::last`]).

use std::ops::Range;
use std::path::{Path, PathBuf};

use rayon::prelude::*;

use crate::data::chosen::{invalid, ChoiceRecipe, ChosenDraws, ChosenRound, CANDIDATE_BASE};
use crate::data::dataset::{fnv1a, Dataset, DatasetWriter, Manifest, MANIFEST_FILE};
use crate::data::generate::{Generator, Input, BLOCK};
use crate::data::response::RestResponse;
use crate::data::split::{IndexSet, Split};
use crate::model::{Method, Model, MODEL_FILE};
use crate::progress::Progress;
use crate::rom::{fit, Context, ReducedModel};
use crate::FieldUnit;
use crate::{LearnError, Result};

/// Where a dataset keeps the models refitted between rounds.
const MODELS_DIR: &str = "chosen";

impl ChoiceRecipe {
    /// `rounds` rounds of `per_round` draws, each chosen among `candidates`, starting with the
    /// reduced-order model `model` (a directory or its `model.json`); checks the counts.
    pub fn new(model: &Path, per_round: usize, candidates: usize, rounds: usize) -> Result<ChoiceRecipe> {
        if per_round == 0 || rounds == 0 {
            return Err(invalid("σ-chosen draws need at least one round of at least one draw"));
        }
        if candidates < per_round {
            return Err(invalid(format!("{candidates} candidates cannot give {per_round} chosen draws")));
        }
        if (candidates as u64).checked_mul(rounds as u64).is_none_or(|n| n > u64::MAX - CANDIDATE_BASE) {
            return Err(invalid(format!("{rounds} rounds of {candidates} candidates are too many")));
        }
        let json = Model::json_path(model);
        let text = std::fs::read(&json).map_err(|e| LearnError::io(&json, e))?;
        if !matches!(Model::kind(&json), Ok(Method::Rom)) {
            return Err(LearnError::model(&json, "not a reduced-order model (`augsim train --method rom` makes one)"));
        }
        Ok(ChoiceRecipe {
            model: model.to_path_buf(),
            model_hash: format!("{:016x}", fnv1a(&text)),
            per_round,
            candidates,
            rounds,
        })
    }
}

/// The `count` highest-scored candidates (among equal scores, the lower index first), in
/// increasing index order.
fn rank(scored: &[(u64, f64)], count: usize) -> Vec<(u64, f64)> {
    let mut order = scored.to_vec();
    order.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
    order.truncate(count);
    order.sort_by_key(|&(i, _)| i);
    order
}

/// The score of a draw of input `input` under `model`: its mean predicted σ over the organ's grid
/// nodes (m).
fn score(model: &ReducedModel, input: &[f32]) -> Result<f64> {
    let std = model.predict_with_std(input)?.std;
    let nodes = model.nodes();
    let mean = nodes.iter().map(|&n| f64::from(std[n])).sum::<f64>() / nodes.len().max(1) as f64;
    if !mean.is_finite() {
        return Err(invalid(format!("the model predicts a σ of {mean}")));
    }
    Ok(mean)
}

impl Generator {
    /// Generates the uniform draws `0..samples` into `dir` as [`run`](Self::run) does (unless they
    /// are there), then `recipe.rounds` rounds of σ-chosen draws (see [`crate::choosing`]),
    /// reporting the chosen draws solved to `progress`, and each round in a line. Resumes an
    /// interrupted run; a dataset with fewer rounds of the same recipe gets the rounds it lacks. A
    /// dataset whose draws another recipe chose, or that holds more rounds, is refused untouched.
    pub fn run_chosen(
        &self,
        dir: &Path,
        name: &str,
        recipe: &ChoiceRecipe,
        progress: &dyn Progress,
    ) -> Result<Manifest> {
        let spec = self.spec(name, None);
        let start = ReducedModel::load(&Model::json_path(&recipe.model))?;
        let mut prior = self.check_chooser(&start, &Manifest::new(&spec).source_id())?;
        let existing = match dir.join(MANIFEST_FILE).exists() {
            true => Some(Dataset::open(dir)?.manifest().clone()),
            false => None,
        };
        let uniform_done = existing.is_some_and(|m| m.chosen.is_some() || (m.complete && m.spec() == spec));
        if !uniform_done {
            self.run(dir, name, None, progress)?;
        }
        let mut writer = DatasetWriter::append(dir, &spec)?;
        let rounds = match writer.manifest().chosen.clone() {
            Some(done) if !done.recipe.continued_by(recipe) => {
                return Err(LearnError::manifest(
                    dir.join(MANIFEST_FILE),
                    format!(
                        "the dataset's draws were chosen by the model {} (hash {}), {} per round among {} \
                         candidates: another model or count cannot go on from them",
                        done.recipe.model.display(),
                        done.recipe.model_hash,
                        done.recipe.per_round,
                        done.recipe.candidates
                    ),
                ));
            }
            Some(done) if done.rounds.len() > recipe.rounds => {
                return Err(invalid(format!(
                    "the dataset holds {} rounds of σ-chosen draws, more than the {} asked",
                    done.rounds.len(),
                    recipe.rounds
                )));
            }
            Some(done) => done.rounds,
            None => Vec::new(),
        };
        if let Some(line) = writer.resumed().filter(|_| uniform_done) {
            progress.line(&line);
        }
        let mut chosen = ChosenDraws { recipe: recipe.clone(), rounds };
        writer.set_chosen(chosen.clone())?;
        let total = (recipe.rounds * recipe.per_round) as u64;
        for r in 0..recipe.rounds {
            let done = (r * recipe.per_round) as u64;
            if r == chosen.rounds.len() {
                let (model, path) = match r {
                    0 => (start.clone(), recipe.model.clone()),
                    _ => {
                        progress.advance(done, total, &format!("round {}: fitting the model again", r + 1));
                        self.refit(dir, &start, prior.as_mut(), r + 1)?
                    }
                };
                progress.advance(done, total, &format!("round {}: ranking {} candidates", r + 1, recipe.candidates));
                let round = self.choose(&model, path, recipe, r)?;
                progress.line(&round.describe());
                chosen.rounds.push(round);
                writer.set_chosen(chosen.clone())?;
            }
            self.solve_round(&mut writer, &chosen.rounds[r].indices, progress, done, total)?;
        }
        writer.finish()
    }

    /// Checks that `model` can choose this generator's draws (a reduced-order model of force inputs
    /// on its grid, fitted on uniform draws of the dataset `source`, its fit settings recorded) and
    /// returns the physics prior of its refits, if it has one.
    fn check_chooser(&self, model: &ReducedModel, source: &str) -> Result<Option<RestResponse>> {
        if self.config().input != Input::Force {
            return Err(invalid("σ-chosen draws need force inputs: a displacement input is known only once solved"));
        }
        if model.grid != self.grid() || model.input_unit != FieldUnit::Newton {
            return Err(invalid(format!(
                "the model predicts on grid {} from inputs in {}, the draws are on grid {} in N",
                model.grid,
                model.input_unit,
                self.grid()
            )));
        }
        if !crate::data::split::same_source(model.info.split.source.as_deref(), Some(source)) {
            return Err(invalid(format!(
                "the model was trained on {:?}, not on this dataset's draws ({source}): train it on the uniform \
                 draws first (`augsim train DATASET --method rom`)",
                model.info.split.source.as_deref().unwrap_or("samples of no dataset")
            )));
        }
        if model.info.fit.is_none() {
            return Err(invalid(
                "the model does not record its fit settings (an earlier augsim saved it): train it again",
            ));
        }
        let Some(description) = &model.info.prior else { return Ok(None) };
        let prior = self.rest_response()?;
        if prior.description() != description {
            return Err(invalid(format!(
                "the model's physics prior is {description}, this dataset's {}",
                prior.description()
            )));
        }
        Ok(Some(prior))
    }

    /// Fits `start` again (its fit settings and physics prior) on every draw of the dataset in
    /// `dir` but its validation and test draws, chosen on its validation draws; saves it in the
    /// dataset as `chosen/round_<round>` and returns it, as loaded from there, with that path.
    fn refit(
        &self,
        dir: &Path,
        start: &ReducedModel,
        prior: Option<&mut RestResponse>,
        round: usize,
    ) -> Result<(ReducedModel, PathBuf)> {
        let dataset = Dataset::open(dir)?;
        let all = dataset.load_all()?;
        let held = &start.info.split;
        let train: Vec<u64> =
            all.indices.iter().copied().filter(|&i| !held.validation.contains(i) && !held.test.contains(i)).collect();
        let split = Split {
            source: all.source.clone(),
            train: IndexSet::from_indices(&train),
            validation: held.validation.clone(),
            test: held.test.clone(),
        };
        let [train, validation, _] = split.apply(&all)?;
        if validation.len() as u64 != held.validation.len() {
            return Err(invalid(format!(
                "{} of the model's {} validation draws are in the dataset: choose with a model trained on it",
                validation.len(),
                held.validation.len()
            )));
        }
        let config = start.info.fit.as_ref().ok_or_else(|| invalid("the model does not record its fit settings"))?;
        let (model, _) = fit(&train, &validation, config, Context::of_dataset(dataset.manifest(), split), prior)?;
        let path = PathBuf::from(MODELS_DIR).join(format!("round_{round}"));
        model.save(&dir.join(&path))?;
        // The model as saved (some arrays in single precision) ranks, so that it gives the recorded scores.
        Ok((ReducedModel::load(&dir.join(&path).join(MODEL_FILE))?, path))
    }

    /// Round `r` (from 0) of `recipe`: its candidates ranked by `model` (found at `path`), the
    /// highest chosen.
    fn choose(&self, model: &ReducedModel, path: PathBuf, recipe: &ChoiceRecipe, r: usize) -> Result<ChosenRound> {
        let first = CANDIDATE_BASE + (r * recipe.candidates) as u64;
        let candidates = first..first + recipe.candidates as u64;
        let scored = self.score_candidates(model, candidates.clone())?;
        if scored.len() < recipe.per_round {
            return Err(invalid(format!(
                "round {}: the loads of only {} of {} candidates could be drawn, fewer than the {} to choose",
                r + 1,
                scored.len(),
                recipe.candidates,
                recipe.per_round
            )));
        }
        let mut sorted: Vec<f64> = scored.iter().map(|&(_, s)| s).collect();
        sorted.sort_by(f64::total_cmp);
        let (indices, scores) = rank(&scored, recipe.per_round).into_iter().unzip();
        Ok(ChosenRound {
            round: r + 1,
            model: path,
            model_train_samples: model.info.train_samples,
            model_val_error: model.info.val_mean_error,
            candidates: [candidates.start, candidates.end],
            ranked: scored.len(),
            median_score: sorted[sorted.len() / 2],
            indices,
            scores,
        })
    }

    /// The score under `model` of each candidate of `candidates` whose loads can be drawn.
    fn score_candidates(&self, model: &ReducedModel, candidates: Range<u64>) -> Result<Vec<(u64, f64)>> {
        let scored: Vec<Option<(u64, f64)>> = candidates
            .into_par_iter()
            .map(|i| match self.draw_input(i) {
                Ok(input) => score(model, &input).map(|s| Some((i, s))),
                Err(_) => Ok(None),
            })
            .collect::<Result<_>>()?;
        Ok(scored.into_iter().flatten().collect())
    }

    /// Solves the draws `indices` of a round that are not committed yet, in blocks of [`BLOCK`]
    /// consecutive draws of the round solved in order as uniform blocks are (a resumed round solves
    /// its block's earlier draws again first), and commits them; reports `done` plus the round's
    /// draws so far, of `total`.
    fn solve_round(
        &self,
        writer: &mut DatasetWriter,
        indices: &[u64],
        progress: &dyn Progress,
        done: u64,
        total: u64,
    ) -> Result<()> {
        let block = BLOCK as usize;
        let mut position = indices.partition_point(|&i| i < writer.resume_from());
        let threads = rayon::current_num_threads();
        let batch = writer.manifest().shard_size.div_ceil(block).div_ceil(threads) * threads;
        progress.advance(done + position as u64, total, "");
        while position < indices.len() {
            let first = position / block;
            let end = ((first + batch) * block).min(indices.len());
            let results: Vec<_> = (first..end.div_ceil(block))
                .into_par_iter()
                .map(|b| {
                    let from = b * block;
                    self.solve_in_order(&indices[from..((b + 1) * block).min(end)], position.saturating_sub(from))
                })
                .collect();
            for (i, result) in results.into_iter().flatten() {
                match result {
                    Ok(sample) => writer.push(&sample)?,
                    Err(reason) => writer.push_failure(i, reason)?,
                }
            }
            position = end;
            progress.advance(done + position as u64, total, "");
        }
        writer.commit()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_highest_scores_are_chosen_in_index_order() {
        let scored = [(10, 0.5), (11, 2.0), (12, 0.1), (13, 2.0), (14, 1.5), (15, f64::MIN_POSITIVE)];
        assert_eq!(rank(&scored, 3), vec![(11, 2.0), (13, 2.0), (14, 1.5)]);
        // Equal scores: the lower index first.
        assert_eq!(rank(&scored, 1), vec![(11, 2.0)]);
        assert_eq!(rank(&scored, 6).len(), 6);
        assert!(rank(&scored, 0).is_empty());
    }
}
