"""Checks that augsim.torch reproduces `augsim predict` to 1e-5.

For each model (the shipped models/liver_ar, and tiny models trained here in seconds with other
channel counts and depths on a grid that needs padding), on a dataset sample made by
`augsim generate` and on a deterministic random grid input, `augsim predict` and
augsim.torch.predict must agree: max |difference| <= 1e-5 m (absolute) and
<= 1e-5 * max |augsim output| (relative to the output scale). The measured differences are printed.

Run: pip install "./python[torch,test]", then python -m pytest -s python/tests/test_torch.py from
the repository root (the augsim binary: $AUGSIM_BIN, default target/release/augsim). Without torch
it is skipped, saying so.
"""

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from helpers import LIVER_AR, run_augsim

pytest.importorskip("torch", reason='the PyTorch twin needs torch: pip install "./python[torch]"')
from augsim.torch import load, predict  # noqa: E402

TOLERANCE = 1e-5
# Tiny models trained by the tests: (base channels, depth) on the 21 x 6 x 6 beam grid, which
# is padded to 24 x 8 x 8 for depth 2 and 3.
TINY = [(4, 2), (5, 3), (3, 0)]


def shard_inputs(dataset_dir):
    """The inputs of a dataset's first shard, [N, 3, nx, ny, nz] float32."""
    with open(os.path.join(dataset_dir, "manifest.json"), encoding="utf-8") as f:
        manifest = json.load(f)
    return np.load(os.path.join(dataset_dir, manifest["shards"][0]["inputs"]))


@pytest.fixture(scope="module")
def measured():
    """The measured differences (model, input, max abs diff, max |output|), printed at the end."""
    results = []
    yield results
    print("\nmax |augsim predict - augsim.torch.predict| per model and input:", file=sys.stderr)
    for model, name, diff, scale in results:
        print(f"  {model:<22} {name:<14} abs {diff:.3e} m, relative to max|u| {scale:.3e} m: {diff / scale:.3e}",
              file=sys.stderr)


def compare(measured, tmp, label, model_dir, inputs):
    """Runs augsim predict and augsim.torch.predict on each named input; asserts agreement."""
    model = load(model_dir)
    for name, x in inputs.items():
        x = np.ascontiguousarray(x, dtype=np.float32)
        stem = "".join(c if c.isalnum() else "_" for c in f"{label}_{name}")
        path_in, path_out = tmp / f"{stem}_in.npy", tmp / f"{stem}_out.npy"
        np.save(path_in, x)
        run_augsim("predict", os.path.join(model_dir, "model.json"), path_in, "-o", path_out, "--runs", "1")
        want = np.load(path_out)
        got = predict(model, x)
        assert got.shape == want.shape
        assert got.dtype == np.float32
        scale = float(np.abs(want).max())
        assert scale > 0.0, f"{label}/{name}: augsim predicted all zeros, nothing compared"
        diff = float(np.abs(got.astype(np.float64) - want).max())
        measured.append((label, name, diff, scale))
        assert diff <= TOLERANCE, f"{label}/{name}: max abs difference {diff:.3e} m"
        assert diff <= TOLERANCE * scale, f"{label}/{name}: max abs difference {diff:.3e} m, output scale {scale:.3e} m"
    return model


def random_input(model, seed):
    rng = np.random.default_rng(seed)
    return (rng.standard_normal((3, *model.grid)) * model.input_scale).astype(np.float32)


def test_liver_ar(measured, tmp_path):
    data = tmp_path / "liver_ar_data"
    run_augsim("generate", "liver_ar", "--out", data, "--samples", "2")
    samples = shard_inputs(data)
    model = load(LIVER_AR)
    assert model.grid == (24, 24, 16)
    model = compare(measured, tmp_path, "models/liver_ar", LIVER_AR,
                    {"sample 0": samples[0], "sample 1": samples[1], "random": random_input(model, 1)})
    # The batch form gives the single predictions (up to rounding: torch picks other kernels).
    batch = predict(model, samples)
    for i in range(len(samples)):
        single = predict(model, samples[i])
        assert float(np.abs(batch[i] - single).max()) <= TOLERANCE * float(np.abs(single).max())


@pytest.fixture(scope="module")
def beam_data(tmp_path_factory):
    data = tmp_path_factory.mktemp("beam") / "data"
    run_augsim("generate", "beam_target", "--out", data, "--samples", "8")
    return data


@pytest.mark.parametrize("channels,depth", TINY)
def test_tiny_models(measured, tmp_path, beam_data, channels, depth):
    samples = shard_inputs(beam_data)
    out = tmp_path / f"tiny_c{channels}_d{depth}"
    run_augsim("train", beam_data, "--out", out, "--iterations", "5", "--batch", "2", "--channels", channels,
               "--depth", depth, "--validate-every", "5", "--validation-samples", "1", "--test-samples", "2",
               "--seed", "7")
    model = load(out)
    assert model.config["base_channels"] == channels
    assert model.config["depth"] == depth
    compare(measured, tmp_path, f"tiny c{channels} d{depth}", str(out),
            {"sample 7": samples[7], "random": random_input(model, depth)})


def test_command_line(tmp_path):
    x = random_input(load(LIVER_AR), 2)
    path_in, path_out, path_py = (tmp_path / f"cli_{n}.npy" for n in ("in", "augsim", "py"))
    np.save(path_in, x)
    run_augsim("predict", os.path.join(LIVER_AR, "model.json"), path_in, "-o", path_out, "--runs", "1")
    r = subprocess.run([sys.executable, "-m", "augsim.torch", LIVER_AR, str(path_in), str(path_py)],
                       capture_output=True, text=True, cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    want, got = np.load(path_out), np.load(path_py)
    assert got.dtype == np.float32
    assert float(np.abs(got.astype(np.float64) - want).max()) <= TOLERANCE


def test_bad_inputs_are_errors():
    model = load(LIVER_AR)
    with pytest.raises(ValueError, match="expects"):
        predict(model, np.zeros((3, 24, 24, 15), np.float32))
    # Refused as `augsim predict` refuses them, in its words: not finite, or beyond 1e6.
    x = np.zeros((3, 24, 24, 16), np.float32)
    x[1, 2, 3, 4] = np.nan
    with pytest.raises(ValueError, match=r"^prediction input value 10036 is NaN: inputs are finite .* within 1e6$"):
        predict(model, x)
    x[1, 2, 3, 4] = -2e6
    with pytest.raises(ValueError, match=r"^prediction input value 10036 is -2e6: "):
        predict(model, x)
    with pytest.raises(ValueError, match=r"^sample 1: prediction input value 10036 is -2e6: "):
        predict(model, np.stack([np.zeros_like(x), x]))
    x[1, 2, 3, 4] = 1e6
    assert predict(model, x).shape == x.shape
    with pytest.raises(ValueError, match="a point cloud"):
        predict(model, np.zeros((10, 6), np.float32))


@pytest.fixture
def copied_model(tmp_path):
    """A copy of models/liver_ar, and its model.json parsed."""
    out = tmp_path / "model"
    out.mkdir()
    for name in ("model.json", "model.safetensors"):
        (out / name).write_bytes(open(os.path.join(LIVER_AR, name), "rb").read())
    with open(out / "model.json", encoding="utf-8") as f:
        return out, json.load(f)


def test_bad_model_files_are_errors_naming_the_file(copied_model, tmp_path):
    out, info = copied_model
    info["normalization"]["input_scale"] = 0
    (out / "model.json").write_text(json.dumps(info))
    with pytest.raises(ValueError, match=r"model\.json: normalization input_scale must be finite and > 0, got 0$"):
        load(out)
    (out / "model.json").write_text('{"format": "augsim-unet",')
    with pytest.raises(ValueError, match=r"model\.json: invalid model JSON: "):
        load(out)
    with pytest.raises(ValueError, match=r"model\.safetensors: .*give the model directory or its model\.json"):
        load(os.path.join(LIVER_AR, "model.safetensors"))
    with pytest.raises(FileNotFoundError, match="give the model directory or its model.json"):
        load(tmp_path / "missing")


def test_command_line_errors_are_one_line(tmp_path, capsys):
    cloud = tmp_path / "cloud.npy"
    np.save(cloud, np.zeros((10, 6), np.float32))
    out = str(tmp_path / "out.npy")
    from augsim.torch import main
    for argv, message in [([str(tmp_path / "missing"), str(cloud), out], "missing: no such file"),
                          ([LIVER_AR, str(cloud), out], "cloud.npy: input shape (10, 6)"),
                          ([LIVER_AR, os.path.join(LIVER_AR, "model.json"), out], "model.json: not a .npy file")]:
        assert main(argv) == 1
        err = capsys.readouterr().err
        assert err.startswith("error: ") and message in err and err.count("\n") == 1, err
    assert not os.path.exists(out)
