"""Checks `python -m augsim.train` against augsim: a model it trains is one that augsim reads unchanged.

On a small `augsim generate beam_target` dataset:
- the dataset identity, the split and the normalisation it records are those `augsim train`
  records for the same split options (identity and split exactly, scales to 1e-12);
- a model it trains a few steps is predicted by `augsim predict` as by the PyTorch module
  (max |difference| <= 1e-5 m and <= 1e-5 of the output scale);
- `augsim eval` evaluates it on its recorded test samples only;
- a killed run resumes from its checkpoint to the same weights as an uninterrupted one;
- without validation samples no step is recorded as chosen (`best_iteration` null), as augsim records it;
- augsim refuses its weights once a byte changed (the digest it records), and while one training
  holds the model folder a second, of either trainer, is refused;
- options and datasets it cannot use are refused in one line, before any training.

Run: pip install "./python[torch,test]", then python -m pytest -s python/tests/test_train.py from
the repository root (the augsim binary: $AUGSIM_BIN, default target/release/augsim). Without torch
it is skipped, saying so.
"""

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from helpers import augsim_bin, run_augsim

torch = pytest.importorskip("torch", reason='training with PyTorch needs torch: pip install "./python[torch]"')
from augsim.torch import load, predict, read_safetensors  # noqa: E402
from augsim._augsim import lock_model_folder  # noqa: E402
from augsim.train import main, read_dataset  # noqa: E402

SPLIT = ["--validation-samples", "6", "--test-samples", "10"]


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    path = tmp_path_factory.mktemp("train") / "data"
    run_augsim("generate", "beam_target", "--out", path, "--samples", "40")
    return path


def train(data, out, *extra):
    """Runs `python -m augsim.train` on `data` into `out`; the model.json it wrote."""
    args = [str(data), "--out", str(out), "--channels", "4", "--depth", "2", "--validate-every", "5", "--seed", "3",
            "--device", "cpu", *SPLIT, *extra]
    r = subprocess.run([sys.executable, "-m", "augsim.train", *args], capture_output=True, text=True,
                       cwd=os.path.dirname(out))
    assert r.returncode == 0, f"python -m augsim.train failed:\n{r.stdout}\n{r.stderr}"
    with open(os.path.join(out, "model.json"), encoding="utf-8") as f:
        return json.load(f)


def test_split_and_normalisation_are_augsim_s(data, tmp_path):
    ours = train(data, tmp_path / "py_split", "--iterations", "1")
    out = tmp_path / "augsim_split"
    run_augsim("train", data, "--out", out, "--iterations", "1", "--channels", "4", "--depth", "2", *SPLIT)
    with open(out / "model.json", encoding="utf-8") as f:
        theirs = json.load(f)
    assert ours["training"]["split"] == theirs["training"]["split"]
    for key in ("input_scale", "target_scale"):
        a, b = ours["normalization"][key], theirs["normalization"][key]
        assert abs(a - b) <= 1e-12 * abs(b), key
    for key in ("grid", "placement", "input_unit", "target_unit", "layout", "format", "version"):
        assert ours[key] == theirs[key], key


def test_augsim_predicts_and_evaluates_a_model_trained_here(data, tmp_path):
    out = tmp_path / "py_model"
    info = train(data, out, "--iterations", "20", "--final-lr", "1e-4")
    assert info["training"]["best_iteration"] % 5 == 0
    model = load(out)
    _, _, inputs, _, _ = read_dataset(data)
    x = np.ascontiguousarray(inputs[-1])
    path_in, path_out = tmp_path / "in.npy", tmp_path / "out.npy"
    np.save(path_in, x)
    run_augsim("predict", out / "model.json", path_in, "-o", path_out, "--runs", "1")
    want, got = np.load(path_out), predict(model, x)
    scale = float(np.abs(want).max())
    diff = float(np.abs(got.astype(np.float64) - want).max())
    print(f"\naugsim predict vs PyTorch on the model augsim.train wrote: max |diff| {diff:.3e} m "
          f"(output scale {scale:.3e} m)", file=sys.stderr)
    assert scale > 0.0
    assert diff <= 1e-5
    assert diff <= 1e-5 * scale
    text = run_augsim("eval", out / "model.json", data, "--out", out / "eval")
    assert "held out   10 of 40 samples (the test split recorded in the model)" in text


def test_without_validation_no_step_is_said_to_be_chosen(data, tmp_path, capsys):
    out = tmp_path / "no_validation"
    assert main([str(data), "--out", str(out), "--channels", "4", "--depth", "2", "--iterations", "10",
                 "--validate-every", "5", "--seed", "3", "--device", "cpu",
                 "--validation-samples", "0", "--test-samples", "10"]) == 0
    said = capsys.readouterr().out
    assert "warning    no validation sample: nothing selects a checkpoint" in said
    assert "kept       the last iteration's weights (no validation sample chose them)" in said
    with open(out / "model.json", encoding="utf-8") as f:
        training = json.load(f)["training"]
    assert training["best_iteration"] is None and training["best_val_mean_error"] is None
    assert training["val_samples"] == 0
    # augsim reads it as one of its own trained without validation.
    text = run_augsim("eval", out / "model.json", data, "--out", out / "eval")
    assert "held out   10 of 40 samples" in text


def test_its_weights_are_checked_and_its_folder_held_as_augsim_s(data, tmp_path, capsys):
    out = tmp_path / "held"
    train(data, out, "--iterations", "5")
    # augsim refuses the weights once a byte of them changed (the digest model.json records).
    weights = bytearray((out / "model.safetensors").read_bytes())
    weights[-1] ^= 0x40
    (out / "model.safetensors").write_bytes(bytes(weights))
    r = subprocess.run([augsim_bin(), "eval", str(out / "model.json"),
                        str(data), "--out", str(tmp_path / "eval")], capture_output=True, text=True)
    assert r.returncode != 0 and "is not the weights it describes" in r.stderr, r.stderr
    # While one training holds the folder, a second, of either trainer, is refused.
    folder = lock_model_folder(out)
    with pytest.raises(SystemExit):
        main([str(data), "--out", str(out), "--iterations", "5", "--device", "cpu", *SPLIT])
    assert "is being written by another run" in capsys.readouterr().err
    r = subprocess.run([augsim_bin(), "train", str(data), "--out",
                        str(out), "--iterations", "5", *SPLIT], capture_output=True, text=True)
    assert r.returncode != 0 and "is being written by another run" in r.stderr, r.stderr
    folder.release()
    assert train(data, out, "--iterations", "6")["training"]["iterations"] == 6, "released, the folder is written"
    # A training that fails after taking the folder lets it go (its checkpoint is of another shape),
    # even while its traceback (which holds its frame) lives on.
    with pytest.raises(SystemExit, match="another configuration") as stopped:
        main([str(data), "--out", str(out), "--channels", "2", "--iterations", "7", "--device", "cpu", *SPLIT])
    lock_model_folder(out).release()
    assert stopped.tb is not None


def test_a_resumed_run_ends_where_an_uninterrupted_one_does(data, tmp_path):
    whole = tmp_path / "whole"
    train(data, whole, "--iterations", "10")
    parts = tmp_path / "parts"
    train(data, parts, "--iterations", "5")
    os.remove(parts / "model.json")
    # The same command with more steps continues from the checkpoint of step 5.
    train(data, parts, "--iterations", "10")
    a = read_safetensors(whole / "model.safetensors")
    b = read_safetensors(parts / "model.safetensors")
    assert sorted(a) == sorted(b)
    for name in a:
        np.testing.assert_allclose(a[name], b[name], rtol=0, atol=1e-6, err_msg=name)


def test_what_cannot_be_trained_is_refused_in_one_line(data, tmp_path, capsys):
    out = str(tmp_path / "refused")
    cases = [
        (["--test-samples", "-3"], "--test-samples must be at least 0, got -3"),
        (["--validation-samples", "-1"], "--validation-samples must be at least 0, got -1"),
        (["--depth", "-1"], "--depth must lie in 0..6 (augsim's U-Net), got -1"),
        (["--depth", "7"], "--depth must lie in 0..6 (augsim's U-Net), got 7"),
        (["--train-samples", "0"], "--train-samples must be at least 1, got 0"),
        (["--validation-samples", "30", "--test-samples", "10"], "leave no training sample out of 40"),
        (["--train-samples", "50", *SPLIT], "--train-samples 50: the training split has 24"),
    ]
    missing = str(tmp_path / "missing")
    for extra, message in cases:
        with pytest.raises(SystemExit) as stop:
            main([str(data), "--out", out, "--device", "cpu", *extra])
        assert stop.value.code == 2, extra
        assert message in capsys.readouterr().err, extra
    with pytest.raises(SystemExit):
        main([missing, "--out", out, "--device", "cpu"])
    assert f"{missing}: not a directory; give a dataset directory from `augsim generate`" in capsys.readouterr().err
    if not torch.cuda.is_available():
        with pytest.raises(SystemExit):
            main([str(data), "--out", out, "--device", "cuda"])
        assert "--device cuda: PyTorch" in capsys.readouterr().err
    assert not os.path.exists(out), "nothing is written for a refused run"
