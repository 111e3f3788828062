//! The reduced-order model on a problem with a known answer: inputs and targets driven by two
//! hidden parameters, the target a nonlinear function of them.

use augsim_learn::rom::{fit, Context, RomConfig};
use augsim_learn::{
    evaluate, uncertainty_coverage, Compute, Corruption, GridShape, Method, Model, PredictInput, Sample, Samples,
    SplitPolicy,
};
use augsim_learn::{FieldUnit, LearnedModel};
use mesh::io::npy::{NpyArray, NpyData};

/// Sample `index`: parameters (a, b) in [−1, 1]²; the input a·φ₁ + b·φ₂ on a patch of nodes (a
/// "visible surface"); the target a smooth field a·ψ₁ + b·ψ₂ + a·b·ψ₃ + a²·ψ₄ (m) inside the mask.
fn sample(grid: GridShape, index: u64) -> Sample {
    let t = index as f64;
    let (a, b) = ((t * 0.618_034).fract() * 2.0 - 1.0, (t * 0.754_877).fract() * 2.0 - 1.0);
    let [nx, ny, nz] = grid.dims();
    let mut input = vec![0f32; grid.field_len()];
    let mut target = vec![0f32; grid.field_len()];
    let mut mask = vec![0u8; grid.nodes()];
    for i in 0..nx {
        for j in 0..ny {
            for k in 0..nz {
                let (x, y, z) = (i as f64 / nx as f64, j as f64 / ny as f64, k as f64 / nz as f64);
                let n = grid.node_index(i, j, k);
                mask[n] = u8::from(i > 0 && i + 1 < nx);
                if k + 1 == nz {
                    input[grid.field_index(2, i, j, k)] = (0.01 * (a * (3.0 * x).sin() + b * (2.0 * y).cos())) as f32;
                }
                for c in 0..3 {
                    let s = c as f64 + 1.0;
                    let value = 0.01
                        * (a * (s * x + z).sin() + b * (y - s * z).cos() + a * b * (x * y * s) + a * a * (z * s).cos());
                    target[grid.field_index(c, i, j, k)] = value as f32 * f32::from(mask[n]);
                }
            }
        }
    }
    Sample { index, input, target, mask }
}

fn samples(grid: GridShape, count: usize) -> Samples {
    let mut s = Samples::new(grid);
    for i in 0..count as u64 {
        s.push(&sample(grid, i)).unwrap();
    }
    s.source = Some("two-parameter test".into());
    s
}

#[test]
fn a_smooth_two_parameter_family_is_learned_saved_and_evaluated() {
    let grid = GridShape::new(8, 7, 5);
    let all = samples(grid, 400);
    let policy = SplitPolicy { validation_samples: Some(50), test_samples: Some(80), ..SplitPolicy::default() };
    let (split, [train, validation, test]) = policy.apply(&all).unwrap();
    let context = Context { placement: None, input_unit: FieldUnit::Metre, target_unit: FieldUnit::Metre, split };
    let (model, report) = fit(&train, &validation, &RomConfig::default(), context, None).unwrap();
    // The basis holds the targets (four fields span them); the regression learns the map.
    assert!(model.info.modes >= 4, "{} modes", model.info.modes);
    assert!(report.val_projection_error < 1e-6, "basis floor {}", report.val_projection_error);
    let size = test.targets.iter().map(|v| f64::from(v.abs())).sum::<f64>() / test.targets.len() as f64;
    let clean = Corruption::none();

    // Saved and loaded as a model directory, it predicts the same fields and is known as a ROM.
    let dir = tempfile::tempdir().unwrap();
    model.save(dir.path()).unwrap();
    let loaded = Model::load(dir.path()).unwrap();
    assert_eq!(loaded.method(), Method::Rom);
    let predictor = loaded.predictor(Compute::Cpu).unwrap();
    let (field, std) = predictor.predict_with_std(test.input(0)).unwrap();
    let direct = model.predict_with_std(test.input(0)).unwrap();
    let largest = field.iter().zip(&direct.field).map(|(a, b)| (a - b).abs()).fold(0f32, f32::max);
    assert!(largest < 1e-6, "loaded and fitted models differ by {largest}");
    let std = std.unwrap();
    assert_eq!(predictor.predict_std(test.input(0)).unwrap().as_ref(), Some(&std), "the standard deviation alone");
    let mask = test.mask(0);
    assert!(std.iter().zip(mask).all(|(s, &m)| if m == 1 { *s > 0.0 } else { *s == 0.0 }));

    // Held-out error: a small share of the motion.
    let report = evaluate(&loaded, &test, &clean, 0, Compute::Cpu).unwrap();
    assert!(
        report.stats.mean < 0.02 * size * 3f64.sqrt(),
        "test ē {} against a mean |u| component of {size}",
        report.stats.mean
    );
    // Its own predictions lie on its basis: projected there they stay; so the model projected on
    // itself evaluates as itself (up to single-precision rounding of the field), and a field off
    // the basis moves.
    let projected = augsim_learn::Projected::new(loaded.clone(), &loaded).unwrap();
    let again = evaluate(&projected, &test, &clean, 0, Compute::Cpu).unwrap();
    let moved = (again.stats.mean - report.stats.mean).abs();
    assert!(moved < 1e-6 * size, "{moved} apart, on fields of {size}");
    let mut off = direct.field.clone();
    off[mask.iter().position(|&m| m == 1).unwrap()] += 1.0;
    let back = model.project(&off).unwrap();
    let moved = back.iter().zip(&direct.field).map(|(a, b)| (a - b).abs()).fold(0f32, f32::max);
    assert!(moved > 0.0 && moved < 1.0, "a unit spike off the basis comes back as {moved}");
    // It refuses samples it was fitted or selected on.
    assert!(evaluate(&loaded, &train, &clean, 0, Compute::Cpu).is_err());
    assert_eq!(loaded.held_out(&all).unwrap(), test);

    // The predicted standard deviation is calibrated on validation: on the test samples, most node
    // errors lie within two of it.
    let share = uncertainty_coverage(&loaded, &test, &clean, 0).unwrap().unwrap();
    assert!((0.8..=1.0).contains(&share), "{:.1} % of the test nodes within 2σ", 100.0 * share);
}

#[test]
fn bad_input_is_refused_with_a_message() {
    let grid = GridShape::new(6, 5, 4);
    let all = samples(grid, 60);
    let policy = SplitPolicy { validation_samples: Some(10), test_samples: Some(10), ..SplitPolicy::default() };
    let (split, [train, validation, _]) = policy.apply(&all).unwrap();
    let context =
        |split| Context { placement: None, input_unit: FieldUnit::Metre, target_unit: FieldUnit::Metre, split };
    let (model, _) = fit(&train, &validation, &RomConfig::default(), context(split.clone()), None).unwrap();
    let e = model.predict(&[0.0; 7]).unwrap_err().to_string();
    assert!(e.contains("expected"), "{e}");
    let mut input = train.input(0).to_vec();
    input[3] = f32::NAN;
    let e = model.predict(&input).unwrap_err().to_string();
    assert!(e.contains("prediction input value 3 is NaN"), "{e}");
    input[3] = 1e30;
    let e = model.predict(&input).unwrap_err().to_string();
    assert!(e.contains("value 3 is 1e30: inputs are finite displacements (m) or forces (N) within 1e6"), "{e}");
    // A float64 input is checked before its rounding to float32 (1e300 would be infinite).
    let mut wide: Vec<f64> = train.input(0).iter().map(|&v| f64::from(v)).collect();
    wide[3] = 1e300;
    let array = NpyArray { shape: vec![3, 6, 5, 4], data: NpyData::F64(wide) };
    let reduced = Model::Reduced(std::sync::Arc::new(model.clone()));
    let e = PredictInput::Grid(array).into_network_input(&reduced).unwrap_err().to_string();
    assert!(e.contains("value 3 is 1e300"), "{e}");
    // An input a thousand times its training inputs (millimetres given as metres) is refused; ten
    // times is not.
    let field = |scale: f32, at: &dyn Fn(usize) -> bool| -> PredictInput {
        let data = train.input(0).iter().enumerate().map(|(e, &v)| if at(e) { scale * v } else { 0.0 }).collect();
        PredictInput::Grid(NpyArray { shape: vec![3, 6, 5, 4], data: NpyData::F32(data) })
    };
    let everywhere = |_: usize| true;
    let e = field(1000.0, &everywhere).into_network_input(&reduced).unwrap_err().to_string();
    assert!(e.contains("times as far from the model's mean input") && e.contains("another unit"), "{e}");
    assert!(field(10.0, &everywhere).into_network_input(&reduced).is_ok());
    // An input only where the model reads none (off the surface it was trained to see) is refused;
    // a node of one there is counted.
    let n = grid.nodes();
    let read: std::collections::BTreeSet<usize> = model.input_entries().iter().map(|e| e % n).collect();
    let unread: Vec<usize> = (0..n).filter(|v| !read.contains(v)).collect();
    let mut off = vec![0f32; grid.field_len()];
    unread.iter().for_each(|&v| off[2 * n + v] = 0.01);
    let e = PredictInput::Grid(NpyArray { shape: vec![3, 6, 5, 4], data: NpyData::F32(off) })
        .into_network_input(&reduced)
        .unwrap_err()
        .to_string();
    assert!(e.contains(&format!("none of the input's {} non-zero grid nodes", unread.len())), "{e}");
    let mut partly = train.input(0).to_vec();
    partly[2 * n + unread[0]] = 0.01;
    let given = (0..n).filter(|&v| (0..3).any(|c| partly[c * n + v] != 0.0)).count();
    let read = PredictInput::Grid(NpyArray { shape: vec![3, 6, 5, 4], data: NpyData::F32(partly) })
        .into_network_input(&reduced)
        .unwrap();
    assert_eq!((read.unread_nodes, read.given_nodes), (1, given));
    // Settings that leave nothing to fit, or that would fit the same thing twice.
    let noisy = Corruption { noise_std: 1e-3, ..Corruption::none() };
    for (config, what) in [
        (RomConfig { max_modes: 0, ..RomConfig::default() }, "at least one of its modes"),
        (RomConfig { max_inducing: 0, ..RomConfig::default() }, "at least one of its inducing points"),
        (RomConfig { input_energy: 0.0, ..RomConfig::default() }, "input energy"),
        (
            RomConfig { noise_copies: 2, ..RomConfig::default() },
            "copies of each training sample asked for, but no corruption",
        ),
        (
            RomConfig { noise_copies: 1_000_000_000_000, corruption: noisy.clone(), ..RomConfig::default() },
            "corrupted copies of each would take",
        ),
    ] {
        let e = fit(&train, &validation, &config, context(split.clone()), None).unwrap_err().to_string();
        assert!(e.contains(what), "{e}");
    }
    // Nothing to learn: every target the same.
    let mut flat = train.clone();
    flat.targets.iter_mut().for_each(|v| *v = 0.5);
    let e = fit(&flat, &validation, &RomConfig::default(), context(split), None).unwrap_err().to_string();
    assert!(e.contains("do not vary"), "{e}");
    // A damaged model directory is refused, naming the array.
    let dir = tempfile::tempdir().unwrap();
    model.save(dir.path()).unwrap();
    std::fs::write(dir.path().join("weights.npy"), b"not an array").unwrap();
    let e = Model::load(dir.path()).unwrap_err().to_string();
    assert!(e.contains("weights.npy"), "{e}");
    // An array of another fit, of the same shape, copied in: refused by its digest.
    model.save(dir.path()).unwrap();
    let weights = mesh::io::npy::read_npy(&dir.path().join("weights.npy")).unwrap();
    let other: Vec<f64> = weights.clone().into_f64().iter().map(|w| w * 1.5).collect();
    mesh::io::npy::write_f64(&dir.path().join("weights.npy"), &weights.shape, &other).unwrap();
    let e = Model::load(dir.path()).unwrap_err().to_string();
    assert!(e.contains("weights.npy is not the one saved with this model (changed since, or another fit's)"), "{e}");
    model.save(dir.path()).unwrap();
    // A model.json cut short is named as bad JSON, at its fault; one of another format says so.
    let json = dir.path().join("model.json");
    let text = std::fs::read_to_string(&json).unwrap();
    std::fs::write(&json, &text[..text.len() / 2]).unwrap();
    let e = Model::load(dir.path()).unwrap_err().to_string();
    assert!(e.contains("invalid model JSON: EOF while parsing") && e.contains("line"), "{e}");
    std::fs::write(&json, text.replace("\"augsim-rom\"", "\"augsim-rm\"")).unwrap();
    let e = Model::load(dir.path()).unwrap_err().to_string();
    assert!(e.contains("its format \"augsim-rm\" is no model's: \"augsim-unet\""), "{e}");
    // A grid without a node along an axis is no grid.
    let mut value: serde_json::Value = serde_json::from_str(&text).unwrap();
    // A placement that places no grid is named with its file.
    value["placement"] = serde_json::json!({"origin": [0.0, 0.0, 0.0], "spacing": [-0.01, 0.01, 0.01]});
    std::fs::write(&json, value.to_string()).unwrap();
    let e = Model::load(dir.path()).unwrap_err().to_string();
    assert!(e.contains("model.json: placement: ") && e.contains("spacing positive"), "{e}");
    value["placement"] = serde_json::Value::Null;
    value["grid"][2] = 0.into();
    std::fs::write(&json, value.to_string()).unwrap();
    let e = Model::load(dir.path()).unwrap_err().to_string();
    assert!(e.contains("every axis needs at least one node"), "{e}");
}

/// The shipped reduced-order models load, save back to the very bytes of their files, and predict
/// a finite field with a finite, non-negative standard deviation (zero where the organ is held).
#[test]
fn shipped_reduced_order_models_load_and_save_back_unchanged() {
    let models = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../models");
    for name in ["liver_ar_rom", "liver_forces_rom"] {
        let dir = models.join(name);
        let model = augsim_learn::rom::ReducedModel::load(&dir.join("model.json")).unwrap();
        assert_eq!(model.info.prior.is_some(), name == "liver_forces_rom", "{name}");
        let out = tempfile::tempdir().unwrap();
        model.save(out.path()).unwrap();
        for entry in std::fs::read_dir(&dir).unwrap() {
            let file = entry.unwrap().file_name();
            let (shipped, saved) =
                (std::fs::read(dir.join(&file)).unwrap(), std::fs::read(out.path().join(&file)).unwrap());
            assert!(shipped == saved, "{name}/{}: saved as other bytes", file.to_string_lossy());
        }
        let input = vec![0f32; model.grid.field_len()];
        let p = model.predict_with_std(&input).unwrap();
        assert!(p.field.iter().chain(&p.std).all(|v| v.is_finite()) && p.std.iter().all(|&s| s >= 0.0));
        assert!(model.nodes().iter().any(|&n| p.std[n] > 0.0), "{name}: no uncertainty anywhere");
    }
}
