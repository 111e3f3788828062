//! A reduced-order model fitted on a small beam dataset, as `augsim train --method rom` fits it:
//! saved where asked (not while another training holds the folder) and described in words.

use std::path::Path;

use augsim_app::training::{fit_rom, rom_lines};
use learn::rom::RomConfig;
use learn::{Dataset, SplitPolicy};
use scenario::DatasetScenario;

#[test]
fn a_rom_fitted_on_a_beam_dataset_is_saved_and_described() {
    let (mut scenario, dir) = DatasetScenario::load(Path::new("beam_bc1")).unwrap();
    scenario.dataset.samples = 30;
    let tmp = tempfile::tempdir().unwrap();
    let data = tmp.path().join("data");
    scenario.generator(&dir).unwrap().run(&data, &scenario.name, None, &learn::Silent).unwrap();
    let dataset = Dataset::open(&data).unwrap();
    let all = dataset.load_all().unwrap();
    let (split, [train, validation, _]) = SplitPolicy::default().apply(&all).unwrap();
    let out = tmp.path().join("rom");
    let config = RomConfig { max_modes: 4, ..RomConfig::default() };
    // While another training holds the folder, the fit is refused before any work.
    let held = learn::take_model_folder(&out).unwrap();
    let e = fit_rom(&dataset, split.clone(), [train.clone(), validation.clone()], &config, None, &out).unwrap_err();
    assert!(e.to_string().contains("is being written by another run"), "{e}");
    assert!(!out.join(learn::MODEL_FILE).exists(), "nothing written");
    drop(held);
    let (model, report) = fit_rom(&dataset, split, [train, validation], &config, None, &out).unwrap();
    assert!(learn::Model::load(&out).is_ok());
    assert!(model.info.modes >= 1 && model.info.modes <= 4, "{} modes", model.info.modes);
    let lines = rom_lines(&model, &report);
    assert!(lines[0].starts_with(&format!("basis      {} modes", model.info.modes)), "{lines:?}");
    assert!(lines.iter().any(|l| l.starts_with("validation mean e = ")), "{lines:?}");
    assert!(lines.last().unwrap().starts_with("time       "), "{lines:?}");
}
