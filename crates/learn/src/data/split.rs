//! Train / validation / test splits of a dataset's samples, recorded in the model, and the
//! guard that keeps evaluation off the samples a model was trained or selected on.
//!
//! A split is fixed by generation indices, not by positions, so it survives re-sharding and
//! merging; together with the dataset's [source](crate::Manifest::source_id) it names exactly
//! the samples that shaped a model (its training samples set the weights and the
//! normalisation, its validation samples chose the checkpoint). Validation and test samples are
//! uniform draws only: a σ-chosen draw ([`crate::choosing`]) is not a draw of the loads to
//! come, and always trains.

use serde::{Deserialize, Serialize};

use crate::data::chosen::is_uniform;
use crate::data::dataset::Samples;
use crate::{LearnError, Result};

/// A set of generation indices, stored as sorted, disjoint, non-adjacent half-open ranges
/// `[start, end)` (a JSON list of pairs).
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize)]
#[serde(transparent)]
pub struct IndexSet(Vec<[u64; 2]>);

impl<'de> Deserialize<'de> for IndexSet {
    /// The ranges as stored, refused unless each is non-empty and they are sorted and disjoint
    /// (a damaged model file would otherwise answer [`IndexSet::contains`] wrongly).
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> std::result::Result<Self, D::Error> {
        let ranges = Vec::<[u64; 2]>::deserialize(deserializer)?;
        if let Some([start, end]) = ranges.iter().find(|r| r[0] >= r[1]) {
            return Err(serde::de::Error::custom(format!("index range [{start}, {end}) is empty or reversed")));
        }
        if let Some(pair) = ranges.windows(2).find(|pair| pair[1][0] < pair[0][1]) {
            return Err(serde::de::Error::custom(format!(
                "index ranges {:?} and {:?} overlap or are out of order",
                pair[0], pair[1]
            )));
        }
        Ok(IndexSet(ranges))
    }
}

impl IndexSet {
    /// The set of `indices` (any order, repeats allowed).
    pub fn from_indices(indices: &[u64]) -> Self {
        let mut sorted = indices.to_vec();
        sorted.sort_unstable();
        let mut ranges: Vec<[u64; 2]> = Vec::new();
        for i in sorted {
            match ranges.last_mut() {
                Some(last) if i <= last[1] => last[1] = last[1].max(i + 1),
                _ => ranges.push([i, i + 1]),
            }
        }
        IndexSet(ranges)
    }

    /// Whether `index` is in the set.
    pub fn contains(&self, index: u64) -> bool {
        let at = self.0.partition_point(|r| r[1] <= index);
        self.0.get(at).is_some_and(|r| r[0] <= index)
    }

    /// Number of indices.
    pub fn len(&self) -> u64 {
        self.0.iter().map(|r| r[1] - r[0]).sum()
    }

    /// Whether the set is empty.
    pub fn is_empty(&self) -> bool {
        self.0.is_empty()
    }

    /// The first index of `indices` that is in the set.
    pub fn first_common(&self, indices: &[u64]) -> Option<u64> {
        indices.iter().copied().find(|&i| self.contains(i))
    }

    /// The first index of `other` in this set, if any (range by range, never index by index).
    pub fn first_common_with(&self, other: &IndexSet) -> Option<u64> {
        other.0.iter().find_map(|&[start, end]| {
            let at = self.0.partition_point(|r| r[1] <= start);
            self.0.get(at).filter(|r| r[0] < end).map(|r| r[0].max(start))
        })
    }
}

/// How many samples [`Split::last`] holds out, as `augsim train` takes them: each held-out set is a fraction of
/// the uniform samples (all of them, unless some draws were σ-chosen; rounded to the nearest count) unless a count
/// is given; the last uniform samples are the test set, the ones before them the validation set, the rest (and
/// every σ-chosen sample) the training set, of which only the first `train_samples` may be used (e.g. 100 for
/// transfer learning).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SplitPolicy {
    /// Fraction of the samples held out as the test set, in [0, 1).
    pub test_fraction: f64,
    /// Number of test samples; overrides `test_fraction`.
    pub test_samples: Option<usize>,
    /// Fraction of the samples used for validation (checkpoint selection), in [0, 1).
    pub validation_fraction: f64,
    /// Number of validation samples; overrides `validation_fraction`.
    pub validation_samples: Option<usize>,
    /// Train on the first this many training samples only (at least 1, at most the training set).
    pub train_samples: Option<usize>,
}

impl Default for SplitPolicy {
    /// 20 % test, 10 % validation, every training sample used.
    fn default() -> Self {
        SplitPolicy {
            test_fraction: 0.2,
            test_samples: None,
            validation_fraction: 0.1,
            validation_samples: None,
            train_samples: None,
        }
    }
}

impl SplitPolicy {
    /// The split of `samples` ([`Split::last`] with this policy's validation and test counts).
    pub fn split(&self, samples: &Samples) -> Result<Split> {
        let uniform = samples.indices.iter().filter(|&&i| is_uniform(i)).count();
        let count = |fraction: f64, given: Option<usize>, what: &str| -> Result<usize> {
            if !(0.0..1.0).contains(&fraction) {
                return Err(LearnError::InvalidInput(format!(
                    "the {what} fraction must lie in [0, 1), got {fraction}"
                )));
            }
            Ok(given.unwrap_or((uniform as f64 * fraction).round() as usize))
        };
        let test = count(self.test_fraction, self.test_samples, "test")?;
        let validation = count(self.validation_fraction, self.validation_samples, "validation")?;
        Split::last(samples, validation, test)
    }

    /// The split of `samples` and its training (the first `train_samples` when set), validation and test
    /// samples. The split records the whole training set even when only part of it is used, so that evaluation
    /// stays off all of it.
    pub fn apply(&self, samples: &Samples) -> Result<(Split, [Samples; 3])> {
        let split = self.split(samples)?;
        let [mut train, validation, test] = split.apply(samples)?;
        if let Some(n) = self.train_samples {
            if n == 0 || n > train.len() {
                return Err(LearnError::InvalidInput(format!(
                    "{n} training samples asked, the training split has {}",
                    train.len()
                )));
            }
            train = train.split_at(n)?.0;
        }
        Ok((split, [train, validation, test]))
    }
}

/// Which samples of one data source trained, selected and test a model.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Split {
    /// The data source ([`Manifest::source_id`](crate::Manifest::source_id)); `None` for
    /// samples of no known dataset.
    pub source: Option<String>,
    /// Samples the weights and the normalisation were fitted on.
    pub train: IndexSet,
    /// Samples the best checkpoint (and any hyper-parameter) was chosen on.
    pub validation: IndexSet,
    /// Samples held out for the reported figures.
    pub test: IndexSet,
}

/// The parts of a data source ([`crate::Manifest::source_id`]: `<scenario>/seed <seed>/<settings>`),
/// last first: settings, seed, scenario (those present).
fn source_parts(source: &str) -> Vec<&str> {
    source.rsplitn(3, '/').collect()
}

/// Whether two data sources (`<scenario>/seed <seed>/<settings>`) are the same draws: their seed and settings
/// agree, whatever the scenario is called (a scenario renamed, or copied under another name, draws
/// the same samples).
pub fn same_source(a: Option<&str>, b: Option<&str>) -> bool {
    match (a, b) {
        (Some(a), Some(b)) => source_parts(a).iter().take(2).eq(source_parts(b).iter().take(2)),
        _ => false,
    }
}

/// Whether the sources `a` and `b` were drawn with one seed but other settings, whatever their
/// scenarios are called (as [`same_source`] ignores the name): their draws of one index may be
/// near copies (a load range changed in its last digit).
pub fn same_seed_other_settings(a: Option<&str>, b: Option<&str>) -> bool {
    match (a.map(source_parts), b.map(source_parts)) {
        (Some(a), Some(b)) => a.len() >= 2 && b.len() >= 2 && a[1] == b[1] && a[0] != b[0],
        _ => false,
    }
}

impl Split {
    /// The dataset scenario the samples were generated from: the first part of the source
    /// (`<scenario>/seed <seed>/<settings>`), when known.
    pub fn scenario(&self) -> Option<&str> {
        self.source.as_deref().and_then(|s| source_parts(s).get(2).copied())
    }

    /// Splits `samples` in index order: the last `test` uniform samples for testing, the
    /// `validation` uniform samples before them for validation, the rest for training (uniform
    /// samples are drawn independently, so their order carries no information), σ-chosen samples
    /// included: they were chosen for the model's doubts, and would not measure it fairly.
    pub fn last(samples: &Samples, validation: usize, test: usize) -> Result<Split> {
        Split::of_indices(samples.source.clone(), &samples.indices, validation, test)
    }

    /// [`Split::last`] of samples of `source` with the generation indices `indices`.
    pub fn of_indices(source: Option<String>, indices: &[u64], validation: usize, test: usize) -> Result<Split> {
        let n = indices.len();
        if validation + test >= n {
            return Err(LearnError::InvalidInput(format!(
                "{validation} validation and {test} test samples leave no training sample out of {n}"
            )));
        }
        let mut indices = indices.to_vec();
        indices.sort_unstable();
        // Uniform draws come first in index order.
        let uniform = indices.partition_point(|&i| is_uniform(i));
        if validation + test > uniform {
            return Err(LearnError::InvalidInput(format!(
                "{validation} validation and {test} test samples asked, but only {uniform} of the {n} samples are \
                 uniform draws (σ-chosen draws are never held out)"
            )));
        }
        let (head, chosen) = indices.split_at(uniform);
        let (train, rest) = head.split_at(uniform - validation - test);
        let (val, test) = rest.split_at(validation);
        Ok(Split {
            source,
            train: IndexSet::from_indices(&[train, chosen].concat()),
            validation: IndexSet::from_indices(val),
            test: IndexSet::from_indices(test),
        })
    }

    /// The training, validation and test samples of `samples` (which must come from the
    /// split's source), each in the order of `samples`.
    pub fn apply(&self, samples: &Samples) -> Result<[Samples; 3]> {
        if !same_source(samples.source.as_deref(), self.source.as_deref()) {
            return Err(LearnError::InvalidInput(format!(
                "the split is of source {:?}, the samples of {:?}",
                self.source, samples.source
            )));
        }
        let part = |set: &IndexSet| {
            let positions: Vec<usize> = (0..samples.len()).filter(|&p| set.contains(samples.indices[p])).collect();
            samples.select(&positions)
        };
        Ok([part(&self.train)?, part(&self.validation)?, part(&self.test)?])
    }

    /// The first sample of `samples` that this split trained or validated on, with what it was
    /// used for ("train", "select (validate)"); `None` when there is none.
    pub fn first_seen(&self, samples: &Samples) -> Option<(u64, &'static str)> {
        if !same_source(samples.source.as_deref(), self.source.as_deref()) {
            return None;
        }
        [(&self.train, "train"), (&self.validation, "select (validate)")]
            .into_iter()
            .find_map(|(set, role)| set.first_common(&samples.indices).map(|i| (i, role)))
    }

    /// Fails when `samples` share an index with the training or validation samples of this
    /// split's source: figures on them would not be held out.
    pub fn check_unseen(&self, samples: &Samples) -> Result<()> {
        match self.first_seen(samples) {
            Some((i, role)) => Err(LearnError::InvalidInput(format!(
                "sample {i} of {} was used to {role} this model; evaluate it on its test samples or on another \
                 dataset",
                samples.source.as_deref().unwrap_or_default()
            ))),
            None => Ok(()),
        }
    }
}

/// What a sample was to a model.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SampleRole {
    /// Trained on (by this model or one it was fine-tuned from).
    Training,
    /// Used to choose the checkpoint.
    Validation,
    /// In the test split recorded in the model.
    Test,
    /// In no split of the model: data it never saw.
    Unseen,
}

impl std::fmt::Display for SampleRole {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            SampleRole::Training => "training",
            SampleRole::Validation => "validation",
            SampleRole::Test => "test",
            SampleRole::Unseen => "unseen",
        })
    }
}

/// Which samples shaped a model: the split of its own run and those of the runs it was
/// fine-tuned from (most recent first).
#[derive(Clone, Copy, Debug)]
pub struct Provenance<'a> {
    /// The model's own run.
    pub own: &'a Split,
    /// The runs it was fine-tuned from.
    pub earlier: &'a [Split],
}

impl<'a> Provenance<'a> {
    /// Every split that shaped the model.
    pub fn splits(self) -> impl Iterator<Item = &'a Split> {
        std::iter::once(self.own).chain(self.earlier)
    }

    /// Fails when `samples` include samples any of these runs trained or validated on.
    pub fn check_unseen(self, samples: &Samples) -> Result<()> {
        self.splits().try_for_each(|split| split.check_unseen(samples))
    }

    /// Whether `samples` come from the data the model's own run was trained on.
    pub fn trained_on(self, samples: &Samples) -> bool {
        same_source(samples.source.as_deref(), self.own.source.as_deref())
    }

    /// What sample `index` of the data source `source` was to the model.
    pub fn role(self, source: Option<&str>, index: u64) -> SampleRole {
        let ours = |s: &Split| same_source(s.source.as_deref(), source);
        for split in self.splits().filter(|s| ours(s)) {
            if split.train.contains(index) {
                return SampleRole::Training;
            }
            if split.validation.contains(index) {
                return SampleRole::Validation;
            }
        }
        if ours(self.own) && self.own.test.contains(index) {
            return SampleRole::Test;
        }
        SampleRole::Unseen
    }

    /// The samples held out from the model: from the data it was trained on, its recorded test
    /// samples; from other data, every sample that no run behind it trained or validated on.
    pub fn held_out(self, samples: &Samples) -> Result<Samples> {
        if self.trained_on(samples) {
            let [_, _, test] = self.own.apply(samples)?;
            return Ok(test);
        }
        let seen =
            |i: u64| matches!(self.role(samples.source.as_deref(), i), SampleRole::Training | SampleRole::Validation);
        let positions: Vec<usize> = (0..samples.len()).filter(|&p| !seen(samples.indices[p])).collect();
        samples.select(&positions)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A stored set reads back as written; ranges empty, reversed, overlapping or out of order
    /// (a damaged model file) are refused; the first index two sets share is found range by
    /// range, as index by index would find it.
    #[test]
    fn index_sets_are_checked_as_read_and_compared_by_ranges() {
        let set = IndexSet::from_indices(&[3, 4, 5, 9, 20, 21]);
        let text = serde_json::to_string(&set).unwrap();
        assert_eq!(text, "[[3,6],[9,10],[20,22]]");
        assert_eq!(serde_json::from_str::<IndexSet>(&text).unwrap(), set);
        for bad in ["[[5,5]]", "[[6,3]]", "[[0,4],[3,8]]", "[[9,10],[3,6]]"] {
            assert!(serde_json::from_str::<IndexSet>(bad).is_err(), "{bad}");
        }
        let others = [vec![0, 1, 2, 10, 11], vec![7, 8, 21, 30], vec![6, 7, 8], vec![1, 4], vec![]];
        for other in others {
            let brute = set.first_common(&other);
            assert_eq!(set.first_common_with(&IndexSet::from_indices(&other)), brute, "{other:?}");
        }
        assert_eq!(set.first_common_with(&IndexSet::from_indices(&[1, 4])), Some(4));
    }

    /// A scenario renamed draws the same samples: the model's training samples stay training
    /// samples under the new name; another seed is other data.
    #[test]
    fn a_renamed_scenario_is_the_same_source() {
        let split = Split::of_indices(Some("liver_ar/seed 1/00ab".into()), &(0..10).collect::<Vec<_>>(), 2, 2).unwrap();
        let provenance = Provenance { own: &split, earlier: &[] };
        assert_eq!(provenance.role(Some("my_liver/seed 1/00ab"), 0), SampleRole::Training);
        assert_eq!(provenance.role(Some("my_liver/seed 1/00ab"), 9), SampleRole::Test);
        assert_eq!(provenance.role(Some("liver_ar/seed 2/00ab"), 0), SampleRole::Unseen);
        assert_eq!(provenance.role(Some("liver_ar/seed 1/00ac"), 0), SampleRole::Unseen);
        assert!(!same_source(None, None) && !same_source(Some("a/seed 1/0"), None));
    }

    /// Settings changed under the same seed are another source, but told apart from another seed,
    /// whatever the scenario is called.
    #[test]
    fn the_same_seed_with_other_settings_is_told() {
        let told = same_seed_other_settings;
        assert!(told(Some("liver_ar/seed 2/00ab"), Some("liver_ar/seed 2/00ac")));
        assert!(told(Some("liver_ar/seed 2/00ab"), Some("my_liver/seed 2/00ac")), "renamed");
        assert!(!told(Some("liver_ar/seed 2/00ab"), Some("liver_ar/seed 2/00ab")), "the same source");
        assert!(!told(Some("liver_ar/seed 2/00ab"), Some("my_liver/seed 2/00ab")), "the same source, renamed");
        assert!(!told(Some("liver_ar/seed 2/00ab"), Some("liver_ar/seed 3/00ac")));
        assert!(!told(Some("liver_ar/seed 2/00ab"), None));
    }
}
