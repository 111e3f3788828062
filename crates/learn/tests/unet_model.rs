//! U-Net shapes, seeded initialisation, and the saved-model bundle.

mod common;

use augsim_learn::{inference_device, GridPlacement, GridShape, Normalization, TrainedModel, UNet, UNetConfig};
use burn::tensor::{Distribution, Tensor};

fn tiny(depth: usize) -> UNetConfig {
    UNetConfig { base_channels: 2, depth, ..UNetConfig::default() }
}

#[test]
fn odd_grids_are_padded_and_cropped_back() {
    let device = inference_device();
    let net = UNet::new(&tiny(3), &device, 1).unwrap();
    assert_eq!(tiny(3).padded(21), 24);
    assert_eq!(tiny(3).padded(23), 24);
    assert_eq!(tiny(3).padded(24), 24);
    let x = Tensor::<5>::random([2, 3, 21, 23, 21], Distribution::Uniform(-1.0, 1.0), &device);
    assert_eq!(net.forward(x).dims(), [2, 3, 21, 23, 21]);
    let x = Tensor::<5>::random([1, 3, 8, 8, 8], Distribution::Uniform(-1.0, 1.0), &device);
    assert_eq!(net.forward(x).dims(), [1, 3, 8, 8, 8]);
    let net1 = UNet::new(&tiny(1), &device, 1).unwrap();
    let x = Tensor::<5>::random([1, 3, 5, 3, 7], Distribution::Uniform(-1.0, 1.0), &device);
    assert_eq!(net1.forward(x).dims(), [1, 3, 5, 3, 7]);
}

#[test]
fn padding_does_not_leak_into_the_cropped_output_more_than_a_zero_input_would() {
    // The output on an odd grid equals the output on the grid explicitly zero-padded to the
    // multiple, cropped: the padding is plain zero padding.
    let device = inference_device();
    let net = UNet::new(&tiny(2), &device, 4).unwrap();
    let x = Tensor::<5>::random([1, 3, 5, 6, 7], Distribution::Uniform(-1.0, 1.0), &device);
    let direct = net.forward(x.clone()).into_data().try_to_vec::<f32>().unwrap();
    let padded = Tensor::<5>::zeros([1, 3, 8, 8, 8], &device).slice_assign([0..1, 0..3, 0..5, 0..6, 0..7], x);
    let full = net.forward(padded).slice([0..1, 0..3, 0..5, 0..6, 0..7]).into_data().try_to_vec::<f32>().unwrap();
    assert_eq!(direct, full);
}

#[test]
fn initialisation_is_seeded() {
    let device = inference_device();
    let a = UNet::new(&tiny(2), &device, 11).unwrap().named_parameters();
    let b = UNet::new(&tiny(2), &device, 11).unwrap().named_parameters();
    let c = UNet::new(&tiny(2), &device, 12).unwrap().named_parameters();
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

#[test]
fn save_then_load_gives_identical_predictions() {
    let dir = tempfile::tempdir().unwrap();
    let grid = GridShape::new(9, 8, 7);
    let device = inference_device();
    let config = tiny(2);
    let model = TrainedModel {
        config: config.clone(),
        normalization: Normalization { input_scale: 2.5, target_scale: 0.01 },
        grid,
        placement: Some(GridPlacement { origin: [-0.1, 0.0, 0.25], spacing: [0.01, 0.02, 0.015] }),
        input_unit: "N".into(),
        target_unit: "m".into(),
        training: None,
        net: UNet::new(&config, &device, 3).unwrap(),
    };
    let path = dir.path().join("m.json");
    model.save(&path).unwrap();
    assert!(dir.path().join("m.safetensors").exists());
    let loaded = TrainedModel::load(&path, &device).unwrap();
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
    let e = TrainedModel::load(&path, &device).unwrap_err().to_string();
    assert!(e.contains("m.safetensors"), "{e}");
    std::fs::write(dir.path().join("m.safetensors"), b"garbage").unwrap();
    std::fs::write(&path, json).unwrap();
    assert!(TrainedModel::load(&path, &device).is_err());
}
