#!/usr/bin/env python3
"""`python -m augsim.replay`: a recorded press and release (the server test's case, 8 frames, its
clouds in metres as `augsim register --case` writes them) replayed to `augsim serve --units mm` as a
tracker would; each frame comes back registered, the targets written per frame in mm, much nearer
their truth than at rest; a cloud file that cannot be sent (a NaN) is reported and the replay goes on;
a cloud in the other frame is registered, flagged and written under a name that says so.

Run: python -m pytest -s python/tests/test_replay.py (needs pyigtl; `.ci/run` runs it).
"""

import os
import shutil
import subprocess
import tempfile
import unittest

import numpy as np
import pytest

from helpers import augsim_bin, make_case

pytest.importorskip("pyigtl", reason="the replay needs pyigtl: pip install pyigtl (or ./python[test])")

import augsim  # noqa: E402
from augsim import replay  # noqa: E402
from test_serve import free_port  # noqa: E402

FRAMES = 8


class ReplayTest(unittest.TestCase):
    def test_a_recorded_sequence_is_replayed_to_the_server(self):
        with tempfile.TemporaryDirectory(prefix="augsim_replay_test_") as tmp:
            case = make_case(tmp, FRAMES)
            frames = os.path.join(tmp, "case", "clouds")
            # A cloud that cannot be sent (a NaN), recorded between two good ones.
            refused = os.path.join(tmp, "with_nan")
            shutil.copytree(frames, refused)
            bad = np.loadtxt(os.path.join(frames, "cloud_0000.csv"), delimiter=",", skiprows=1)
            bad[0, 0] = np.nan
            np.savetxt(os.path.join(refused, "cloud_0000b.csv"), bad, delimiter=",", header="x,y,z", comments="")
            # A cloud in the other frame (x and y negated): registered, flagged, written under a name that says so.
            mirrored = np.loadtxt(os.path.join(frames, "cloud_0000.csv"), delimiter=",", skiprows=1) * [-1, -1, 1]
            np.savetxt(os.path.join(refused, "cloud_0000c.csv"), mirrored, delimiter=",", header="x,y,z", comments="")
            port = free_port()
            server = subprocess.Popen([augsim_bin(), "serve", "--fem", case["scenario"], "--targets", case["targets"],
                                       "--port", str(port), "--units", "mm"], stdout=subprocess.PIPE,
                                      stderr=subprocess.STDOUT, text=True)
            out = os.path.join(tmp, "targets")
            lines = []
            try:
                client = replay.connect("127.0.0.1", port)
                try:
                    files = replay.frame_files(refused)
                    records = replay.replay(files, client, units="m", rate=0, out=out, report=lines.append)
                finally:
                    client.stop()
            finally:
                server.send_signal(2)
                log, _ = server.communicate(timeout=30)
            self.assertEqual(server.returncode, 0, log)
            written = sorted(os.listdir(out))
            self.assertEqual(written.pop(), "targets_implausible_0002.csv")
            self.assertEqual(len(written), FRAMES, written)
            with open(os.path.join(out, written[0]), encoding="utf-8") as f:
                self.assertEqual(f.readline().strip(), "x_mm,y_mm,z_mm")
            # The targets as the server sent them (float32), written in as many digits as they hold.
            first = np.loadtxt(os.path.join(out, written[0]), delimiter=",", skiprows=1)
            np.testing.assert_array_equal(first.astype(np.float32), records[0]["targets"].astype(np.float32))
        self.assertEqual(len(records), FRAMES + 2)
        self.assertFalse(records.pop(2)["status"]["plausible"], lines[2])
        self.assertIn("not plausible", lines[2])
        self.assertTrue(lines[1].startswith("not sent   cloud_0000b.csv: "), lines[1])
        # Numbered as the server numbers its frames: the file not sent takes no number.
        numbers = [r["status"]["frame"] for k, r in enumerate(records) if k != 1]
        self.assertEqual(numbers, [1] + list(range(3, FRAMES + 2)))
        self.assertEqual(written[-1], f"targets_{FRAMES + 1:04d}.csv")
        self.assertIn("finite", records[1]["status"]["error"])
        self.assertIsNone(records[1]["targets"])
        good = [r for k, r in enumerate(records) if k != 1]
        self.assertTrue(all(r["targets"] is not None for r in good), lines)
        tres = [np.linalg.norm(r["targets"] - truth, axis=1).mean() for r, truth in zip(good, case["truths"])]
        unregistered = [np.linalg.norm(case["rest"] - truth, axis=1).mean() for truth in case["truths"]]
        peak = int(np.argmax(unregistered))
        print(f"\nreplay of {FRAMES} frames: TRE at the peak {tres[peak]:.2f} mm (unregistered "
              f"{unregistered[peak]:.2f} mm); " + "; ".join(lines[:3]))
        self.assertLess(tres[peak], 0.3 * unregistered[peak])

    def test_a_folder_without_clouds_is_a_clear_error(self):
        with tempfile.TemporaryDirectory() as tmp:
            with self.assertRaisesRegex(ValueError, "holds no .csv or .npy cloud"):
                replay.frame_files(tmp)
            with self.assertRaises(SystemExit) as stop:
                replay.main([os.path.join(tmp, "missing")])
            self.assertIn("is not a directory", str(stop.exception))
            # A loop of no pass, a negative rate: refused by the parser (exit status 2), not run once.
            for flags in (["--loop", "0"], ["--rate", "-1"]):
                with self.assertRaises(SystemExit) as stop:
                    replay.main([tmp] + flags)
                self.assertEqual(stop.exception.code, 2, flags)


def test_a_cloud_file_is_read_as_register_reads_it(tmp_path):
    named, plain = tmp_path / "named.csv", tmp_path / "plain.csv"
    named.write_text("x_mm,y_mm,z_mm\n10,20,30\n")
    plain.write_text("x,y,z\n10,20,30\n")
    np.testing.assert_allclose(replay.read_cloud(str(named), "m"), [[0.01, 0.02, 0.03]])
    np.testing.assert_allclose(replay.read_cloud(str(plain), "mm"), [[0.01, 0.02, 0.03]])
    np.testing.assert_allclose(replay.read_cloud(str(plain), "m"), [[10.0, 20.0, 30.0]])
    # Sent in another unit than the files' own.
    np.testing.assert_allclose(replay.read_cloud(str(named), "m", "mm"), [[10.0, 20.0, 30.0]])
    np.testing.assert_allclose(augsim.read_cloud(str(plain), units="mm", file_units="m"), [[1e4, 2e4, 3e4]])
    # Columns found by their names wherever they are; a file that is no cloud is a ValueError
    # saying why, as `augsim register` says it.
    labelled = tmp_path / "labelled.csv"
    labelled.write_text("id,x_mm,y_mm,z_mm\n7,10,20,30\n")
    np.testing.assert_allclose(replay.read_cloud(str(labelled), "m"), [[0.01, 0.02, 0.03]])
    wrong = tmp_path / "wrong.npy"
    np.save(wrong, np.zeros((3, 5)))
    with pytest.raises(ValueError, match=r"expected an array of shape \[N, 3\] \(x, y, z per row\), found \[3, 5\]"):
        replay.read_cloud(str(wrong))
    broken = tmp_path / "broken.csv"
    broken.write_text("x,y,z\n1,2\n")
    with pytest.raises(ValueError, match="broken.csv: line 2: 2 fields, the header has 3 columns"):
        replay.read_cloud(str(broken))
    mixed = tmp_path / "mixed.csv"
    mixed.write_text("x_mm,y_m,z_mm\n10,20,30\n")
    with pytest.raises(ValueError, match="mixed.csv: line 1: the x, y and z columns name different units"):
        replay.read_cloud(str(mixed))
    # A CSV without a header is refused, as `augsim register` refuses it: which column is x?
    headerless = tmp_path / "headerless.csv"
    headerless.write_text("10,20,30\n40,50,60\n")
    with pytest.raises(ValueError, match="headerless.csv: line 1: the header has no 'x' column"):
        replay.read_cloud(str(headerless), "mm")
    strings = tmp_path / "strings.npy"
    np.save(strings, np.array([["a", "b", "c"]]))
    with pytest.raises(ValueError, match="strings.npy: invalid .npy file"):
        replay.read_cloud(str(strings))
    with pytest.raises(ValueError, match="units: must be m, cm, mm or um, got 'in'"):
        augsim.read_cloud(str(plain), units="in")