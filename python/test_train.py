#!/usr/bin/env python3
"""Checks python/train.py against augsim: a model it trains is one that augsim reads unchanged.

On a small `augsim generate beam_target` dataset:
- the dataset identity, the split and the normalisation train.py records are those `augsim train`
  records for the same split options (identity and split exactly, scales to 1e-12);
- a model trained a few steps by train.py is predicted by `augsim predict` as by the PyTorch module
  (max |difference| <= 1e-5 m and <= 1e-5 of the output scale);
- `augsim eval` evaluates it on its recorded test samples only;
- a killed run resumes from its checkpoint to the same weights as an uninterrupted one.

Run:  python/.venv/bin/python python/test_train.py -v   (torch and numpy, and the augsim binary:
$AUGSIM_BIN, default target/release/augsim). Fails, never skips, when something is missing.
"""

import json
import os
import subprocess
import sys
import tempfile
import unittest

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)

from test_augsim_unet import IMPORT_ERROR, augsim_bin, run_augsim  # noqa: E402

if IMPORT_ERROR is None:
    import numpy as np
    import augsim_unet
    import train

SPLIT = ["--validation-samples", "6", "--test-samples", "10"]


class TrainTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.tmp = tempfile.TemporaryDirectory(prefix="augsim_train_test_")
        cls.data = os.path.join(cls.tmp.name, "data")
        if IMPORT_ERROR is None:
            run_augsim("generate", "beam_target", "--out", cls.data, "--samples", "40")

    @classmethod
    def tearDownClass(cls):
        cls.tmp.cleanup()

    def setUp(self):
        if IMPORT_ERROR is not None:
            self.fail(IMPORT_ERROR)
        augsim_bin()

    def train_py(self, out, *extra):
        args = [self.data, "--out", out, "--channels", "4", "--depth", "2", "--validate-every", "5", "--seed", "3",
                "--device", "cpu", *SPLIT, *extra]
        r = subprocess.run([sys.executable, os.path.join(HERE, "train.py"), *args], capture_output=True, text=True)
        self.assertEqual(r.returncode, 0, f"train.py failed:\n{r.stdout}\n{r.stderr}")
        with open(os.path.join(out, "model.json"), encoding="utf-8") as f:
            return json.load(f)

    def test_split_and_normalisation_are_augsim_s(self):
        ours = self.train_py(os.path.join(self.tmp.name, "py_split"), "--iterations", "1")
        out = os.path.join(self.tmp.name, "augsim_split")
        run_augsim("train", self.data, "--out", out, "--iterations", "1", "--channels", "4", "--depth", "2", *SPLIT)
        with open(os.path.join(out, "model.json"), encoding="utf-8") as f:
            theirs = json.load(f)
        self.assertEqual(ours["training"]["split"], theirs["training"]["split"])
        for key in ("input_scale", "target_scale"):
            a, b = ours["normalization"][key], theirs["normalization"][key]
            self.assertLessEqual(abs(a - b), 1e-12 * abs(b), key)
        for key in ("grid", "placement", "input_unit", "target_unit", "layout", "format", "version"):
            self.assertEqual(ours[key], theirs[key], key)

    def test_augsim_predicts_and_evaluates_a_model_trained_here(self):
        out = os.path.join(self.tmp.name, "py_model")
        info = self.train_py(out, "--iterations", "20", "--final-lr", "1e-4")
        self.assertEqual(info["training"]["best_iteration"] % 5, 0)
        model = augsim_unet.load(out)
        manifest, _, inputs, _, _ = train.read_dataset(self.data)
        x = np.ascontiguousarray(inputs[-1])
        path_in, path_out = os.path.join(self.tmp.name, "in.npy"), os.path.join(self.tmp.name, "out.npy")
        np.save(path_in, x)
        run_augsim("predict", os.path.join(out, "model.json"), path_in, "-o", path_out, "--runs", "1")
        want, got = np.load(path_out), augsim_unet.predict(model, x)
        scale = float(np.abs(want).max())
        diff = float(np.abs(got.astype(np.float64) - want).max())
        print(f"\naugsim predict vs PyTorch on the model train.py wrote: max |diff| {diff:.3e} m "
              f"(output scale {scale:.3e} m)", file=sys.stderr)
        self.assertGreater(scale, 0.0)
        self.assertLessEqual(diff, 1e-5)
        self.assertLessEqual(diff, 1e-5 * scale)
        text = run_augsim("eval", os.path.join(out, "model.json"), self.data, "--out", os.path.join(out, "eval"))
        self.assertIn("held out   10 of 40 samples (the test split recorded in the model)", text)

    def test_a_resumed_run_ends_where_an_uninterrupted_one_does(self):
        whole = os.path.join(self.tmp.name, "whole")
        self.train_py(whole, "--iterations", "10")
        parts = os.path.join(self.tmp.name, "parts")
        self.train_py(parts, "--iterations", "5")
        os.remove(os.path.join(parts, "model.json"))
        # The same command with more steps continues from the checkpoint of step 5.
        self.train_py(parts, "--iterations", "10")
        a = augsim_unet.read_safetensors(os.path.join(whole, "model.safetensors"))
        b = augsim_unet.read_safetensors(os.path.join(parts, "model.safetensors"))
        self.assertEqual(sorted(a), sorted(b))
        for name in a:
            np.testing.assert_allclose(a[name], b[name], rtol=0, atol=1e-6, err_msg=name)


if __name__ == "__main__":
    unittest.main()
