"""A reduced-order model's directory predicts with NumPy alone, as `learn::rom`'s documentation
writes it, with and without the physics prior: the same field as `augsim predict`."""

import json
import os
import subprocess
import tempfile

import numpy as np

from helpers import augsim_bin

SCENARIO = """kind = "dataset"
name = "box_forces"
[mesh.box]
min = [0.0, 0.0, 0.0]
max = [0.2, 0.1, 0.1]
cells = [8, 4, 4]
element = "tet"
[material]
law = "neo_hookean"
young = 5000.0
poisson = 0.45
[dataset]
samples = 60
seed = 3
shard_size = 60
grid = [11, 6, 6]
fixed = [{ box = { min = [-0.001, -0.001, -0.001], max = [0.001, 0.101, 0.101] } }]
input = "force"
[dataset.load.patch_force]
radius = 0.03
magnitude = [0.0, 0.3]
"""


def numpy_predict(d, x):
    """The lines of the ROM module's documentation."""
    m = json.load(open(f"{d}/model.json"))
    a = lambda n: np.load(f"{d}/{n}.npy")  # noqa: E731
    rom = m["rom"]
    v = x[a("input_mask").astype(bool)] - a("input_mean")
    prior = rom.get("prior") is not None
    r = a("prior") if prior else a("input_components")
    f = a("feature_scales") * (r[: rom["input_components"]] @ v)
    z = a("inducing")
    d2 = ((z - f) ** 2).sum(1) / rom["length_scale"] ** 2
    if rom["kernel"] == "rbf":
        k = np.exp(-0.5 * d2)
    else:
        r = np.sqrt(5 * d2)
        k = (1 + r + r**2 / 3) * np.exp(-r)
    c = k @ a("weights")
    if prior:
        c = c + a("prior")[: rom["modes"]] @ v
    field = np.zeros(x.shape)
    mask = a("output_mask").astype(bool)
    field[:, mask] = (a("output_mean") + c @ a("basis")).reshape(3, -1)
    return field


def test_a_rom_directory_predicts_with_numpy_alone():
    with tempfile.TemporaryDirectory() as tmp:
        scenario = os.path.join(tmp, "box_forces.toml")
        with open(scenario, "w") as f:
            f.write(SCENARIO)
        data = os.path.join(tmp, "data")
        run = lambda *args: subprocess.run([augsim_bin(), *args], check=True, capture_output=True, text=True)  # noqa: E731
        run("generate", scenario, "--out", data)
        shard = sorted(p for p in os.listdir(data) if p.startswith("shard_"))[0]
        x = np.load(os.path.join(data, shard, "inputs.npy"))[-1].astype(np.float64)
        np.save(os.path.join(tmp, "input.npy"), x.astype(np.float32))
        for prior in (False, True):
            model = os.path.join(tmp, f"rom_{prior}")
            run("train", data, "--method", "rom", "-o", model, *(["--prior", scenario] if prior else []))
            assert os.path.exists(os.path.join(model, "prior.npy")) == prior
            out = os.path.join(tmp, f"prediction_{prior}.npy")
            run("predict", model, os.path.join(tmp, "input.npy"), "-o", out, "--runs", "1")
            expected = np.load(out)
            ours = numpy_predict(model, x)
            scale = np.abs(expected).max()
            assert scale > 1e-4
            assert np.abs(ours - expected).max() < 1e-5 * scale, (prior, np.abs(ours - expected).max(), scale)
