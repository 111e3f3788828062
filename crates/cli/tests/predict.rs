//! End to end through the command line: generate a tiny liver dataset, train a tiny network,
//! then predict from a point cloud of forces and interpolate the result to the organ mesh.

use std::path::Path;
use std::process::Command;

fn augsim(args: &[&str], dir: &Path) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_augsim")).args(args).current_dir(dir).output().unwrap();
    let text = format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    assert!(out.status.success(), "augsim {args:?} failed:\n{text}");
    text
}

/// Runs `augsim args` until `ready` holds (polled), then sends it SIGINT; its output once it ends.
#[cfg(unix)]
fn interrupted(args: &[&str], dir: &Path, ready: impl Fn() -> bool) -> (bool, String) {
    use std::process::Stdio;
    let child = Command::new(env!("CARGO_BIN_EXE_augsim"))
        .args(args)
        .current_dir(dir)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let began = std::time::Instant::now();
    while !ready() {
        assert!(began.elapsed().as_secs() < 300, "augsim {args:?} never got ready");
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    // SAFETY: a signal to the child process this test spawned.
    assert_eq!(unsafe { libc::kill(child.id() as libc::pid_t, libc::SIGINT) }, 0);
    let out = child.wait_with_output().unwrap();
    (out.status.success(), format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr)))
}

/// Ctrl-C during a training writes its checkpoint and says so; the same command resumes from it.
#[cfg(unix)]
fn ctrl_c_stops_a_training_with_its_checkpoint_and_the_next_run_resumes(d: &Path) {
    let args = ["train", "data", "--out", "long", "--iterations", "100000000", "--channels", "2", "--depth", "1"];
    let args = [&args[..], &["--test-samples", "2", "--validate-every", "5"]].concat();
    let checkpoint = d.join("long/checkpoint.bin");
    let (ok, text) = interrupted(&args, d, || checkpoint.exists());
    let step = |text: &str| -> u64 {
        let at = text.find("interrupted at step ").unwrap_or_else(|| panic!("{text}")) + "interrupted at step ".len();
        text[at..].split(' ').next().unwrap().parse().unwrap()
    };
    assert!(!ok && text.contains("its checkpoint is written in long; the same command resumes from it"), "{text}");
    let first = step(&text);
    let written = std::fs::metadata(&checkpoint).unwrap().modified().unwrap();
    let (ok, text) = interrupted(&args, d, || std::fs::metadata(&checkpoint).unwrap().modified().unwrap() != written);
    assert!(!ok && text.contains(&format!("resuming long/checkpoint.bin at step {first} of 100000000")), "{text}");
    assert!(step(&text) > first, "{text}");
}

fn augsim_err(args: &[&str], dir: &Path) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_augsim")).args(args).current_dir(dir).output().unwrap();
    assert!(!out.status.success(), "augsim {args:?} should fail");
    String::from_utf8_lossy(&out.stderr).into_owned()
}

#[test]
fn point_cloud_prediction_through_the_cli() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(
        d.join("tiny.toml"),
        r#"
kind = "dataset"
name = "tiny"
[mesh.phantom]
tets = 800
[material]
law = "svk"
young = 5000.0
poisson = 0.45
[dataset]
samples = 6
seed = 3
shard_size = 3
grid = [9, 10, 9]
fixed = [{ region = "fixed" }]
input = "force"
[dataset.load.patch_force]
radius = 0.03
magnitude = [0.05, 0.2]
"#,
    )
    .unwrap();
    augsim(&["generate", "tiny.toml", "--out", "data"], d);
    augsim(&["mesh", "--tets", "800", "-o", "organ.vtu"], d);
    let text = augsim(
        &[
            "train",
            "data",
            "--out",
            "net",
            "--iterations",
            "6",
            "--channels",
            "2",
            "--depth",
            "1",
            "--test-samples",
            "2",
        ],
        d,
    );
    assert!(text.contains("split      3 training, 1 validation, 2 test samples"), "{text}");
    assert!(text.contains("batch      3 samples per step: the whole training set (--batch 4 is more"), "{text}");
    assert!(text.contains("best       validation"), "{text}");
    assert!(d.join("net/curve.png").is_file(), "the learning curve is drawn beside the model");
    #[cfg(unix)]
    ctrl_c_stops_a_training_with_its_checkpoint_and_the_next_run_resumes(d);

    // The model records its split; eval reports on its test samples only.
    let text = augsim(&["eval", "net/model.json", "data", "--out", "eval"], d);
    assert!(text.contains("held out   2 of 6 samples (the test split recorded in the model)"), "{text}");
    let errors = std::fs::read_to_string(d.join("eval/errors.csv")).unwrap();
    assert_eq!(errors.lines().count(), 3, "{errors}");
    // A folder of an earlier evaluation is refused; without --out each run takes a fresh one.
    let e = augsim_err(&["eval", "net/model.json", "data", "--out", "eval"], d);
    assert!(e.contains("holds the results of an earlier run"), "{e}");
    for run in ["001", "002"] {
        assert!(augsim(&["eval", "net/model.json", "data"], d).contains(&format!("out/eval/{run}/summary.json")));
    }
    // Sparse, noisy input: MIN,MAX as the help says; a malformed or reversed range is refused.
    let text =
        augsim(&["eval", "net/model.json", "data", "--out", "eval_sparse", "--sparse", "2,20", "--noise", "1e-4"], d);
    assert!(text.contains("held out   2 of 6 samples"), "{text}");
    // A noise in another unit than the inputs' would drown them.
    let e = augsim_err(&["eval", "net/model.json", "data", "--noise", "1"], d);
    assert!(
        e.contains("a noise of 1 N on inputs whose RMS is") && e.contains("the noise is in the inputs' unit, N"),
        "{e}"
    );
    let e = augsim_err(&["eval", "net/model.json", "data", "--sparse", "20"], d);
    assert!(e.contains("expected MIN,MAX (e.g. 13,114), got '20'"), "{e}");
    // A patch of more nodes than any input has would leave the input dense: refused.
    let e = augsim_err(&["eval", "net/model.json", "data", "--sparse", "500,1000"], d);
    assert!(e.contains("--sparse 500,1000 keeps every input node: the samples have at most"), "{e}");
    let e = augsim_err(&["eval", "net/model.json", "data", "--sparse", "20,2"], d);
    assert!(e.contains("patch sizes must satisfy 1 <= min <= max, got 20, 2"), "{e}");
    // A copy of the model whose record lost its split, or that takes displacements, is not
    // evaluated: its figures would be on its own training samples, or on inputs of another kind.
    let edited = |name: &str, edit: &dyn Fn(&mut serde_json::Value)| {
        std::fs::create_dir_all(d.join(name)).unwrap();
        for entry in std::fs::read_dir(d.join("net")).unwrap() {
            let entry = entry.unwrap();
            if entry.path().is_file() {
                std::fs::copy(entry.path(), d.join(name).join(entry.file_name())).unwrap();
            }
        }
        let path = d.join(name).join("model.json");
        let mut model: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
        edit(&mut model);
        std::fs::write(&path, model.to_string()).unwrap();
    };
    edited("no_split", &|m| {
        m["training"].as_object_mut().unwrap().remove("split");
    });
    let e = augsim_err(&["eval", "no_split/model.json", "data"], d);
    assert!(e.contains("the model records no split of the data it was trained on"), "{e}");
    edited("displacements", &|m| m["input_unit"] = "m".into());
    let e = augsim_err(&["eval", "displacements/model.json", "data"], d);
    assert!(e.contains("the model takes displacements as input, the dataset's inputs are forces"), "{e}");

    // Two point forces inside the organ's bounding box, one on a grid-cell corner.
    let model: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("net/model.json")).unwrap()).unwrap();
    let origin: Vec<f64> = serde_json::from_value(model["placement"]["origin"].clone()).unwrap();
    let spacing: Vec<f64> = serde_json::from_value(model["placement"]["spacing"].clone()).unwrap();
    let p =
        |i: f64, j: f64, k: f64| [origin[0] + i * spacing[0], origin[1] + j * spacing[1], origin[2] + k * spacing[2]];
    let (a, b) = (p(4.0, 5.0, 4.0), p(3.5, 2.25, 6.0));
    std::fs::write(
        d.join("cloud.csv"),
        format!("x,y,z,fx,fy,fz\n{},{},{},0,0,-0.1\n{},{},{},0.05,0,0\n", a[0], a[1], a[2], b[0], b[1], b[2]),
    )
    .unwrap();
    let text =
        augsim(&["predict", "net/model.json", "cloud.csv", "-o", "pred.npy", "--mesh", "organ.vtu", "--runs", "2"], d);
    assert!(text.contains("points     2"), "{text}");
    assert!(text.contains("prediction 2 runs"), "{text}");
    assert!(d.join("pred.npy").exists() && d.join("pred.vtu").exists());
    let (organ, fields) = mesh::io::read_mesh_with_fields(d.join("pred.vtu")).unwrap();
    let u = fields.iter().find(|f| f.name == "displacement").expect("displacement field");
    assert_eq!(u.values.len(), 3 * organ.num_nodes());
    assert!(u.values.iter().all(|v| v.is_finite()) && u.values.iter().any(|v| *v != 0.0));
    // The same forces a thousand times stronger (kN read as N): far outside what the network learned.
    let strong =
        std::fs::read_to_string(d.join("cloud.csv")).unwrap().replace(",-0.1\n", ",-100\n").replace(",0.05,", ",50,");
    std::fs::write(d.join("strong.csv"), strong).unwrap();
    let e = augsim_err(&["predict", "net/model.json", "strong.csv", "-o", "strong.npy"], d);
    assert!(e.contains("times that of the inputs the model was trained on") && e.contains("another unit"), "{e}");
    assert!(!d.join("pred_sigma.npy").exists() && !fields.iter().any(|f| f.name == "sigma"), "a U-Net predicts no σ");
    // A reduced-order model writes its predicted σ beside the displacement, on the grid and the mesh.
    augsim(&["train", "data", "--out", "rom", "--method", "rom", "--test-samples", "2"], d);
    // It reads its input where its training draws pushed, and nowhere else: the cloud above pushes
    // inside the organ, where it reads nothing; one on a node it reads is predicted.
    let e = augsim_err(&["predict", "rom", "cloud.csv", "-o", "rom.npy", "--runs", "1"], d);
    assert!(e.contains("none of the input's 9 non-zero grid nodes lies where the model reads its input"), "{e}");
    let read = mesh::io::npy::read_npy(&d.join("rom/input_mask.npy")).unwrap().into_f32();
    let entry = read.iter().position(|&m| m == 1.0).unwrap();
    let (channel, node) = (entry / (9 * 10 * 9), entry % (9 * 10 * 9));
    let at = p((node / 90) as f64, (node / 9 % 10) as f64, (node % 9) as f64);
    let mut force = [0.0; 3];
    force[channel] = 0.1;
    let row = format!("{},{},{},{},{},{}", at[0], at[1], at[2], force[0], force[1], force[2]);
    std::fs::write(d.join("cloud.csv"), format!("x,y,z,fx,fy,fz\n{row}\n")).unwrap();
    let text = augsim(&["predict", "rom", "cloud.csv", "-o", "rom.npy", "--mesh", "organ.vtu", "--runs", "1"], d);
    assert!(text.contains("points     1") && !text.contains("warning"), "{text}");
    assert!(text.contains("sigma      predicted at the organ's grid nodes: mean"), "{text}");
    let sigma = mesh::io::npy::read_npy(&d.join("rom_sigma.npy")).unwrap();
    assert_eq!(sigma.shape, [9, 10, 9]);
    let sigma = sigma.into_f32();
    assert!(sigma.iter().all(|s| s.is_finite() && *s >= 0.0) && sigma.iter().any(|s| *s > 0.0));
    let (_, fields) = mesh::io::read_mesh_with_fields(d.join("rom.vtu")).unwrap();
    let at_nodes = fields.iter().find(|f| f.name == "sigma").expect("sigma on the mesh");
    assert_eq!(at_nodes.values.len(), organ.num_nodes());
    assert!(at_nodes.values.iter().all(|s| s.is_finite() && *s >= 0.0), "{:?}", &at_nodes.values[..5]);
    // A tensor named as one of the model's own files is refused, the model left as it was.
    let basis = std::fs::read(d.join("rom/basis.npy")).unwrap();
    let e = augsim_err(&["predict", "rom", "cloud.csv", "-o", "no_folder/../rom/basis.npy", "--runs", "1"], d);
    assert!(e.contains("would be written over") && e.contains("basis.npy"), "{e}");
    assert_eq!(std::fs::read(d.join("rom/basis.npy")).unwrap(), basis, "the model's basis is left as it was");
    // Projected on a basis fitted on the same split, the U-Net is evaluated; on one fitted or chosen
    // on its test samples, it is not (the basis would hold them).
    let text = augsim(&["eval", "net/model.json", "data", "--project", "rom", "--out", "eval_projected"], d);
    assert!(text.contains("projected  on the basis of rom"), "{text}");
    // The summary tells a projected figure from a plain one.
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("eval_projected/summary.json")).unwrap()).unwrap();
    assert_eq!(summary["projection"]["basis"], "rom", "{summary}");
    assert!(summary["projection"]["modes"].as_u64().is_some_and(|m| m >= 1), "{summary}");
    let summary = std::fs::read_to_string(d.join("eval/summary.json")).unwrap();
    assert!(summary.contains("\"projection\": null"), "{summary}");
    augsim(&["train", "data", "--out", "rom_other", "--method", "rom", "--test-samples", "1"], d);
    let e = augsim_err(&["eval", "net/model.json", "data", "--project", "rom_other"], d);
    assert!(e.contains("was used to select (validate) the projection's basis (a reduced-order model)"), "{e}");

    // burn's own kernels (the GPU's code path) predict the same tensor; they and the GPU need their
    // features.
    let burn_args =
        ["predict", "net/model.json", "cloud.csv", "-o", "pred_burn.npy", "--runs", "1", "--device", "cpu-burn"];
    if cfg!(feature = "cpu-burn") {
        let text = augsim(&burn_args, d);
        assert!(text.contains("device     cpu (burn flex)"), "{text}");
        let read = |name: &str| mesh::io::npy::read_npy(&d.join(name)).unwrap().into_f32();
        let (repacked, burn) = (read("pred.npy"), read("pred_burn.npy"));
        let scale = repacked.iter().fold(0f32, |m, v| m.max(v.abs()));
        let diff = repacked.iter().zip(&burn).fold(0f32, |m, (a, b)| m.max((a - b).abs()));
        assert!(scale > 0.0 && diff <= 1e-5 * scale, "cpu-burn differs by {diff:e} (scale {scale:e})");
    } else {
        let e = augsim_err(&burn_args, d);
        assert!(e.contains("without burn's CPU engine") && e.contains("--features cpu-burn"), "{e}");
    }
    if cfg!(not(feature = "gpu")) {
        let e = augsim_err(&["predict", "net/model.json", "cloud.csv", "--device", "gpu"], d);
        assert!(e.contains("built without GPU support") && e.contains("--features gpu"), "{e}");
    }
    let e = augsim_err(&["eval", "net/model.json", "data", "--device", "tpu"], d);
    assert!(e.contains("expected `cpu`, `gpu` or `cpu-burn`"), "{e}");
    // A reduced-order model is not written over a U-Net's folder (their files would mix).
    let e = augsim_err(&["train", "data", "--out", "net", "--method", "rom"], d);
    assert!(e.contains("net holds a U-Net (model.safetensors): a reduced-order model written there"), "{e}");
    // Nor a model over a dataset, a dataset over a model, or a fit over another fit.
    let e = augsim_err(&["train", "data", "--out", "data", "--method", "rom"], d);
    assert!(e.contains("data holds a dataset (manifest.json): a model written there"), "{e}");
    let e = augsim_err(&["generate", "tiny.toml", "--out", "net"], d);
    assert!(e.contains("net holds a model (model.json): a dataset written there"), "{e}");
    // Nor over a training in PyTorch, which resumes from its own checkpoint.
    std::fs::create_dir_all(d.join("torch")).unwrap();
    std::fs::write(d.join("torch/checkpoint.pt"), "a PyTorch checkpoint").unwrap();
    let e = augsim_err(&["train", "data", "--out", "torch"], d);
    assert!(e.contains("torch holds a training in PyTorch (checkpoint.pt)"), "{e}");
    // A rerun without --samples keeps the count the dataset was made for, not the scenario's 6.
    augsim(&["generate", "tiny.toml", "--out", "three", "--samples", "3"], d);
    let text = augsim(&["generate", "tiny.toml", "--out", "three"], d);
    assert!(text.contains("samples    3, the count three was made for (--samples grows it)"), "{text}");
    let manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("three/manifest.json")).unwrap()).unwrap();
    assert_eq!(manifest["num_samples"].as_u64().unwrap() + manifest["failed"].as_array().unwrap().len() as u64, 3);
    // A folder of other files is no place for a new dataset: refused, its files left as they were.
    std::fs::create_dir_all(d.join("notes/shard_00000")).unwrap();
    std::fs::write(d.join("notes/shard_00000/inputs.npy"), "mine").unwrap();
    let e = augsim_err(&["generate", "tiny.toml", "--out", "notes"], d);
    assert!(e.contains("notes holds other files (shard_00000) and no dataset: give a new or empty folder"), "{e}");
    assert_eq!(std::fs::read_to_string(d.join("notes/shard_00000/inputs.npy")).unwrap(), "mine");
    // A U-Net's settings are checked before its dataset is read (and split).
    let out = Command::new(env!("CARGO_BIN_EXE_augsim"))
        .args(["train", "data", "--out", "zero", "--iterations", "0"])
        .current_dir(d)
        .output()
        .unwrap();
    let (said, e) = (String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    assert!(!out.status.success() && e.contains("must be at least 1") && !said.contains("split"), "{said}{e}");
    // Loads no draw survives: an error, not a dataset of no sample said to be written.
    let heavy = std::fs::read_to_string(d.join("tiny.toml")).unwrap().replace("[0.05, 0.2]", "[500.0, 600.0]");
    std::fs::write(d.join("heavy.toml"), heavy.replace("samples = 6", "samples = 2")).unwrap();
    let e = augsim_err(&["generate", "heavy.toml", "--out", "heavy"], d);
    assert!(e.contains("every one of its 2 draws failed, so heavy holds no sample (the first: "), "{e}");
    let e = augsim_err(&["train", "heavy", "--out", "nothing", "--method", "rom"], d);
    assert!(e.contains("heavy holds no sample (its 2 draws all failed: reasons in its manifest)"), "{e}");
    // A grid with no node inside the organ would hold no target: refused before any draw.
    let coarse = std::fs::read_to_string(d.join("tiny.toml")).unwrap().replace("[9, 10, 9]", "[2, 2, 2]");
    std::fs::write(d.join("coarse.toml"), coarse).unwrap();
    let e = augsim_err(&["generate", "coarse.toml", "--out", "coarse"], d);
    assert!(e.contains("no node of its [dataset] grid = [2, 2, 2] lies inside the organ"), "{e}");
    assert!(!d.join("coarse").exists());
    // A reduced-order model runs on no device: --device is refused as the U-Net's other options are.
    let e = augsim_err(&["train", "data", "--out", "rom_gpu", "--method", "rom", "--device", "cpu-burn"], d);
    assert!(e.contains("--device is a U-Net's"), "{e}");
    std::fs::create_dir_all(d.join("fitted")).unwrap();
    std::fs::write(d.join("fitted/model.json"), "{}").unwrap();
    let e = augsim_err(&["train", "data", "--out", "fitted", "--method", "rom"], d);
    assert!(e.contains("fitted holds a model (model.json): a new fit written there would replace"), "{e}");
    // A network fine-tuned from another keeps its architecture: another shape asked for is refused,
    // the default one too.
    let e = augsim_err(&["train", "data", "--out", "tuned", "--init", "net", "--channels", "4"], d);
    let kept = "a network fine-tuned from --init keeps the pre-trained one's architecture (2 channels, depth 1)";
    assert!(e.contains(&format!("--channels 4: {kept}")), "{e}");
    let e = augsim_err(&["train", "data", "--out", "tuned", "--init", "net", "--channels", "16", "--depth", "3"], d);
    assert!(e.contains(&format!("--channels 16, --depth 3: {kept}")), "{e}");
    // A patch that keeps every input node is no sparse input: refused, as eval refuses it.
    let e = augsim_err(&["train", "data", "--out", "dense", "--sparse", "500,1000"], d);
    assert!(e.contains("--sparse 500,1000 keeps every input node") && !d.join("dense").exists(), "{e}");
    let e = augsim_err(&["train", "data", "--out", "dense", "--method", "rom", "--sparse", "500,1000"], d);
    assert!(e.contains("--sparse 500,1000 keeps every input node") && !d.join("dense").exists(), "{e}");
    // Without validation samples nothing chooses the weights: said, and no best iteration recorded.
    let no_val = ["--validation-samples", "0", "--test-samples", "2", "--iterations", "2", "--channels", "2"];
    let text = augsim(&[&["train", "data", "--out", "no_val", "--depth", "1"][..], &no_val[..]].concat(), d);
    assert!(text.contains("warning    no validation sample: nothing selects a checkpoint"), "{text}");
    assert!(text.contains("kept       the last iteration's weights"), "{text}");
    let model: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("no_val/model.json")).unwrap()).unwrap();
    assert!(model["training"]["best_iteration"].is_null(), "{}", model["training"]);
    // A network pre-trained on another grid carries over, with a warning that names both grids.
    let shipped = concat!(env!("CARGO_MANIFEST_DIR"), "/../../models/liver_forces");
    let args = ["train", "data", "--out", "other_grid", "--init", shipped, "--iterations", "1", "--test-samples", "2"];
    let text = augsim(&args, d);
    assert!(text.contains("was trained on grid 21x23x21, spacing"), "{text}");
    assert!(text.contains("the dataset is on grid 9x10x9, spacing"), "{text}");
    // A network that cannot be built is refused before its folder is made.
    let e = augsim_err(&["train", "data", "--out", "no_net", "--channels", "0"], d);
    assert!(e.contains("channel counts must be at least 1") && !d.join("no_net").exists(), "{e}");
    // A dataset whose generation was stopped trains, with a warning.
    std::fs::create_dir_all(d.join("unfinished")).unwrap();
    for entry in std::fs::read_dir(d.join("data")).unwrap().flatten() {
        let to = d.join("unfinished").join(entry.file_name());
        match entry.path().is_dir() {
            true => {
                std::fs::create_dir_all(&to).unwrap();
                for file in std::fs::read_dir(entry.path()).unwrap().flatten() {
                    std::fs::copy(file.path(), to.join(file.file_name())).unwrap();
                }
            }
            false => drop(std::fs::copy(entry.path(), to).unwrap()),
        }
    }
    let manifest = std::fs::read_to_string(d.join("unfinished/manifest.json")).unwrap();
    std::fs::write(d.join("unfinished/manifest.json"), manifest.replace("\"complete\": true", "\"complete\": false"))
        .unwrap();
    let text = augsim(&["train", "unfinished", "--out", "rom_unfinished", "--method", "rom", "--test-samples", "1"], d);
    assert!(text.contains("warning    the dataset is unfinished (6 draws held"), "{text}");

    // A point outside the grid, a malformed line and a grid tensor of the wrong shape.
    std::fs::write(d.join("far.csv"), "5,5,5,0,0,1\n").unwrap();
    let e = augsim_err(&["predict", "net/model.json", "far.csv"], d);
    assert!(e.contains("outside the grid box"), "{e}");
    std::fs::write(d.join("bad.csv"), "x,y,z,fx,fy,fz\n0,0,0,1,2\n").unwrap();
    let e = augsim_err(&["predict", "net/model.json", "bad.csv"], d);
    assert!(e.contains("bad.csv:2") && e.contains("expected 6"), "{e}");
    // Vectors named in mm are displacements: not the forces this network takes.
    std::fs::write(d.join("mm.csv"), "x_mm,y_mm,z_mm,ux_mm,uy_mm,uz_mm\n0,0,0,0,0,1\n").unwrap();
    let e = augsim_err(&["predict", "net/model.json", "mm.csv"], d);
    assert!(e.contains("the points' vectors are named in mm, but the model takes forces (N)"), "{e}");
    std::fs::write(d.join("u.csv"), "x,y,z,ux,uy,uz\n0,0,0,0,0,1\n").unwrap();
    let e = augsim_err(&["predict", "net/model.json", "u.csv"], d);
    assert!(e.contains("the points' vectors are named displacements, but the model takes forces (N)"), "{e}");
    let e = augsim_err(&["predict", "net/model.json", "cloud.csv", "--runs", "0"], d);
    assert!(e.contains("'0' for '--runs <RUNS>': expected a count of at least 1, got 0"), "{e}");
}

/// The shipped reduced-order model predicts on the phantom's mesh as the shipped U-Net does: its
/// displacement and its σ interpolated alike to the mesh nodes (a node a fraction of a cell out
/// of the grid's box included); a prediction that fails on its mesh writes nothing.
#[test]
fn the_shipped_rom_predicts_on_the_phantom_mesh() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    augsim(&["mesh", "-o", "organ.vtu"], d);
    std::fs::write(
        d.join("forces.csv"),
        "x,y,z,fx,fy,fz\n0.0097,-0.0701,-0.0136,0,0.5,0\n0.0097,-0.0701,-0.0091,0,0.5,0\n",
    )
    .unwrap();
    let models = concat!(env!("CARGO_MANIFEST_DIR"), "/../../models");
    for model in ["liver_forces", "liver_forces_rom"] {
        let out = format!("{model}.npy");
        let text =
            augsim(&["predict", &format!("{models}/{model}"), "forces.csv", "--mesh", "organ.vtu", "-o", &out], d);
        assert!(text.contains("mesh       "), "{text}");
    }
    let (organ, fields) = mesh::io::read_mesh_with_fields(d.join("liver_forces_rom.vtu")).unwrap();
    let sigma = fields.iter().find(|f| f.name == "sigma").expect("sigma on the mesh");
    assert_eq!(sigma.values.len(), organ.num_nodes());
    assert!(sigma.values.iter().all(|s| s.is_finite() && *s >= 0.0) && sigma.values.iter().any(|s| *s > 0.0));
    let e = augsim_err(
        &["predict", &format!("{models}/liver_forces_rom"), "forces.csv", "--mesh", "no.vtu", "-o", "x.npy"],
        d,
    );
    assert!(e.contains("no.vtu"), "{e}");
    assert!(!d.join("x.npy").exists() && !d.join("x_sigma.npy").exists(), "a failed prediction writes nothing");
    // A tensor named as the mesh would write the mesh's fields over the mesh read, and a tensor
    // named as its σ file over itself: refused, nothing written; an output not .npy, by the parser.
    let rom = format!("{models}/liver_forces_rom");
    let before = std::fs::read(d.join("organ.vtu")).unwrap();
    let e = augsim_err(&["predict", &rom, "forces.csv", "--mesh", "organ.vtu", "-o", "organ.npy"], d);
    assert!(e.contains("organ.vtu would be written over organ.vtu"), "{e}");
    assert_eq!(std::fs::read(d.join("organ.vtu")).unwrap(), before, "the mesh read is left as it was");
    assert!(!d.join("organ.npy").exists() && !d.join("organ_sigma.npy").exists(), "nothing written");
    let cloud = [0.0097f32, -0.0701, -0.0136, 0.0, 0.5, 0.0];
    mesh::io::npy::write_f32(&d.join("p_sigma.npy"), &[1, 6], &cloud).unwrap();
    let e = augsim_err(&["predict", &rom, "p_sigma.npy", "-o", "p.npy"], d);
    assert!(e.contains("p_sigma.npy would be written over p_sigma.npy"), "{e}");
    assert!(!d.join("p.npy").exists(), "nothing written");
    let e = augsim_err(&["predict", &rom, "forces.csv", "--mesh", "organ.vtu", "-o", "pred.vtu"], d);
    assert!(e.contains("expected a file ending in .npy"), "{e}");
}

/// The shipped scenario-1 network (`models/liver_forces`, trained on the built-in
/// `liver_forces_large`): the last ten draws of its scenario, solved anew, are held out from it
/// (the split tests on the last draws); its error on them stays within twice its validation error.
#[test]
fn the_shipped_liver_forces_network_predicts_its_held_out_draws_solved_anew() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let model = concat!(env!("CARGO_MANIFEST_DIR"), "/../../models/liver_forces/model.json");
    augsim(&["generate", "liver_forces_large", "--shard", "199/200", "--out", "draws"], d);
    let text = augsim(&["eval", model, "draws", "--out", "eval"], d);
    let read =
        |path: &Path| -> serde_json::Value { serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap() };
    let summary = read(&d.join("eval/summary.json"));
    let validation = read(Path::new(model))["training"]["best_val_mean_error"].as_f64().unwrap();
    let (samples, mean) = (summary["samples"].as_u64().unwrap(), summary["mean_m"].as_f64().unwrap());
    assert!(samples >= 8, "a few of the ten draws may fail to solve, not most: {text}");
    assert!(mean < 2.0 * validation, "ē {mean} m against a validation ē of {validation} m: {text}");
}
