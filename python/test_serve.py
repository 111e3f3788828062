#!/usr/bin/env python3
"""`augsim serve` driven by pyigtl, the Python OpenIGTLink client used with 3D Slicer.

A small stream: the built-in `register_case_test` case (a Neo-Hookean phantom of 2,000 T4 pushed
down, seen from above; its truth from another mesh and law than the model) is made by
`augsim register --case`; `augsim serve` registers it with a co-rotational FEM of the 800-T4
phantom; pyigtl sends the case's cloud in millimetres as POINT messages, each frame with fresh
0.5 mm noise, and reads the registered targets (POINT) and the status (STRING JSON). It checks
every frame is answered in order with a target registration error well below the unregistered
one, that a cloud with a NaN gets an error status while the stream goes on, and prints the
latency (send to status, median and p95), the sustained frame rate and the TRE per frame. With
`--rigid`, the same cloud moved by a few centimetres comes back as a TRANSFORM `rigid` and targets
in the cloud's frame.

Run: python3 -m venv .venv && .venv/bin/pip install pyigtl numpy && .venv/bin/python python/test_serve.py
The augsim binary: $AUGSIM_BIN, default target/release/augsim. `.ci/run` runs it.
"""

import json
import os
import socket
import subprocess
import sys
import tempfile
import time
import unittest

import numpy as np
import pyigtl

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from test_augsim_unet import augsim_bin  # noqa: E402  (needs no torch)
FRAMES = 12
MODEL = """kind = "static"
name = "phantom_800"
[mesh.phantom]
tets = 800
[material]
law = "corotational"
young = 5000.0
poisson = 0.48
[[fixed]]
select = { region = "fixed" }
"""


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def read_csv(path):
    return np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)[:, :3]


def make_case(tmp):
    """The `register_case_test` case made in `tmp` by `augsim register --case`, in mm: its cloud,
    the targets' truth and rest positions, the rest positions as a CSV file and the FEM model's
    scenario file."""
    r = subprocess.run([augsim_bin(), "register", "--case", "register_case_test", "--out", str(tmp)],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stdout + r.stderr
    case = {name: read_csv(os.path.join(tmp, "case", f"{name}.csv")) * 1e3  # m -> mm
            for name in ("cloud", "truth")}
    case["rest"] = read_csv(os.path.join(tmp, "case", "targets_rest.csv")) * 1e3
    case["targets"] = os.path.join(tmp, "targets_mm.csv")
    np.savetxt(case["targets"], case["rest"], delimiter=",", header="x,y,z", comments="")
    case["scenario"] = os.path.join(tmp, "model.toml")
    with open(case["scenario"], "w", encoding="utf-8") as f:
        f.write(MODEL)
    return case


def connected(test, port):
    """A pyigtl client connected to the server on `port`."""
    client = pyigtl.OpenIGTLinkClient(host="127.0.0.1", port=port)
    deadline = time.time() + 30
    while not client.is_connected() and time.time() < deadline:
        time.sleep(0.05)
    test.assertTrue(client.is_connected(), "pyigtl could not connect")
    return client


class ServeTest(unittest.TestCase):
    def serve(self, tmp, options, exchange):
        """Makes the case in `tmp`, starts `augsim serve` on it with `options` and runs
        `exchange(port, cloud, truth, rest)` (mm), then stops the server with SIGINT."""
        case = make_case(tmp)
        cloud, truth, rest, targets, scenario = (case[k] for k in ("cloud", "truth", "rest", "targets", "scenario"))
        port = free_port()
        server = subprocess.Popen([augsim_bin(), "serve", "--fem", scenario, "--targets", targets, "--port",
                                   str(port)] + options, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        try:
            exchange(port, cloud, truth, rest)
        finally:
            server.send_signal(2)  # SIGINT: a clean stop
            out, _ = server.communicate(timeout=30)
        self.assertEqual(server.returncode, 0, out)
        self.assertIn("stopped", out)

    def test_a_stream_from_pyigtl(self):
        with tempfile.TemporaryDirectory(prefix="augsim_serve_test_") as tmp:
            self.serve(tmp, ["--outputs", "targets,status"], self.stream)

    def test_a_rigid_pre_alignment_answers_a_transform(self):
        with tempfile.TemporaryDirectory(prefix="augsim_serve_test_") as tmp:
            self.serve(tmp, ["--rigid", "--outputs", "targets,transform,status"], self.shifted)

    def shifted(self, port, cloud, truth, rest):
        """The cloud moved by a few centimetres: the TRANSFORM `rigid` holds the move (up to what of
        the push the rigid fit of a deformed, partial surface takes: within 1 cm), and the targets
        come back in the cloud's frame."""
        client = connected(self, port)
        shift = np.array([20.0, -15.0, 10.0])
        try:
            client.send_message(pyigtl.PointMessage(positions=(cloud + shift).astype(np.float32),
                                                    device_name="cloud"), wait=True)
            targets = client.wait_for_message("targets", timeout=60)
            transform = client.wait_for_message("rigid", timeout=60)
            status = json.loads(client.wait_for_message("status", timeout=60).string)
        finally:
            client.stop()
        self.assertIsNotNone(targets)
        self.assertIsNotNone(transform)
        matrix = np.asarray(transform.matrix)
        moved = np.linalg.norm(matrix[:3, 3] - shift)
        tre = np.linalg.norm(np.asarray(targets.positions) - (truth + shift), axis=1).mean()
        unregistered = np.linalg.norm(rest - (truth + shift), axis=1).mean()
        print(f"\nrigid: translation {np.round(matrix[:3, 3], 2)} mm for a move of {shift} mm; TRE {tre:.2f} mm "
              f"(unregistered {unregistered:.2f} mm); {status['ms']:.0f} ms", file=sys.stderr)
        self.assertLess(moved, 10.0)
        self.assertLess(tre, 0.3 * unregistered)

    def stream(self, port, cloud, truth, rest):
        client = connected(self, port)
        rng = np.random.default_rng(1)
        unregistered = np.linalg.norm(rest - truth, axis=1).mean()
        latencies, tres, server_ms = [], [], []
        began = time.perf_counter()
        try:
            for frame in range(1, FRAMES + 1):
                noisy = cloud + rng.normal(0.0, 0.5, cloud.shape)
                sent = time.perf_counter()
                client.send_message(pyigtl.PointMessage(positions=noisy.astype(np.float32), device_name="cloud"),
                                    wait=True)
                targets = client.wait_for_message("targets", timeout=30)
                status = client.wait_for_message("status", timeout=30)
                latencies.append((time.perf_counter() - sent) * 1e3)
                self.assertIsNotNone(targets, f"frame {frame}: no targets")
                self.assertIsNotNone(status, f"frame {frame}: no status")
                s = json.loads(status.string)
                self.assertEqual(s["frame"], frame, s)
                server_ms.append(s["ms"])
                tres.append(float(np.linalg.norm(np.asarray(targets.positions) - truth, axis=1).mean()))
            rate = FRAMES / (time.perf_counter() - began)
            # A cloud with a NaN: an error status, then the stream goes on.
            bad = cloud.copy()
            bad[0, 0] = np.nan
            client.send_message(pyigtl.PointMessage(positions=bad.astype(np.float32), device_name="cloud"), wait=True)
            s = json.loads(client.wait_for_message("status", timeout=30).string)
            self.assertEqual(s["frame"], FRAMES + 1, s)
            self.assertIn("finite", s["error"])
            client.send_message(pyigtl.PointMessage(positions=cloud.astype(np.float32), device_name="cloud"),
                                wait=True)
            self.assertIsNotNone(client.wait_for_message("targets", timeout=30))
            self.assertEqual(json.loads(client.wait_for_message("status", timeout=30).string)["frame"], FRAMES + 2)
        finally:
            client.stop()
        print(f"\n{FRAMES} frames of {len(cloud)} points: latency median {np.median(latencies):.1f} ms, "
              f"p95 {np.percentile(latencies, 95):.1f} ms; server {np.median(server_ms):.1f} ms per frame (median), "
              f"first {server_ms[0]:.1f} ms; {rate:.1f} frames/s sustained; TRE per frame "
              f"{', '.join(f'{t:.2f}' for t in tres)} mm (unregistered {unregistered:.2f} mm)", file=sys.stderr)
        self.assertLess(max(tres), 0.3 * unregistered)


if __name__ == "__main__":
    unittest.main()
