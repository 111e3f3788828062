//! The record of a dataset's σ-chosen draws, as its manifest keeps it: how they are chosen
//! ([`ChoiceRecipe`]) and each round's choice ([`ChosenRound`]). The choosing itself, where a
//! reduced-order model is least sure, is [`crate::choosing`].

use std::path::PathBuf;

use mesh::length::mm;
use serde::{Deserialize, Serialize};

use crate::LearnError;

/// Generation index of candidate 0: candidate `c` is the dataset's draw `CANDIDATE_BASE + c`.
pub const CANDIDATE_BASE: u64 = 1 << 40;

/// Whether generation index `index` is a uniform draw (below [`CANDIDATE_BASE`]).
pub fn is_uniform(index: u64) -> bool {
    index < CANDIDATE_BASE
}

pub(crate) fn invalid(message: impl Into<String>) -> LearnError {
    LearnError::InvalidInput(message.into())
}

/// How a dataset's σ-chosen draws are chosen (`augsim generate --chosen-by`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ChoiceRecipe {
    /// The reduced-order model that ranks the first round's candidates: its directory (or its
    /// `model.json`), as given.
    pub model: PathBuf,
    /// FNV-1a hash of its `model.json`, in hexadecimal: a resumed run checks that it is the same.
    pub model_hash: String,
    /// Draws chosen, and solved, per round.
    pub per_round: usize,
    /// Candidates drawn and ranked per round.
    pub candidates: usize,
    /// Rounds.
    pub rounds: usize,
}

impl ChoiceRecipe {
    /// Whether `other` continues what `self` chose: the same model, draws and candidates per
    /// round (it may ask for more rounds).
    pub(crate) fn continued_by(&self, other: &ChoiceRecipe) -> bool {
        (&self.model_hash, self.per_round, self.candidates) == (&other.model_hash, other.per_round, other.candidates)
    }
}

/// A dataset's σ-chosen draws, as its manifest records them.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ChosenDraws {
    /// How they are chosen.
    pub recipe: ChoiceRecipe,
    /// The rounds so far.
    pub rounds: Vec<ChosenRound>,
}

/// One round of σ-chosen draws.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ChosenRound {
    /// Round number, from 1.
    pub round: usize,
    /// The model whose σ ranked the candidates: the recipe's in round 1; later, its refit on the
    /// draws before the round, kept in the dataset (`chosen/round_<round>`, relative to it).
    pub model: PathBuf,
    /// That model's training samples.
    pub model_train_samples: usize,
    /// Its mean error on its validation samples (m).
    pub model_val_error: f64,
    /// The candidates: generation indices `[start, end)`.
    pub candidates: [u64; 2],
    /// How many of them were ranked (a candidate whose loads cannot be drawn is left out).
    pub ranked: usize,
    /// The median score of the ranked candidates (m).
    pub median_score: f64,
    /// The chosen draws' generation indices, increasing (a draw whose solve failed is among the
    /// manifest's failed draws).
    pub indices: Vec<u64>,
    /// The score of each: its mean predicted σ over the organ's grid nodes (m).
    pub scores: Vec<f64>,
}

impl ChosenRound {
    /// The round in words.
    pub fn describe(&self) -> String {
        let (low, high) = self.scores.iter().fold((f64::INFINITY, 0f64), |(l, h), &s| (l.min(s), h.max(s)));
        format!(
            "round {}: {} of {} candidates chosen by {} ({} training samples, validation ē {:.3} mm): mean σ \
             {:.3}–{:.3} mm, the median candidate's {:.3} mm",
            self.round,
            self.indices.len(),
            self.ranked,
            self.model.display(),
            self.model_train_samples,
            mm(self.model_val_error),
            mm(low),
            mm(high),
            mm(self.median_score)
        )
    }
}

impl ChosenDraws {
    /// The round that chose draw `index`; `None` for a uniform draw.
    pub fn round_of(&self, index: u64) -> Option<&ChosenRound> {
        self.rounds.iter().find(|r| r.indices.binary_search(&index).is_ok())
    }

    /// Checks the record: rounds numbered from 1, each choosing increasing indices among its own
    /// candidates, after the previous round's, with a score each.
    pub(crate) fn validate(&self) -> std::result::Result<(), String> {
        let mut last = CANDIDATE_BASE;
        for (k, r) in self.rounds.iter().enumerate() {
            let bad = |what: &str| Err(format!("σ-chosen round {}: {what}", r.round));
            if r.round != k + 1 {
                return bad(&format!("numbered {} at position {}", r.round, k + 1));
            }
            if r.scores.len() != r.indices.len() {
                return bad(&format!("{} scores for {} draws", r.scores.len(), r.indices.len()));
            }
            if r.candidates[0] < last || r.candidates[1] < r.candidates[0] {
                return bad(&format!("candidates {:?} overlap an earlier round's", r.candidates));
            }
            let mut previous = None;
            for &i in &r.indices {
                if !(r.candidates[0]..r.candidates[1]).contains(&i) || previous.is_some_and(|p| i <= p) {
                    return bad(&format!("draw {i} is out of order or not among its candidates"));
                }
                previous = Some(i);
            }
            last = r.candidates[1];
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn candidates_lie_beyond_every_uniform_draw() {
        assert!(is_uniform(0) && is_uniform(CANDIDATE_BASE - 1) && !is_uniform(CANDIDATE_BASE));
    }

    #[test]
    fn a_record_out_of_order_is_refused() {
        let recipe =
            ChoiceRecipe { model: "m".into(), model_hash: "0".into(), per_round: 2, candidates: 10, rounds: 2 };
        let round = |round: usize, first: u64, indices: Vec<u64>| ChosenRound {
            round,
            model: "m".into(),
            model_train_samples: 5,
            model_val_error: 0.0,
            candidates: [first, first + 10],
            ranked: 10,
            median_score: 0.0,
            scores: vec![1.0; indices.len()],
            indices,
        };
        let b = CANDIDATE_BASE;
        let good = ChosenDraws {
            recipe: recipe.clone(),
            rounds: vec![round(1, b, vec![b + 2, b + 7]), round(2, b + 10, vec![b + 11, b + 19])],
        };
        assert!(good.validate().is_ok());
        assert_eq!(good.round_of(b + 11).map(|r| r.round), Some(2));
        assert!(good.round_of(3).is_none());
        for rounds in [
            vec![round(2, b, vec![b + 2])],
            vec![round(1, b, vec![b + 7, b + 2])],
            vec![round(1, b, vec![b + 12])],
            vec![round(1, b, vec![b + 2]), round(2, b + 5, vec![b + 11])],
        ] {
            assert!(ChosenDraws { recipe: recipe.clone(), rounds }.validate().is_err());
        }
    }
}
