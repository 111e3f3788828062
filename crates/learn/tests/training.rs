//! Training on tiny models: overfitting, bit-identical resume, transfer learning with a frozen
//! encoder, evaluation and outputs.

mod common;

use augsim_learn::training::metrics::{masked_mse_values, mean_euclidean_error};
use augsim_learn::training::train::{CHECKPOINT_FILE, CURVE_CSV, MODEL_FILE};
use augsim_learn::{
    evaluate, evaluate_at_points, evaluation_input, time_prediction, train, Compute, Corruption, GridShape,
    Initialization, Normalization, Predictor, Samples, Silent, Sparsity, TrainConfig, TrainOptions, TrainedModel, UNet,
    UNetConfig,
};
use common::{synthetic_samples, Lines};
use mesh::embedding::Grid;

fn grid() -> GridShape {
    GridShape::new(8, 8, 8)
}

fn scratch(base: usize, depth: usize, data: &Samples) -> Initialization {
    // Normalisation from the data, as the manifest statistics would give it.
    let rms = |v: &[f32]| {
        let s: f64 = v.iter().map(|x| f64::from(*x).powi(2)).sum();
        (s / data.len() as f64 / data.grid.nodes() as f64).sqrt()
    };
    Initialization::Scratch {
        unet: UNetConfig { base_channels: base, depth, ..UNetConfig::default() },
        normalization: Normalization { input_scale: rms(&data.inputs) * 8.0, target_scale: rms(&data.targets) * 4.0 },
        input_unit: augsim_learn::FieldUnit::Newton,
    }
}

/// Masked MSE (physical units) of a model over a sample set.
fn mse(model: &TrainedModel, s: &Samples) -> f64 {
    let predictor = Predictor::new(model, Compute::Cpu).unwrap();
    let pred: Vec<f32> = (0..s.len()).flat_map(|p| predictor.predict(s.input(p)).unwrap()).collect();
    masked_mse_values(&pred, &s.targets, &s.masks, s.grid).unwrap()
}

#[test]
fn tiny_unet_overfits_a_handful_of_samples() {
    let dir = tempfile::tempdir().unwrap();
    let data = synthetic_samples(grid(), 0, 4);
    let init = scratch(4, 2, &data);
    let config = TrainConfig {
        iterations: 600,
        batch_size: 4,
        learning_rate: 3e-3,
        validate_every: 200,
        checkpoint_every: 600,
        ..TrainConfig::default()
    };
    let val = synthetic_samples(grid(), 10, 2);
    let last = std::sync::Mutex::new((0, 0, String::new()));
    let record = |done: u64, total: u64, note: &str| *last.lock().unwrap() = (done, total, note.to_string());
    let out = train(&data, &val, &init, &config, &TrainOptions::new(dir.path()), &record).unwrap();
    assert!(out.completed);
    assert_eq!(out.iterations_done, 600);
    let (done, total, note) = last.into_inner().unwrap();
    assert_eq!((done, total), (600, 600));
    assert!(note.starts_with("loss ") && note.contains(" val "), "{note}");

    // The same network before training (same seed, same normalisation).
    let Initialization::Scratch { unet, normalization, .. } = &init else { unreachable!() };
    let initial = TrainedModel {
        config: unet.clone(),
        normalization: *normalization,
        grid: grid(),
        placement: None,
        input_unit: augsim_learn::FieldUnit::Newton,
        target_unit: augsim_learn::FieldUnit::Metre,
        training: None,
        net: UNet::new(unet, config.seed).unwrap(),
    };
    let (before, after) = (mse(&initial, &data), mse(&out.model, &data));
    assert!(after * 100.0 <= before, "masked MSE only fell from {before:e} to {after:e}");

    // The kept model is the best validated one, and the files are there.
    let info = out.model.training.clone().unwrap();
    let best = out.curve.iter().filter_map(|r| r.val.map(|v| v.mean)).fold(f64::INFINITY, f64::min);
    assert_eq!(info.best_val_mean_error, Some(best));
    let saved = TrainedModel::load(&dir.path().join(MODEL_FILE)).unwrap();
    assert_eq!(saved.predict(data.input(0)).unwrap(), out.model.predict(data.input(0)).unwrap());
    let csv = std::fs::read_to_string(dir.path().join(CURVE_CSV)).unwrap();
    assert_eq!(csv.lines().count(), 4, "{csv}");
    assert!(csv.starts_with("iteration,train_loss,val_mean_error_m,val_std_error_m,val_max_error_m\n200,"));

    // evaluate() agrees with per-sample predictions, and reports the worst sample.
    let report = evaluate(&out.model, &data, &Corruption::none(), 0, Compute::Cpu).unwrap();
    for p in 0..data.len() {
        let pred = out.model.predict(data.input(p)).unwrap();
        let e = mean_euclidean_error(&pred, data.target(p), data.mask(p), grid()).unwrap();
        assert!((e - report.errors[p]).abs() <= 1e-6 * e.max(1e-9), "{e} vs {}", report.errors[p]);
    }
    // With corrupted inputs, the errors are those of the inputs `evaluation_input` gives.
    let noisy = Corruption { sparsity: None, noise_std: 0.3 };
    let noisy_report = evaluate(&out.model, &data, &noisy, 5, Compute::Cpu).unwrap();
    for p in 0..data.len() {
        let input = evaluation_input(&data, p, &noisy, 5).unwrap();
        assert_ne!(input, data.input(p));
        let e =
            mean_euclidean_error(&out.model.predict(&input).unwrap(), data.target(p), data.mask(p), grid()).unwrap();
        assert!((e - noisy_report.errors[p]).abs() <= 1e-6 * e.max(1e-9), "{e} vs {}", noisy_report.errors[p]);
    }
    let worst = report.errors.iter().cloned().fold(0.0, f64::max);
    assert_eq!(report.stats.max, worst);
    assert_eq!(report.errors[report.stats.worst], worst);
    assert_eq!(report.worst_index(), data.indices[report.stats.worst]);
    assert!(report.to_string().contains(&format!("sample index {}", report.worst_index())));

    // Errors at points: at a grid node they are the nodal errors; half-way between two nodes
    // the fields are averaged.
    let g = grid();
    let placed = Grid::new([0.1, -0.2, 0.3], [0.5, 0.25, 0.75], g.dims()).unwrap();
    let (a, b) = (placed.node(1, 2, 1), placed.node(2, 2, 1));
    let mid = [0.5 * (a[0] + b[0]), a[1], a[2]];
    let (same, at) =
        evaluate_at_points(&out.model, &data, &Corruption::none(), 0, &placed, &[a, mid], Compute::Cpu).unwrap();
    assert_eq!(same.errors, report.errors);
    let n = g.nodes();
    let value = |field: &[f32], node: usize| -> [f64; 3] { std::array::from_fn(|c| f64::from(field[c * n + node])) };
    let dist =
        |u: [f64; 3], v: [f64; 3]| ((u[0] - v[0]).powi(2) + (u[1] - v[1]).powi(2) + (u[2] - v[2]).powi(2)).sqrt();
    let (na, nb) = (g.node_index(1, 2, 1), g.node_index(2, 2, 1));
    let (mut at_a, mut at_mid, mut still) = (0.0, 0.0, 0.0f64);
    let mut worst = (0.0, 0, 0);
    for p in 0..data.len() {
        let (pred, target) = (out.model.predict(data.input(p)).unwrap(), data.target(p));
        let errors = [dist(value(&pred, na), value(target, na)), {
            let avg = |f: &[f32]| -> [f64; 3] { std::array::from_fn(|c| 0.5 * (value(f, na)[c] + value(f, nb)[c])) };
            still = still.max(dist(value(target, na), [0.0; 3])).max(dist(avg(target), [0.0; 3]));
            dist(avg(&pred), avg(target))
        }];
        at_a += errors[0] / data.len() as f64;
        at_mid += errors[1] / data.len() as f64;
        for (k, e) in errors.into_iter().enumerate() {
            if e > worst.0 {
                worst = (e, data.indices[p], k);
            }
        }
    }
    // The largest error named by its sample's generation index and its point.
    assert_eq!((at.worst_sample, at.worst_point), (worst.1, worst.2));
    assert!((at.per_point_mean[0] - at_a).abs() < 1e-6 * at_a.max(1e-12), "{:?} vs {at_a}", at.per_point_mean);
    assert!((at.per_point_mean[1] - at_mid).abs() < 1e-6 * at_mid.max(1e-12), "{:?} vs {at_mid}", at.per_point_mean);
    assert!((at.no_motion.max - still).abs() < 1e-6 * still);
    assert!(evaluate_at_points(&out.model, &data, &Corruption::none(), 0, &placed, &[[9.0, 9.0, 9.0]], Compute::Cpu)
        .is_err());

    let predictor = Predictor::new(&out.model, Compute::Cpu).unwrap();
    let timing = time_prediction(|x| predictor.predict(x), data.input(0), 1, 3).unwrap();
    assert!(timing.min <= timing.median && timing.median <= timing.max && timing.runs == 3);
}

#[test]
fn cosine_learning_rate_falls_from_first_to_final() {
    let config =
        TrainConfig { iterations: 101, learning_rate: 1e-3, final_learning_rate: Some(1e-5), ..Default::default() };
    config.validate().unwrap();
    assert!((config.learning_rate_at(0) - 1e-3).abs() < 1e-15);
    assert!((config.learning_rate_at(100) - 1e-5).abs() < 1e-15);
    assert!((config.learning_rate_at(50) - 0.5 * (1e-3 + 1e-5)).abs() < 1e-12, "half-way is the mean");
    assert!((0..100).all(|i| config.learning_rate_at(i + 1) < config.learning_rate_at(i)));
    let constant = TrainConfig { final_learning_rate: None, ..config.clone() };
    assert!((0..101).all(|i| constant.learning_rate_at(i) == 1e-3));
    let bad = TrainConfig { final_learning_rate: Some(2e-3), ..config };
    assert!(bad.validate().unwrap_err().to_string().contains("final_learning_rate"));
}

/// A batch larger than the training set is the training set: a batch of 1,000 on 3 samples
/// trains the very network a batch of 3 does (not 1,000 samples a step, most of them repeats).
#[test]
fn a_batch_is_at_most_the_training_set() {
    let root = tempfile::tempdir().unwrap();
    let train_set = synthetic_samples(grid(), 0, 3);
    let init = scratch(2, 1, &train_set);
    let config =
        TrainConfig { iterations: 3, batch_size: 3, validate_every: 3, checkpoint_every: 3, ..TrainConfig::default() };
    let run = |config: &TrainConfig, dir: &str| {
        train(&train_set, &Samples::new(grid()), &init, config, &TrainOptions::new(root.path().join(dir)), &Silent)
            .unwrap()
    };
    let whole = run(&config, "whole");
    // No validation sample: nothing chose the weights kept (the last iteration's).
    let info = whole.model.training.as_ref().unwrap();
    assert_eq!((info.best_iteration, info.best_val_mean_error), (None, None));
    let large = run(&TrainConfig { batch_size: 1000, ..config.clone() }, "large");
    assert_eq!(whole.model.net.named_parameters(), large.model.net.named_parameters());
    let two = run(&TrainConfig { batch_size: 2, ..config }, "two");
    assert_ne!(whole.model.net.named_parameters(), two.model.net.named_parameters());
}

/// Two trainings into one folder: the second is refused while the first runs (their checkpoints
/// would mix, and one's model would replace the other's); once the first has returned, its lock
/// is gone.
#[test]
fn a_second_training_into_the_same_folder_is_refused_while_the_first_runs() {
    let root = tempfile::tempdir().unwrap();
    let data = synthetic_samples(grid(), 0, 3);
    let init = scratch(2, 1, &data);
    let config =
        TrainConfig { iterations: 2, batch_size: 3, validate_every: 2, checkpoint_every: 2, ..TrainConfig::default() };
    let options = TrainOptions::new(root.path().join("net"));
    let no_val = Samples::new(grid());
    let (started, release) = (std::sync::Barrier::new(2), std::sync::Barrier::new(2));
    let second = std::thread::scope(|scope| {
        let first = scope.spawn(|| {
            // Held at its first report, the folder locked, until the second has tried.
            let held = |done: u64, _: u64, _: &str| {
                if done == 0 {
                    started.wait();
                    release.wait();
                }
            };
            train(&data, &no_val, &init, &config, &options, &held)
        });
        started.wait();
        let second = train(&data, &no_val, &init, &config, &options, &Silent).map(|_| ());
        release.wait();
        assert!(first.join().unwrap().unwrap().completed);
        second
    });
    let e = second.unwrap_err().to_string();
    assert!(
        e.contains("net is being written by another run (`augsim train`, `python -m augsim.train`): two trainings"),
        "{e}"
    );
    assert!(!root.path().join("net").join(augsim_learn::data::dataset::WRITER_LOCK).exists());
}

#[test]
fn resumed_training_equals_uninterrupted() {
    let root = tempfile::tempdir().unwrap();
    let train_set = synthetic_samples(grid(), 0, 6);
    let val = synthetic_samples(grid(), 100, 2);
    let init = scratch(2, 2, &train_set);
    let config = TrainConfig {
        iterations: 12,
        batch_size: 4,
        learning_rate: 1e-3,
        final_learning_rate: None,
        seed: 42,
        validate_every: 4,
        checkpoint_every: 4,
        train_corruption: Corruption {
            sparsity: Some(Sparsity::Subset { min_fraction: 0.5, max_fraction: 1.0 }),
            noise_std: 0.05,
        },
        val_corruption: Corruption { sparsity: None, noise_std: 0.02 },
    };
    let (a, b) = (root.path().join("a"), root.path().join("b"));
    let full = train(&train_set, &val, &init, &config, &TrainOptions::new(&a), &Silent).unwrap();

    // Interrupted after iteration 6 (checkpoint), then resumed.
    let stopped = train(
        &train_set,
        &val,
        &init,
        &config,
        &TrainOptions { stop_after: Some(6), ..TrainOptions::new(&b) },
        &Silent,
    )
    .unwrap();
    assert!(!stopped.completed);
    assert_eq!(stopped.iterations_done, 6);
    assert!(!b.join(MODEL_FILE).exists());
    assert!(b.join(CHECKPOINT_FILE).exists());
    let told = Lines::default();
    let resumed = train(&train_set, &val, &init, &config, &TrainOptions::new(&b), &told).unwrap();
    let said = told.0.lock().unwrap().clone();
    assert_eq!(said, [format!("resuming {} at step 6 of 12", b.join(CHECKPOINT_FILE).display())]);
    assert!(resumed.completed);
    assert_eq!(resumed.curve, full.curve);
    let (pa, pb) = (full.model.net.named_parameters(), resumed.model.net.named_parameters());
    let max_diff = pa
        .iter()
        .zip(&pb)
        .flat_map(|((_, x), (_, y))| x.iter().zip(y).map(|(u, v)| (u - v).abs()))
        .fold(0f32, f32::max);
    assert_eq!(max_diff, 0.0, "resumed weights differ from uninterrupted ones by up to {max_diff:e}");
    assert!(
        std::fs::read(a.join("model.safetensors")).unwrap() == std::fs::read(b.join("model.safetensors")).unwrap(),
        "model files differ"
    );
    assert_eq!(std::fs::read(a.join(CURVE_CSV)).unwrap(), std::fs::read(b.join(CURVE_CSV)).unwrap());

    // Extending the finished run to 16 iterations equals a run of 16 from the start.
    let longer = TrainConfig { iterations: 16, ..config.clone() };
    let extended = train(&train_set, &val, &init, &longer, &TrainOptions::new(&b), &Silent).unwrap();
    let full16 = train(&train_set, &val, &init, &longer, &TrainOptions::new(root.path().join("c")), &Silent).unwrap();
    assert_eq!(extended.curve, full16.curve);
    assert_eq!(extended.model.net.named_parameters(), full16.model.net.named_parameters());
    let shorter = TrainConfig { iterations: 8, ..config.clone() };
    let e = train(&train_set, &val, &init, &shorter, &TrainOptions::new(&b), &Silent).unwrap_err().to_string();
    assert!(e.contains("beyond"), "{e}");

    // With a cosine schedule the rate depends on the iteration count: extending is refused.
    let cosine = TrainConfig { final_learning_rate: Some(1e-4), ..config.clone() };
    let cosine_dir = root.path().join("d");
    train(&train_set, &val, &init, &cosine, &TrainOptions::new(&cosine_dir), &Silent).unwrap();
    let e = train(
        &train_set,
        &val,
        &init,
        &TrainConfig { iterations: 16, ..cosine },
        &TrainOptions::new(&cosine_dir),
        &Silent,
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("different setup"), "{e}");

    // A checkpoint from another setup is refused.
    let other = TrainConfig { learning_rate: 2e-3, ..config.clone() };
    let e = train(&train_set, &val, &init, &other, &TrainOptions::new(&b), &Silent).unwrap_err().to_string();
    assert!(e.contains("different setup (config.learning_rate 0.001 there, 0.002 now)"), "{e}");
    // A corrupt checkpoint gives a clear error.
    let ck = b.join(CHECKPOINT_FILE);
    let bytes = std::fs::read(&ck).unwrap();
    std::fs::write(&ck, &bytes[..bytes.len() / 2]).unwrap();
    let e = train(&train_set, &val, &init, &config, &TrainOptions::new(&b), &Silent).unwrap_err().to_string();
    assert!(e.contains("checkpoint.bin") && e.contains("truncated"), "{e}");
}

#[test]
fn fine_tuning_with_a_frozen_encoder_leaves_it_unchanged() {
    let root = tempfile::tempdir().unwrap();
    let pre_data = synthetic_samples(grid(), 0, 4);
    let new_data = synthetic_samples(grid(), 50, 4);
    let config = TrainConfig {
        iterations: 8,
        validate_every: 4,
        checkpoint_every: 8,
        learning_rate: 3e-3,
        ..TrainConfig::default()
    };
    let pre_dir = root.path().join("pre");
    let pre_val = synthetic_samples(grid(), 20, 2);
    train(&pre_data, &pre_val, &scratch(2, 2, &pre_data), &config, &TrainOptions::new(&pre_dir), &Silent).unwrap();
    let pre_path = pre_dir.join(MODEL_FILE);
    let pre = TrainedModel::load(&pre_path).unwrap();

    // Without validation samples the last weights are kept, whether or not they are better.
    let no_val = Samples::new(grid());
    let finetune = |freeze: bool, name: &str| {
        let init = Initialization::FineTune { model: pre_path.clone(), freeze_encoder: freeze };
        train(&new_data, &no_val, &init, &config, &TrainOptions::new(root.path().join(name)), &Silent).unwrap()
    };
    let frozen = finetune(true, "frozen");
    assert_eq!(frozen.model.normalization, pre.normalization);
    assert!(frozen.model.training.as_ref().unwrap().frozen_encoder);
    let before = pre.net.named_parameters();
    let after = frozen.model.net.named_parameters();
    let (mut encoder, mut decoder_changed) = (0, 0);
    for ((name, a), (name2, b)) in before.iter().zip(&after) {
        assert_eq!(name, name2);
        if UNet::is_encoder_parameter(name) {
            assert_eq!(a, b, "frozen parameter {name} changed");
            encoder += 1;
        } else if a != b {
            decoder_changed += 1;
        }
    }
    assert!(encoder > 0);
    assert!(decoder_changed > 0, "fine-tuning changed nothing");

    // Without freezing, the encoder moves too.
    let free = finetune(false, "free");
    let moved = pre
        .net
        .named_parameters()
        .iter()
        .zip(free.model.net.named_parameters())
        .any(|((name, a), (_, b))| UNet::is_encoder_parameter(name) && *a != b);
    assert!(moved);
}

#[test]
fn fine_tuning_keeps_the_pre_trained_network_when_no_step_beats_it() {
    let root = tempfile::tempdir().unwrap();
    let (data, val) = (synthetic_samples(grid(), 0, 4), synthetic_samples(grid(), 20, 2));
    let config = TrainConfig {
        iterations: 200,
        validate_every: 100,
        checkpoint_every: 200,
        learning_rate: 3e-3,
        ..TrainConfig::default()
    };
    let pre_dir = root.path().join("pre");
    train(&data, &val, &scratch(2, 2, &data), &config, &TrainOptions::new(&pre_dir), &Silent).unwrap();
    let pre = TrainedModel::load(&pre_dir.join(MODEL_FILE)).unwrap();

    // Steps far too long for the pre-trained network: every validation after them is worse.
    let harmful = TrainConfig { iterations: 4, validate_every: 2, checkpoint_every: 4, learning_rate: 0.5, ..config };
    let init = Initialization::FineTune { model: pre_dir.join(MODEL_FILE), freeze_encoder: false };
    let out = train(&data, &val, &init, &harmful, &TrainOptions::new(root.path().join("tuned")), &Silent).unwrap();
    let first = out.curve[0];
    assert_eq!((first.iteration, first.train_loss), (0, None), "{:?}", out.curve);
    let at_start = first.val.unwrap().mean;
    assert!(out.curve[1..].iter().all(|r| r.val.unwrap().mean > at_start), "{:?}", out.curve);
    let info = out.model.training.as_ref().unwrap();
    assert_eq!((info.best_iteration, info.best_val_mean_error), (Some(0), Some(at_start)));
    assert_eq!(out.model.net.named_parameters(), pre.net.named_parameters());
    let csv = std::fs::read_to_string(root.path().join("tuned").join(CURVE_CSV)).unwrap();
    assert!(csv.lines().nth(1).unwrap().starts_with("0,,"), "{csv}");
}

/// burn's own kernels and autodiff ([`Compute::CpuBurn`]: the code path a GPU runs) train and
/// predict as the repacked CPU engines do, up to rounding; a checkpoint written on one resumes on
/// the other.
#[cfg(feature = "cpu-burn")]
#[test]
fn burn_path_trains_and_predicts_as_the_cpu_engines_do() {
    let root = tempfile::tempdir().unwrap();
    let data = synthetic_samples(grid(), 0, 4);
    let val = synthetic_samples(grid(), 10, 2);
    let init = scratch(3, 2, &data);
    let config = TrainConfig {
        iterations: 8,
        batch_size: 2,
        learning_rate: 3e-3,
        validate_every: 4,
        checkpoint_every: 4,
        ..TrainConfig::default()
    };
    let on = |compute: Compute, name: &str| TrainOptions { compute, ..TrainOptions::new(root.path().join(name)) };
    let cpu = train(&data, &val, &init, &config, &on(Compute::Cpu, "cpu"), &Silent).unwrap();
    let burn = train(&data, &val, &init, &config, &on(Compute::CpuBurn, "burn"), &Silent).unwrap();
    assert_eq!(cpu.curve.len(), burn.curve.len());
    for (a, b) in cpu.curve.iter().zip(&burn.curve) {
        let (a_loss, b_loss) = (a.train_loss.unwrap(), b.train_loss.unwrap());
        let rel = (a_loss - b_loss).abs() / a_loss;
        assert!(rel < 1e-4, "iteration {}: train loss {} (cpu) against {} (burn)", a.iteration, a_loss, b_loss);
        let (va, vb) = (a.val.unwrap().mean, b.val.unwrap().mean);
        assert!((va - vb).abs() <= 1e-4 * va, "iteration {}: validation {va} against {vb}", a.iteration);
    }
    let largest =
        cpu.model.net.named_parameters().iter().flat_map(|(_, v)| v.clone()).fold(0f32, |m, v| m.max(v.abs()));
    let differ = cpu
        .model
        .net
        .named_parameters()
        .iter()
        .zip(&burn.model.net.named_parameters())
        .flat_map(|((_, x), (_, y))| x.iter().zip(y).map(|(u, v)| (u - v).abs()).collect::<Vec<_>>())
        .fold(0f32, f32::max);
    assert!(differ <= 1e-3 * largest, "weights differ by {differ:e} (largest weight {largest:e})");

    // One model, predicted by both engines.
    let repacked = Predictor::new(&cpu.model, Compute::Cpu).unwrap().predict(data.input(1)).unwrap();
    let by_burn = Predictor::new(&cpu.model, Compute::CpuBurn).unwrap().predict(data.input(1)).unwrap();
    let scale = repacked.iter().fold(0f32, |m, v| m.max(v.abs()));
    let diff = repacked.iter().zip(&by_burn).fold(0f32, |m, (a, b)| m.max((a - b).abs()));
    assert!(scale > 0.0 && diff <= 1e-5 * scale, "predictions differ by {diff:e} (scale {scale:e})");
    let report = evaluate(&cpu.model, &val, &Corruption::none(), 0, Compute::Cpu).unwrap();
    let report_burn = evaluate(&cpu.model, &val, &Corruption::none(), 0, Compute::CpuBurn).unwrap();
    assert!((report.stats.mean - report_burn.stats.mean).abs() <= 1e-5 * report.stats.mean);

    // Stopped on burn's path, resumed on the CPU engines: the same run up to rounding.
    let mixed = root.path().join("mixed");
    let stopped = TrainOptions { stop_after: Some(4), ..on(Compute::CpuBurn, "mixed") };
    assert!(!train(&data, &val, &init, &config, &stopped, &Silent).unwrap().completed);
    let resumed = train(&data, &val, &init, &config, &TrainOptions::new(&mixed), &Silent).unwrap();
    assert!(resumed.completed);
    let last = |o: &augsim_learn::TrainOutcome| o.curve.last().unwrap().val.unwrap().mean;
    assert!((last(&resumed) - last(&cpu)).abs() <= 1e-4 * last(&cpu));
}

/// Asking for the GPU in a build without the `gpu` feature is a clear error.
#[cfg(not(feature = "gpu"))]
#[test]
fn gpu_without_the_feature_is_a_clear_error() {
    let e = Compute::Gpu.ensure_available().unwrap_err().to_string();
    assert!(e.contains("--features gpu"), "{e}");
    let root = tempfile::tempdir().unwrap();
    let data = synthetic_samples(grid(), 0, 2);
    let options = TrainOptions { compute: Compute::Gpu, ..TrainOptions::new(root.path()) };
    let e = train(&data, &Samples::new(grid()), &scratch(2, 1, &data), &TrainConfig::default(), &options, &Silent)
        .unwrap_err()
        .to_string();
    assert!(e.contains("without GPU support"), "{e}");
    assert_eq!("cpu-burn".parse::<Compute>().unwrap(), Compute::CpuBurn);
    let e = "tpu".parse::<Compute>().unwrap_err().to_string();
    assert!(e.contains("`cpu`, `gpu` or `cpu-burn`"), "{e}");
}

/// Asking for burn's CPU engine in a build without the `cpu-burn` feature is a clear error, in
/// training and in prediction.
#[cfg(not(feature = "cpu-burn"))]
#[test]
fn cpu_burn_without_the_feature_is_a_clear_error() {
    let root = tempfile::tempdir().unwrap();
    let data = synthetic_samples(grid(), 0, 2);
    let options = TrainOptions { compute: Compute::CpuBurn, ..TrainOptions::new(root.path()) };
    let e = train(&data, &Samples::new(grid()), &scratch(2, 1, &data), &TrainConfig::default(), &options, &Silent)
        .unwrap_err()
        .to_string();
    assert!(e.contains("--features cpu-burn"), "{e}");
    let Initialization::Scratch { unet, normalization, .. } = scratch(2, 1, &data) else { unreachable!() };
    let model = TrainedModel {
        config: unet.clone(),
        normalization,
        grid: grid(),
        placement: None,
        input_unit: augsim_learn::FieldUnit::Newton,
        target_unit: augsim_learn::FieldUnit::Metre,
        training: None,
        net: UNet::new(&unet, 0).unwrap(),
    };
    let e = Predictor::new(&model, Compute::CpuBurn).err().unwrap().to_string();
    assert!(e.contains("--features cpu-burn"), "{e}");
    assert!(Compute::CpuBurn.describe().is_err());
}
