#!/usr/bin/env python3
"""Checks that augsim_unet.py reproduces `augsim predict` to 1e-5.

For each model (the shipped models/liver_ar, and tiny models trained here in seconds with other
channel counts and depths on a grid that needs padding), on a dataset sample made by
`augsim generate` and on a deterministic random grid input, `augsim predict` and
augsim_unet.predict must agree: max |difference| <= 1e-5 m (absolute) and
<= 1e-5 * max |augsim output| (relative to the output scale). The measured differences are printed.

Run (no pytest needed):   python/.venv/bin/python python/test_augsim_unet.py
or, with pytest:          python/.venv/bin/python -m pytest -s python
The augsim binary: $AUGSIM_BIN, default target/release/augsim (cargo build --release -p augsim).
Fails, never skips, when torch/numpy or the binary is missing.
"""

import json
import os
import subprocess
import sys
import tempfile
import unittest

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path.insert(0, HERE)

INSTALL = ("install them with: python3 -m venv python/.venv && python/.venv/bin/pip install torch numpy "
           "(see python/README.md), then run this file with python/.venv/bin/python")
try:
    import numpy as np
    import torch
    import augsim_unet
    IMPORT_ERROR = None
except ImportError as e:  # reported as a failure by every test, not a skip
    IMPORT_ERROR = f"cannot import torch/numpy ({e}); {INSTALL}"

TOLERANCE = 1e-5
LIVER_AR = os.path.join(ROOT, "models", "liver_ar")
# Tiny models trained by the tests: (base channels, depth) on the 21 x 6 x 6 beam grid, which
# is padded to 24 x 8 x 8 for depth 2 and 3.
TINY = [(4, 2), (5, 3), (3, 0)]


def augsim_bin():
    path = os.environ.get("AUGSIM_BIN", os.path.join(ROOT, "target", "release", "augsim"))
    if not (os.path.isfile(path) and os.access(path, os.X_OK)):
        raise AssertionError(f"augsim binary not found at {path}: build it with `cargo build --release -p augsim` "
                             f"in {ROOT}, or point AUGSIM_BIN at one")
    return path


def run_augsim(*args):
    r = subprocess.run([augsim_bin(), *map(str, args)], capture_output=True, text=True)
    if r.returncode != 0:
        raise AssertionError(f"augsim {' '.join(map(str, args))} failed ({r.returncode}):\n{r.stdout}\n{r.stderr}")
    return r.stdout


def shard_inputs(dataset_dir):
    """The inputs of a dataset's first shard, [N, 3, nx, ny, nz] float32."""
    with open(os.path.join(dataset_dir, "manifest.json"), encoding="utf-8") as f:
        manifest = json.load(f)
    return np.load(os.path.join(dataset_dir, manifest["shards"][0]["inputs"]))


class State:
    tmp = None
    results = []  # (model, input, max abs diff, max |output|)


def setUpModule():
    if IMPORT_ERROR is None:
        State.tmp = tempfile.TemporaryDirectory(prefix="augsim_unet_test_")


def tearDownModule():
    if State.results:
        print("\nmax |augsim predict - augsim_unet.predict| per model and input:", file=sys.stderr)
        for model, name, diff, scale in State.results:
            print(f"  {model:<22} {name:<14} abs {diff:.3e} m, relative to max|u| {scale:.3e} m: "
                  f"{diff / scale:.3e}", file=sys.stderr)
    if State.tmp is not None:
        State.tmp.cleanup()


class AugsimUNetTest(unittest.TestCase):
    def setUp(self):
        if IMPORT_ERROR is not None:
            self.fail(IMPORT_ERROR)
        augsim_bin()
        self.tmp = State.tmp.name

    def compare(self, label, model_dir, inputs):
        """Runs augsim predict and augsim_unet.predict on each named input; asserts agreement."""
        model = augsim_unet.load(model_dir)
        for name, x in inputs.items():
            x = np.ascontiguousarray(x, dtype=np.float32)
            stem = "".join(c if c.isalnum() else "_" for c in f"{label}_{name}")
            path_in = os.path.join(self.tmp, f"{stem}_in.npy")
            path_out = os.path.join(self.tmp, f"{stem}_out.npy")
            np.save(path_in, x)
            run_augsim("predict", os.path.join(model_dir, "model.json"), path_in, "-o", path_out, "--runs", "1")
            want = np.load(path_out)
            got = augsim_unet.predict(model, x)
            self.assertEqual(got.shape, want.shape)
            self.assertEqual(got.dtype, np.float32)
            scale = float(np.abs(want).max())
            self.assertGreater(scale, 0.0, f"{label}/{name}: augsim predicted all zeros, nothing compared")
            diff = float(np.abs(got.astype(np.float64) - want).max())
            State.results.append((label, name, diff, scale))
            self.assertLessEqual(diff, TOLERANCE, f"{label}/{name}: max abs difference {diff:.3e} m")
            self.assertLessEqual(diff, TOLERANCE * scale,
                                 f"{label}/{name}: max abs difference {diff:.3e} m, output scale {scale:.3e} m")
        return model

    def random_input(self, model, seed):
        rng = np.random.default_rng(seed)
        return (rng.standard_normal((3, *model.grid)) * model.input_scale).astype(np.float32)

    def test_liver_ar(self):
        data = os.path.join(self.tmp, "liver_ar_data")
        run_augsim("generate", "liver_ar", "--out", data, "--samples", "2")
        samples = shard_inputs(data)
        model = augsim_unet.load(LIVER_AR)
        self.assertEqual(model.grid, (24, 24, 16))
        model = self.compare("models/liver_ar", LIVER_AR, {
            "sample 0": samples[0], "sample 1": samples[1], "random": self.random_input(model, 1)})
        # The batch form gives the single predictions (up to rounding: torch picks other kernels).
        batch = augsim_unet.predict(model, samples)
        for i in range(len(samples)):
            single = augsim_unet.predict(model, samples[i])
            self.assertLessEqual(float(np.abs(batch[i] - single).max()), TOLERANCE * float(np.abs(single).max()))

    def test_tiny_models(self):
        data = os.path.join(self.tmp, "beam_data")
        run_augsim("generate", "beam_target", "--out", data, "--samples", "8")
        samples = shard_inputs(data)
        for channels, depth in TINY:
            with self.subTest(channels=channels, depth=depth):
                out = os.path.join(self.tmp, f"tiny_c{channels}_d{depth}")
                run_augsim("train", data, "--out", out, "--iterations", "5", "--batch", "2",
                           "--channels", channels, "--depth", depth, "--validate-every", "5",
                           "--validation-samples", "1", "--test-samples", "2", "--seed", "7")
                model = augsim_unet.load(out)
                self.assertEqual(model.config["base_channels"], channels)
                self.assertEqual(model.config["depth"], depth)
                self.compare(f"tiny c{channels} d{depth}", out,
                             {"sample 7": samples[7], "random": self.random_input(model, depth)})

    def test_command_line(self):
        x = self.random_input(augsim_unet.load(LIVER_AR), 2)
        path_in, path_out, path_py = (os.path.join(self.tmp, f"cli_{n}.npy") for n in ("in", "augsim", "py"))
        np.save(path_in, x)
        run_augsim("predict", os.path.join(LIVER_AR, "model.json"), path_in, "-o", path_out, "--runs", "1")
        r = subprocess.run([sys.executable, os.path.join(HERE, "augsim_unet.py"), LIVER_AR, path_in, path_py],
                           capture_output=True, text=True)
        self.assertEqual(r.returncode, 0, r.stderr)
        want, got = np.load(path_out), np.load(path_py)
        self.assertEqual(got.dtype, np.float32)
        self.assertLessEqual(float(np.abs(got.astype(np.float64) - want).max()), TOLERANCE)

    def test_bad_inputs_are_errors(self):
        model = augsim_unet.load(LIVER_AR)
        with self.assertRaisesRegex(ValueError, "expects"):
            augsim_unet.predict(model, np.zeros((3, 24, 24, 15), np.float32))
        x = np.zeros((3, 24, 24, 16), np.float32)
        x[1, 2, 3, 4] = np.nan
        with self.assertRaisesRegex(ValueError, "non-finite"):
            augsim_unet.predict(model, x)


if __name__ == "__main__":
    unittest.main()
