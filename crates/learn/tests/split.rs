//! Train / validation / test splits: disjoint, recorded in the model, normalisation from the
//! training samples only, and evaluation refused on samples a model was trained or selected on.

mod common;

use augsim_learn::training::train::MODEL_FILE;
use augsim_learn::LearnedModel;
use augsim_learn::{
    evaluate, train, Compute, Corruption, GridShape, IndexSet, Initialization, Normalization, Samples, Silent, Split,
    SplitPolicy, TrainConfig, TrainOptions, TrainedModel, UNetConfig, CANDIDATE_BASE,
};
use common::synthetic_sample;

fn grid() -> GridShape {
    GridShape::new(6, 5, 4)
}

/// Samples with the given generation indices, from `source`.
fn samples(indices: &[u64], source: &str) -> Samples {
    let mut s = Samples::new(grid());
    for &i in indices {
        s.push(&synthetic_sample(grid(), i)).unwrap();
    }
    s.source = Some(source.into());
    s
}

#[test]
fn splits_are_disjoint_cover_the_samples_and_store_compactly() {
    // Gaps where generation failed.
    let all = samples(&[0, 1, 2, 4, 5, 7, 8, 9, 12, 13], "liver");
    let split = Split::last(&all, 2, 3).unwrap();
    assert_eq!(split.source.as_deref(), Some("liver"));
    let [train, val, test] = split.apply(&all).unwrap();
    assert_eq!(train.indices, [0, 1, 2, 4, 5]);
    assert_eq!(val.indices, [7, 8]);
    assert_eq!(test.indices, [9, 12, 13]);
    for i in 0..20 {
        let roles = [&split.train, &split.validation, &split.test].iter().filter(|s| s.contains(i)).count();
        assert_eq!(roles, usize::from(all.indices.contains(&i)), "index {i}");
    }
    assert_eq!((split.train.len(), split.validation.len(), split.test.len()), (5, 2, 3));
    let json = serde_json::to_string(&split).unwrap();
    assert!(json.contains(r#""train":[[0,3],[4,6]]"#), "{json}");
    assert_eq!(serde_json::from_str::<Split>(&json).unwrap(), split);
    assert_eq!(IndexSet::from_indices(&[5, 3, 4, 4, 9]), serde_json::from_str("[[3,6],[9,10]]").unwrap());

    // Nothing left for training, or samples of another source, are errors.
    assert!(Split::last(&all, 4, 6).is_err());
    assert!(split.apply(&samples(&[0, 1], "beam")).is_err());
}

#[test]
fn sigma_chosen_draws_always_train() {
    // Ten uniform draws, then draws chosen among candidates (from CANDIDATE_BASE on).
    let b = CANDIDATE_BASE;
    let mut indices: Vec<u64> = (0..10).collect();
    indices.extend([b + 3, b + 9, b + 40]);
    let all = samples(&indices, "liver");
    let split = Split::last(&all, 2, 3).unwrap();
    let [train, val, test] = split.apply(&all).unwrap();
    assert_eq!((val.indices, test.indices), (vec![5, 6], vec![7, 8, 9]));
    assert_eq!(train.indices, [0, 1, 2, 3, 4, b + 3, b + 9, b + 40]);
    // Held-out fractions are of the uniform draws: as if the chosen ones were not there.
    let uniform = samples(&indices[..10], "liver");
    assert_eq!(SplitPolicy::default().split(&all).unwrap().test, SplitPolicy::default().split(&uniform).unwrap().test);
    // Only uniform draws can be held out.
    let e = Split::last(&all, 5, 6).unwrap_err().to_string();
    assert!(e.contains("only 10 of the 13 samples are uniform"), "{e}");
}

#[test]
fn the_split_policy_rounds_fractions_lets_counts_override_them_and_limits_training() {
    let all = samples(&(0..10).collect::<Vec<_>>(), "liver");
    // Defaults: 20 % test, 10 % validation.
    let (split, [train, val, test]) = SplitPolicy::default().apply(&all).unwrap();
    assert_eq!((train.indices.len(), val.indices, test.indices), (7, vec![7], vec![8, 9]));
    assert_eq!(split, Split::last(&all, 1, 2).unwrap());
    // Fractions round to the nearest count (0.25 × 10 = 2.5 → 3); counts override fractions.
    let policy = SplitPolicy { test_fraction: 0.25, validation_samples: Some(3), ..SplitPolicy::default() };
    assert_eq!(policy.split(&all).unwrap(), Split::last(&all, 3, 3).unwrap());
    let policy = SplitPolicy { test_samples: Some(0), validation_fraction: 0.0, ..SplitPolicy::default() };
    assert_eq!(policy.split(&all).unwrap().train.len(), 10);
    // Only the first training samples are used, but the split records all of them.
    let (split, [train, ..]) = SplitPolicy { train_samples: Some(2), ..SplitPolicy::default() }.apply(&all).unwrap();
    assert_eq!(train.indices, [0, 1]);
    assert_eq!(split.train.len(), 7);
    for bad in [
        SplitPolicy { train_samples: Some(0), ..SplitPolicy::default() },
        SplitPolicy { train_samples: Some(8), ..SplitPolicy::default() },
        SplitPolicy { test_fraction: 1.0, ..SplitPolicy::default() },
        SplitPolicy { validation_fraction: -0.1, ..SplitPolicy::default() },
        SplitPolicy { test_samples: Some(5), validation_samples: Some(5), ..SplitPolicy::default() },
    ] {
        assert!(bad.apply(&all).is_err(), "{bad:?}");
    }
    let e = SplitPolicy { test_fraction: 1.5, ..SplitPolicy::default() }.split(&all).unwrap_err().to_string();
    assert!(e.contains("test fraction") && e.contains("1.5"), "{e}");
}

#[test]
fn normalisation_comes_from_the_training_samples_only() {
    let mut all = samples(&(0..8).collect::<Vec<_>>(), "liver");
    // Make the held-out samples ten times larger: they must not move the scales.
    let f = grid().field_len();
    for v in &mut all.targets[6 * f..] {
        *v *= 10.0;
    }
    let [train, ..] = Split::last(&all, 1, 1).unwrap().apply(&all).unwrap();
    let norm = Normalization::from_samples(&train);
    let n = grid().nodes();
    let (mut sq, mut count) = (0.0, 0u64);
    for p in 0..train.len() {
        for node in 0..n {
            if train.mask(p)[node] != 0 {
                count += 1;
                sq += (0..3).map(|c| f64::from(train.target(p)[c * n + node]).powi(2)).sum::<f64>();
            }
        }
    }
    let expected = (sq / count as f64).sqrt();
    assert!((norm.target_scale - expected).abs() < 1e-12 * expected, "{} vs {expected}", norm.target_scale);
    assert!(Normalization::from_samples(&all).target_scale > 2.0 * norm.target_scale);
}

#[test]
fn models_record_their_split_and_evaluation_refuses_seen_samples() {
    let root = tempfile::tempdir().unwrap();
    let all = samples(&(0..10).collect::<Vec<_>>(), "liver");
    let split = Split::last(&all, 2, 3).unwrap();
    let [train_set, val, test] = split.apply(&all).unwrap();
    let init = Initialization::Scratch {
        unet: UNetConfig { base_channels: 2, depth: 1, ..UNetConfig::default() },
        normalization: Normalization::from_samples(&train_set),
        input_unit: augsim_learn::FieldUnit::Newton,
    };
    let config = TrainConfig { iterations: 2, validate_every: 1, checkpoint_every: 2, ..TrainConfig::default() };
    let options = |name: &str| TrainOptions { test: split.test.clone(), ..TrainOptions::new(root.path().join(name)) };
    train(&train_set, &val, &init, &config, &options("a"), &Silent).unwrap();
    let model = TrainedModel::load(&root.path().join("a").join(MODEL_FILE)).unwrap();
    assert_eq!(model.training.as_ref().unwrap().split, split);
    assert_eq!(model.held_out(&all).unwrap(), test);

    let none = Corruption::none();
    assert!(evaluate(&model, &test, &none, 0, Compute::Cpu).is_ok());
    let e = evaluate(&model, &train_set, &none, 0, Compute::Cpu).unwrap_err().to_string();
    assert!(e.contains("sample 0 of liver was used to train this model"), "{e}");
    let e = evaluate(&model, &val, &none, 0, Compute::Cpu).unwrap_err().to_string();
    assert!(e.contains("sample 5 of liver was used to select"), "{e}");
    // The same indices of another dataset are unseen.
    let other = samples(&(0..10).collect::<Vec<_>>(), "beam");
    assert!(evaluate(&model, &other, &none, 0, Compute::Cpu).is_ok());
    assert_eq!(model.held_out(&other).unwrap(), other);

    // Overlapping roles are refused before training.
    let e = train(&train_set, &train_set, &init, &config, &options("b"), &Silent).unwrap_err().to_string();
    assert!(e.contains("both a training and a validation sample"), "{e}");
    let overlapping = TrainOptions { test: IndexSet::from_indices(&[4, 8]), ..options("c") };
    let e = train(&train_set, &val, &init, &config, &overlapping, &Silent).unwrap_err().to_string();
    assert!(e.contains("sample 4 is both a training and a test sample"), "{e}");
    let e = train(&train_set, &other.select(&[8]).unwrap(), &init, &config, &options("d"), &Silent)
        .unwrap_err()
        .to_string();
    assert!(e.contains("different data"), "{e}");

    // Fine-tuned on another dataset, the model still remembers what it was pre-trained on.
    let beam = Split::last(&other, 2, 2).unwrap();
    let [beam_train, beam_val, beam_test] = beam.apply(&other).unwrap();
    let fine = Initialization::FineTune { model: root.path().join("a").join(MODEL_FILE), freeze_encoder: false };
    let tuned = train(
        &beam_train,
        &beam_val,
        &fine,
        &config,
        &TrainOptions { test: beam.test.clone(), ..options("e") },
        &Silent,
    )
    .unwrap()
    .model;
    let info = tuned.training.as_ref().unwrap();
    assert_eq!((&info.split, &info.pretraining[..]), (&beam, &[split.clone()][..]));
    assert_eq!(tuned.held_out(&other).unwrap(), beam_test);
    assert_eq!(tuned.held_out(&all).unwrap(), test, "the pre-training's unseen samples");
    assert!(evaluate(&tuned, &train_set, &none, 0, Compute::Cpu).is_err());

    // Fine-tuned on the pre-training's own data with its split, it trains; a run that would test
    // or validate on samples the pre-trained network learned is refused before it trains.
    assert!(train(&train_set, &val, &fine, &config, &options("f"), &Silent).is_ok());
    let wider = Split::last(&all, 2, 6).unwrap();
    let [wider_train, wider_val, _] = wider.apply(&all).unwrap();
    let wider_options = TrainOptions { test: wider.test.clone(), ..options("g") };
    let e = train(&wider_train, &wider_val, &fine, &config, &wider_options, &Silent).unwrap_err().to_string();
    assert!(e.contains("sample 4, a test sample of this run, is one the pre-trained network trained on"), "{e}");
    let shifted = Split::last(&all, 7, 0).unwrap();
    let [shifted_train, shifted_val, _] = shifted.apply(&all).unwrap();
    let shifted_options = TrainOptions { test: shifted.test.clone(), ..options("h") };
    let e = train(&shifted_train, &shifted_val, &fine, &config, &shifted_options, &Silent).unwrap_err().to_string();
    assert!(e.contains("a validation sample of this run, is one the pre-trained network trained on"), "{e}");
}
