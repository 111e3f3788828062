//! U-Net shapes, seeded initialisation, and the saved-model bundle.

mod common;

use std::path::Path;

use augsim_learn::{GridPlacement, GridShape, Normalization, TrainedModel, UNet, UNetConfig};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

fn tiny(depth: usize) -> UNetConfig {
    UNetConfig { base_channels: 2, depth, ..UNetConfig::default() }
}

/// Seeded uniform values in [-1, 1).
fn uniform(n: usize, seed: u64) -> Vec<f32> {
    let mut rng = StdRng::seed_from_u64(seed);
    (0..n).map(|_| rng.random_range(-1.0..1.0)).collect()
}

#[test]
fn odd_grids_are_padded_and_cropped_back() {
    assert_eq!(tiny(3).padded(21), 24);
    assert_eq!(tiny(3).padded(23), 24);
    assert_eq!(tiny(3).padded(24), 24);
    for (depth, [nx, ny, nz]) in [(3, [21, 23, 21]), (3, [8, 8, 8]), (1, [5, 3, 7])] {
        let net = UNet::new(&tiny(depth), 1).unwrap().to_inference().unwrap();
        let grid = GridShape::new(nx, ny, nz);
        let out = net.forward(&uniform(grid.field_len(), 2), grid).unwrap();
        assert_eq!(out.len(), grid.field_len());
        assert!(out.iter().all(|v| v.is_finite()) && out.iter().any(|v| *v != 0.0));
    }
}

#[test]
fn padding_does_not_leak_into_the_cropped_output_more_than_a_zero_input_would() {
    // The output on an odd grid equals the output on the grid explicitly zero-padded to the
    // multiple, cropped: the padding is plain zero padding.
    let net = UNet::new(&tiny(2), 4).unwrap().to_inference().unwrap();
    let (small, full) = (GridShape::new(5, 6, 7), GridShape::new(8, 8, 8));
    let x = uniform(small.field_len(), 5);
    let direct = net.forward(&x, small).unwrap();
    let mut padded = vec![0.0; full.field_len()];
    let (n, m) = (small.nodes(), full.nodes());
    for c in 0..3 {
        for node in 0..n {
            let [i, j, k] = small.node_coords(node);
            padded[c * m + full.node_index(i, j, k)] = x[c * n + node];
        }
    }
    let out = net.forward(&padded, full).unwrap();
    let cropped: Vec<f32> = (0..3)
        .flat_map(|c| (0..n).map(move |node| (c, node)))
        .map(|(c, node)| {
            let [i, j, k] = small.node_coords(node);
            out[c * m + full.node_index(i, j, k)]
        })
        .collect();
    assert_eq!(direct, cropped);
}

#[test]
fn initialisation_is_seeded() {
    let a = UNet::new(&tiny(2), 11).unwrap().named_parameters();
    let b = UNet::new(&tiny(2), 11).unwrap().named_parameters();
    let c = UNet::new(&tiny(2), 12).unwrap().named_parameters();
    assert_eq!(a, b);
    assert_ne!(a, c);
    let names: Vec<&str> = a.iter().map(|(n, _)| n.as_str()).collect();
    assert!(names.contains(&"encoder.0.conv1.weight"), "{names:?}");
    assert!(names.contains(&"head.bias"), "{names:?}");
    let encoder = names.iter().filter(|n| UNet::is_encoder_parameter(n)).count();
    // depth 2: 2 encoder blocks (2 convs, weight+bias) + 2 down convs + bottleneck (2 convs).
    assert_eq!(encoder, 2 * 4 + 2 * 2 + 4);
    // He-uniform bound for the first convolution: sqrt(6 / (3 * 27)).
    let w = &a.iter().find(|(n, _)| n == "encoder.0.conv1.weight").unwrap().1;
    let bound = (6.0f32 / 81.0).sqrt();
    assert!(w.iter().all(|v| v.abs() <= bound) && w.iter().any(|v| v.abs() > 0.8 * bound));
}

/// Networks too large for memory are refused before any allocation, with the count; the
/// published network (16 channels, depth 3) is far inside the bound.
#[test]
fn oversized_networks_are_refused() {
    let published = UNet::new(&UNetConfig::default(), 0).unwrap();
    let count: usize = published.named_parameters().iter().map(|(_, v)| v.len()).sum();
    assert!((1_000_000..2_000_000).contains(&count), "{count}");
    for (config, what) in [
        (UNetConfig { base_channels: 100_000, ..UNetConfig::default() }, "100000 channels"),
        (UNetConfig { kernel_size: 1001, ..UNetConfig::default() }, "kernel_size 1001"),
        (UNetConfig { base_channels: 1000, ..UNetConfig::default() }, "parameters, more than 100000000"),
    ] {
        let e = UNet::new(&config, 0).unwrap_err().to_string();
        assert!(e.contains(what), "{e}");
    }
}

#[test]
fn save_then_load_gives_identical_predictions() {
    let dir = tempfile::tempdir().unwrap();
    let grid = GridShape::new(9, 8, 7);
    let config = tiny(2);
    let model = TrainedModel {
        config: config.clone(),
        normalization: Normalization { input_scale: 2.5, target_scale: 0.01 },
        grid,
        placement: Some(GridPlacement { origin: [-0.1, 0.0, 0.25], spacing: [0.01, 0.02, 0.015] }),
        input_unit: augsim_learn::FieldUnit::Newton,
        target_unit: augsim_learn::FieldUnit::Metre,
        training: None,
        net: UNet::new(&config, 3).unwrap(),
    };
    let path = dir.path().join("m.json");
    model.save(&path).unwrap();
    assert!(dir.path().join("m.safetensors").exists());
    let loaded = TrainedModel::load(&path).unwrap();
    assert_eq!(loaded.config, config);
    assert_eq!(loaded.normalization, model.normalization);
    assert_eq!(loaded.grid, grid);
    assert_eq!(loaded.placement, model.placement);
    let input = common::synthetic_sample(grid, 0).input;
    let a = model.predict(&input).unwrap();
    let b = loaded.predict(&input).unwrap();
    assert_eq!(a.len(), grid.field_len());
    assert_eq!(a, b);
    assert!(a.iter().any(|v| *v != 0.0));
    assert_eq!(model.net.named_parameters(), loaded.net.named_parameters());

    // Wrong input length, and weights that do not fit the configuration.
    assert!(model.predict(&input[1..]).is_err());
    let json = std::fs::read_to_string(&path).unwrap();
    std::fs::write(&path, json.replace("\"base_channels\": 2", "\"base_channels\": 4")).unwrap();
    let e = TrainedModel::load(&path).unwrap_err().to_string();
    assert!(e.contains("m.safetensors"), "{e}");
    std::fs::write(dir.path().join("m.safetensors"), b"garbage").unwrap();
    std::fs::write(&path, &json).unwrap();
    assert!(TrainedModel::load(&path).is_err());
    // Another run's weights under this model.json (a run stopped between its two writes): refused.
    TrainedModel { net: UNet::new(&config, 4).unwrap(), ..model }.save(&path).unwrap();
    std::fs::write(&path, &json).unwrap();
    let e = TrainedModel::load(&path).unwrap_err().to_string();
    assert!(e.contains("m.safetensors is not the weights it describes"), "{e}");
}

/// Where the data of tensor `name` lies in the safetensors `bytes`.
fn tensor_bytes(bytes: &[u8], name: &str) -> std::ops::Range<usize> {
    let header_len = u64::from_le_bytes(bytes[..8].try_into().unwrap()) as usize;
    let header: serde_json::Value = serde_json::from_slice(&bytes[8..8 + header_len]).unwrap();
    let offsets = &header[name]["data_offsets"];
    let start = 8 + header_len + offsets[0].as_u64().unwrap() as usize;
    start..8 + header_len + offsets[1].as_u64().unwrap() as usize
}

/// Weights with a NaN or an infinity (an edited file, or another tool's model) are refused as
/// they are read, the tensor named: the network would predict NaN, or swallow it in a ReLU.
#[test]
fn non_finite_weights_are_refused_when_read() {
    let dir = tempfile::tempdir().unwrap();
    let config = tiny(1);
    let model = TrainedModel {
        config: config.clone(),
        normalization: Normalization { input_scale: 1.0, target_scale: 0.01 },
        grid: GridShape::new(4, 4, 4),
        placement: None,
        input_unit: augsim_learn::FieldUnit::Newton,
        target_unit: augsim_learn::FieldUnit::Metre,
        training: None,
        net: UNet::new(&config, 3).unwrap(),
    };
    let path = dir.path().join("model.json");
    model.save(&path).unwrap();
    let weights = dir.path().join("model.safetensors");
    let intact = std::fs::read(&weights).unwrap();
    for (name, value) in [("bottleneck.conv1.bias", f32::NAN), ("head.weight", f32::INFINITY)] {
        let mut bytes = intact.clone();
        let at = tensor_bytes(&bytes, name).start + 4;
        bytes[at..at + 4].copy_from_slice(&value.to_le_bytes());
        let e = UNet::from_safetensors(&config, &bytes, &weights).unwrap_err().to_string();
        assert!(e.contains(&format!("tensor {name} holds a non-finite value ({value} at position 1)")), "{e}");
        // Through the model file too (one saved without a digest, which would refuse the bytes first).
        std::fs::write(&weights, &bytes).unwrap();
        let mut json: serde_json::Value = serde_json::from_slice(&std::fs::read(&path).unwrap()).unwrap();
        json.as_object_mut().unwrap().remove("weights_digest");
        std::fs::write(&path, json.to_string()).unwrap();
        let e = TrainedModel::load(&path).unwrap_err().to_string();
        assert!(e.contains(&format!("tensor {name} holds a non-finite value")), "{e}");
    }
}

/// The `weights_digest` of the model file at `path`.
fn digest_of(path: &Path) -> Option<String> {
    let json: serde_json::Value = serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap();
    json["weights_digest"].as_str().map(str::to_string)
}

/// The shipped models load, their weights serialize back to the very bytes of their files, and
/// their model files name those bytes by the digest a save writes: a flipped byte is refused.
#[test]
fn shipped_models_load_and_serialize_back_unchanged() {
    let models = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../models");
    let tmp = tempfile::tempdir().unwrap();
    for name in ["liver_ar", "liver_forces"] {
        let dir = models.join(name);
        let model = TrainedModel::load(&augsim_learn::Model::json_path(&dir)).unwrap();
        assert_eq!(model.net.config(), &model.config);
        let bytes = std::fs::read(dir.join("model.safetensors")).unwrap();
        assert!(model.net.to_safetensors().unwrap() == bytes, "{name}: weights serialize to other bytes");
        let saved = tmp.path().join(name).join("model.json");
        std::fs::create_dir(saved.parent().unwrap()).unwrap();
        model.save(&saved).unwrap();
        let shipped = dir.join("model.json");
        assert!(digest_of(&shipped).is_some(), "{name}: model.json holds no weights_digest");
        assert_eq!(digest_of(&shipped), digest_of(&saved), "{name}");
        let mut flipped = bytes.clone();
        flipped[tensor_bytes(&bytes, "head.bias").start] ^= 0x10;
        std::fs::copy(&shipped, &saved).unwrap();
        std::fs::write(saved.with_extension("safetensors"), &flipped).unwrap();
        let e = TrainedModel::load(&saved).unwrap_err().to_string();
        assert!(e.contains("is not the weights it describes") && e.contains("damaged since"), "{name}: {e}");
        // One cut short is told as such, not as another run's.
        std::fs::write(saved.with_extension("safetensors"), &bytes[..bytes.len() - 1000]).unwrap();
        let e = TrainedModel::load(&saved).unwrap_err().to_string();
        assert!(e.contains("model.safetensors") && !e.contains("another run"), "{name}: {e}");
        let names: Vec<String> = model.net.named_parameters().into_iter().map(|(n, _)| n).collect();
        assert_eq!(names.len(), 42);
        assert_eq!(names[..3], ["encoder.0.conv1.weight", "encoder.0.conv1.bias", "encoder.0.conv2.weight"]);
        assert_eq!(names[40..], ["head.weight", "head.bias"]);
    }
}

/// A model is found from its directory, its `model.json` or its weights file alike.
#[test]
fn a_model_is_found_from_its_weights_file() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../models/liver_ar");
    for path in [dir.clone(), dir.join("model.json"), dir.join("model.safetensors")] {
        assert_eq!(augsim_learn::Model::json_path(&path), dir.join("model.json"), "{}", path.display());
        assert!(matches!(augsim_learn::Model::load(&path), Ok(augsim_learn::Model::UNet(_))), "{}", path.display());
    }
}
