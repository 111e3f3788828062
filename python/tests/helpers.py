"""What the tests share: the augsim binary they compare with, and the registration case of the
server test (which the package's tests register too).

The augsim binary: $AUGSIM_BIN, default target/release/augsim in the repository
(`cargo build --release -p augsim`). Needs numpy only.
"""

import os
import subprocess

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
LIVER_AR = os.path.join(ROOT, "models", "liver_ar")

# The server test's case: by default the small built-in test case on an 800-T4 model (seconds);
# AUGSIM_STREAM=full makes it the built-in case (truth of about 9,000 T10, 1,500 points per cloud)
# on a 3,000-T4 model.
FULL = os.environ.get("AUGSIM_STREAM") == "full"
CASE = "register_case" if FULL else "register_case_test"
MODEL = f"""kind = "static"
name = "phantom"
[mesh.phantom]
tets = {3000 if FULL else 800}
[material]
law = "corotational"
young = 5000.0
poisson = 0.48
[[fixed]]
select = {{ region = "fixed" }}
"""


def augsim_bin():
    path = os.environ.get("AUGSIM_BIN", os.path.join(ROOT, "target", "release", "augsim"))
    if not (os.path.isfile(path) and os.access(path, os.X_OK)):
        raise AssertionError(f"augsim binary not found at {path}: build it with `cargo build --release -p augsim` "
                             f"in {ROOT}, or point AUGSIM_BIN at one")
    return path


def run_augsim(*args):
    """Runs the augsim binary; its standard output. A failure is an AssertionError with the output."""
    r = subprocess.run([augsim_bin(), *map(str, args)], capture_output=True, text=True)
    if r.returncode != 0:
        raise AssertionError(f"augsim {' '.join(map(str, args))} failed ({r.returncode}):\n{r.stdout}\n{r.stderr}")
    return r.stdout


def read_csv(path):
    return np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)[:, :3]


def make_case(tmp, frames=1):
    """The registration case `CASE` made in `tmp` by `augsim register --case`, in mm: its cloud and
    the targets' truth (of the peak frame), their rest positions, the rest positions as a CSV file,
    the FEM model's scenario file; with `frames` > 1, the press and release's clouds and truths."""
    run_augsim("register", "--case", CASE, "--frames", frames, "--out", tmp)
    made = {name: read_csv(os.path.join(tmp, "case", f"{name}.csv")) * 1e3  # m -> mm
            for name in ("cloud", "truth")}
    made["rest"] = read_csv(os.path.join(tmp, "case", "targets_rest.csv")) * 1e3
    if frames > 1:
        for kind in ("cloud", "truth"):
            folder = os.path.join(tmp, "case", f"{kind}s")
            made[f"{kind}s"] = [read_csv(os.path.join(folder, f)) * 1e3 for f in sorted(os.listdir(folder))]
    made["targets"] = os.path.join(tmp, "targets_mm.csv")
    np.savetxt(made["targets"], made["rest"], delimiter=",", header="x,y,z", comments="")
    made["scenario"] = os.path.join(tmp, "model.toml")
    with open(made["scenario"], "w", encoding="utf-8") as f:
        f.write(MODEL)
    return made
