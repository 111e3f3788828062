"""Tests of the `augsim` Python package (pip install ./python): each call against the command
line's result or a known figure, the warm start between clouds, and the errors.

Run: pytest -s python/tests (the augsim binary: $AUGSIM_BIN, default target/release/augsim;
`.ci/run` runs them).
"""

import _thread
import importlib.util
import multiprocessing
import os
import pickle
import re
import signal
import subprocess
import sys
import threading
import time
import warnings
from concurrent.futures import ProcessPoolExecutor

import numpy as np
import pytest

import augsim
from helpers import LIVER_AR, ROOT, make_case, run_augsim

BEAM_ASSIMILATION = os.path.join(ROOT, "crates", "app", "tests", "data", "beam_assimilation.toml")


def test_a_solve_s_warnings_are_python_warnings(tmp_path):
    # A bar pulled to four times its length, far beyond soft tissue: warned of as the command line does.
    scenario = tmp_path / "pull.toml"
    scenario.write_text(
        'kind = "static"\nname = "pull"\n[mesh.box]\nmin = [0.0, 0.0, 0.0]\nmax = [0.04, 0.01, 0.01]\n'
        'cells = [4, 1, 1]\nelement = "hex"\n[material]\nlaw = "neo_hookean"\nyoung = 5000.0\npoisson = 0.3\n'
        "[[fixed]]\nselect = { box = { min = [-1.0, -1.0, -1.0], max = [1e-9, 1.0, 1.0] } }\n"
        "[[prescribed]]\nselect = { box = { min = [0.04, -1.0, -1.0], max = [1.0, 1.0, 1.0] } }\n"
        "displacement = [0.12, 0.0, 0.0]\n"
    )
    with pytest.warns(augsim.AugsimWarning, match="far beyond what soft tissue bears"):
        augsim.solve(str(scenario))


def test_solve_beam_matches_the_command_line(tmp_path):
    s = augsim.solve("beam")
    assert s.points.shape == s.displacement.shape == (6 * 6 * 21, 3)
    assert s.points.dtype == s.displacement.dtype == np.float64
    out = run_augsim("solve", "beam", "-o", str(tmp_path / "beam.vtu"))
    line = next(l for l in out.splitlines() if l.startswith("max |u|"))
    cli_max = float(line.split()[2])
    norms = np.linalg.norm(s.displacement, axis=1)
    assert norms.max() == pytest.approx(cli_max, rel=1e-4)
    assert s.max_displacement == pytest.approx(norms.max())
    assert f"solver     {s.iterations} iterations" in out
    # Fixed on its bottom face up to x = 1 m, pulled down at x = 4 m: the tip sinks.
    fixed = (s.points[:, 0] <= 1.0) & (s.points[:, 2] < 0.01)
    assert fixed.sum() == 6 * 6 and np.abs(s.displacement[fixed]).max() == 0.0
    # The held nodes take the pull: their reaction forces balance it, as the command line says.
    assert s.reaction_force.shape == s.points.shape and np.abs(s.reaction_force[~fixed]).max() == 0.0
    reaction = next(l for l in out.splitlines() if l.startswith("reaction"))
    held, loads = reaction.split("held nodes (")[1].split(")")[0], reaction.split("the loads: (")[1].split(")")[0]
    held, loads = np.array(held.split(", "), float), np.array(loads.split(", "), float)
    # (The command line prints 5 significant digits.)
    assert s.reaction_force.sum(axis=0) == pytest.approx(held, abs=1e-4 * np.abs(loads).max())
    assert held == pytest.approx(-loads, abs=1e-3 * np.abs(loads).max())
    tip = s.points[:, 0] > 4.0 - 1e-9
    assert (s.displacement[tip, 2] < -0.45).all()
    # Converged: a relative residual under rtol (1e-6), or a last increment under utol at one under
    # its square root.
    assert 0 < s.residual <= 1e-3 and s.load_steps >= 1
    assert repr(s).startswith(f"Solution(nodes={6 * 6 * 21}, iterations={s.iterations}, load_steps={s.load_steps}, ")


@pytest.fixture(scope="module")
def case(tmp_path_factory):
    """The server test's case: register_case_test made by `augsim register --case`, in mm."""
    return make_case(tmp_path_factory.mktemp("case"))


def test_registration_reduces_the_tre_with_a_warm_start(case):
    reg = augsim.Registration(fem=case["scenario"], targets=case["targets"], units="mm")
    assert reg.units == "mm" and reg.method.startswith("FEM, co-rotational")
    np.testing.assert_allclose(reg.targets, case["rest"], atol=1e-9)
    unregistered = np.linalg.norm(case["rest"] - case["truth"], axis=1).mean()
    rng = np.random.default_rng(1)
    frames = [reg.register(case["cloud"] + rng.normal(0.0, 0.5, case["cloud"].shape)) for _ in range(4)]
    tres = [np.linalg.norm(f.targets - case["truth"], axis=1).mean() for f in frames]
    print(f"\nTRE per frame {', '.join(f'{t:.2f}' for t in tres)} mm (unregistered {unregistered:.2f} mm); "
          f"iterations {[f.iterations for f in frames]}, {[round(f.ms, 1) for f in frames]} ms", file=sys.stderr)
    assert max(tres) < 0.3 * unregistered
    first = frames[0]
    assert first.targets.shape == case["rest"].shape
    assert first.displacement.shape == reg.points.shape
    assert first.points == len(case["cloud"]) and 0 < first.inliers <= first.points
    assert 0 < first.surface_residual < 2.0  # mm
    assert repr(first).startswith(f"Registered(targets={len(case['rest'])}, iterations={first.iterations}, "
                                  "from_rest=True, ")
    assert repr(frames[1]).count("from_rest=False") == 1
    assert repr(reg) == (f"Registration(method='{reg.method}', units='mm', frame=None, nodes={len(reg.points)}, "
                         f"targets={len(case['rest'])})")
    # Its fields as a dict, which pickles (a worker process returns it).
    fields = pickle.loads(pickle.dumps(first.to_dict()))
    np.testing.assert_array_equal(fields["targets"], first.targets)
    assert (fields["from_rest"], fields["iterations"], fields["rigid"]) == (True, first.iterations, None)
    with pytest.raises(TypeError):
        pickle.dumps(first)
    # The warm start: after those frames the noiseless cloud registers otherwise (measured: 0.85 mm
    # apart) than from rest, as a new Registration does; after reset() it registers from rest
    # again (measured: 0.06 mm apart, the FEM solver keeping its factorisation).
    warm = reg.register(case["cloud"])
    reg.reset()
    again = reg.register(case["cloud"])
    assert (first.from_rest, warm.from_rest, again.from_rest) == (True, False, True)
    fresh = augsim.Registration(fem=case["scenario"], targets=case["targets"], units="mm").register(case["cloud"])
    warm_gap, reset_gap = (np.abs(r.targets - fresh.targets).max() for r in (warm, again))
    print(f"warm vs fresh {warm_gap:.3f} mm, reset vs fresh {reset_gap:.3f} mm", file=sys.stderr)
    assert warm_gap > 0.3 and reset_gap < 0.25 * warm_gap


def _solve_the_beam(_):
    try:
        augsim.solve("beam")
        return "solved"
    except augsim.AugsimError as e:
        return str(e)


@pytest.mark.skipif(not hasattr(os, "fork"), reason="no fork on this platform")
def test_a_forked_worker_is_told_to_spawn_rather_than_wait_forever():
    """A process forked from one that computed lacks augsim's worker threads: it raises, naming
    "spawn", instead of waiting for them forever; a spawned worker computes."""
    augsim.solve("beam")
    for method, expected in [("fork", "start worker processes with \"spawn\""), ("spawn", "solved")]:
        with ProcessPoolExecutor(1, mp_context=multiprocessing.get_context(method)) as pool:
            assert expected in pool.submit(_solve_the_beam, 0).result(timeout=120), method


def test_registration_with_default_targets_in_metres(case):
    reg = augsim.Registration(fem=case["scenario"], targets=case["rest"] * 1e-3)
    r = reg.register(case["cloud"] * 1e-3)
    assert np.linalg.norm(r.targets * 1e3 - case["truth"], axis=1).mean() < 0.3 * np.linalg.norm(
        case["rest"] - case["truth"], axis=1).mean()


def test_registration_with_the_unet(case):
    reg = augsim.Registration(model=LIVER_AR, scenario="liver_ar_t10", targets=case["rest"], units="mm")
    assert reg.method.startswith("U-Net")
    r = reg.register(case["cloud"])
    unregistered = np.linalg.norm(case["rest"] - case["truth"], axis=1).mean()
    assert np.linalg.norm(r.targets - case["truth"], axis=1).mean() < 0.5 * unregistered


def test_registration_with_the_unet_after_the_rom_s_shape_fit(case):
    rom = os.path.join(ROOT, "models", "liver_ar_rom")
    reg = augsim.Registration(model=LIVER_AR, scenario="liver_ar_t10", shape_model=rom, targets=case["rest"],
                              units="mm")
    assert reg.method.startswith("U-Net") and "after the shape fit of ROM" in reg.method
    r = reg.register(case["cloud"])
    unregistered = np.linalg.norm(case["rest"] - case["truth"], axis=1).mean()
    assert np.linalg.norm(r.targets - case["truth"], axis=1).mean() < 0.5 * unregistered
    with pytest.raises(ValueError, match="give --model MODEL"):
        augsim.Registration(fem=case["scenario"], shape_model=rom)


def test_a_rigid_pre_alignment_answers_in_the_clouds_frame(case):
    shift = np.array([20.0, -15.0, 10.0])
    reg = augsim.Registration(fem=case["scenario"], targets=case["targets"], units="mm", rigid=True)
    r = reg.register(case["cloud"] + shift)
    assert r.rigid.shape == (4, 4) and np.allclose(r.rigid[3], [0.0, 0.0, 0.0, 1.0])
    # The rigid fit of a deformed partial surface takes part of the push: within 1 cm of the move.
    assert np.linalg.norm(r.rigid[:3, 3] - shift) < 10.0
    unregistered = np.linalg.norm(case["rest"] - (case["truth"] + shift), axis=1).mean()
    assert np.linalg.norm(r.targets - (case["truth"] + shift), axis=1).mean() < 0.3 * unregistered


def test_registration_errors(case, tmp_path):
    reg = augsim.Registration(fem=case["scenario"], targets=case["targets"], units="mm")
    bad = case["cloud"].copy()
    bad[0, 0] = np.nan
    with pytest.raises(augsim.AugsimError, match="finite"):
        reg.register(bad)
    with pytest.raises(ValueError, match=r"shape \[N, 3\]"):
        reg.register(case["cloud"][:, :2])
    with pytest.raises(augsim.AugsimError):
        reg.register(np.zeros((0, 3)))
    # A damaged coordinate is quoted in the caller's unit.
    far = case["cloud"].copy()
    far[5, 1] = 1e300
    with pytest.raises(augsim.AugsimError, match=r"cloud point 5 lies at \[.*, 1e300, .*\]: a coordinate beyond 1e6"):
        reg.register(far)
    with pytest.raises(TypeError, match="cloud is None: an array of numbers is expected"):
        reg.register(None)
    # NumPy would cast complex numbers and booleans silently.
    with pytest.raises(ValueError, match="cloud holds complex numbers: real numbers are expected"):
        reg.register(case["cloud"].astype(complex))
    with pytest.raises(ValueError, match="cloud holds booleans"):
        reg.register(case["cloud"] > 0)
    with pytest.raises(ValueError, match="iterations = -1 must be at least 1"):
        augsim.Registration(fem=case["scenario"], units="mm", iterations=-1)
    with pytest.raises(ValueError, match="targets: the array holds no point"):
        augsim.Registration(fem=case["scenario"], targets=np.zeros((0, 3)), units="mm")
    # A cloud in metres where millimetres are expected, or in micrometres: refused, saying why.
    with pytest.raises(augsim.AugsimError, match="too small"):
        reg.register(case["cloud"] * 1e-3)
    with pytest.raises(augsim.AugsimError, match="millimetres"):
        reg.register(case["cloud"] * 1e3)
    # The registration goes on after an error.
    good = reg.register(case["cloud"])
    assert good.iterations > 0 and good.warnings == [] and good.rigid is None
    missing = str(tmp_path / "missing.toml")
    with pytest.raises(augsim.AugsimError, match="missing.toml"):
        augsim.Registration(fem=missing)
    with pytest.raises(ValueError, match="units: must be m, cm, mm or um, got 'in'"):
        augsim.Registration(fem=case["scenario"], units="in")
    with pytest.raises(ValueError, match="fem SCENARIO"):
        augsim.Registration(model=LIVER_AR)
    with pytest.raises(augsim.AugsimError, match="target"):
        augsim.Registration(fem=case["scenario"], targets=[[10.0, 10.0, 10.0]])  # 10 m: outside the organ


def test_the_package_says_its_version():
    # The installed distribution's, which the crate's version makes.
    assert augsim.__version__.count(".") == 2 and augsim.__version__[0].isdigit(), augsim.__version__


def test_a_time_budget_ends_a_cloud_with_its_estimate(case):
    # A budget far below one FEM solve: the cloud answers with the estimate reached, saying why.
    reg = augsim.Registration(fem=case["scenario"], targets=case["targets"], units="mm", time_budget_ms=1e-3)
    # A result that may not be believed is said as a Python warning too, of augsim's own class;
    # running out of time alone does not make it so.
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        r = reg.register(case["cloud"])
    assert any("past its time budget of 0 ms" in w for w in r.warnings), r.warnings
    doubted = [w for w in caught if "may not be believed: its result's `warnings` say why" in str(w.message)]
    assert all(w.category is augsim.AugsimWarning for w in doubted)
    assert len(doubted) == (0 if r.plausible else 1), (r.plausible, r.warnings)
    assert r.plausible == (len(r.warnings) == 1), r.warnings
    assert r.to_dict()["plausible"] == r.plausible
    # A budget that is no budget is a ValueError, as iterations=0 is.
    for budget in [-1.0, 0.0, float("nan")]:
        with pytest.raises(ValueError, match="time_budget_ms"):
            augsim.Registration(fem=case["scenario"], units="mm", time_budget_ms=budget)


def test_a_unit_mistake_in_the_targets_is_named(case):
    # Millimetres declared as metres: outside the organ, refused, naming the likely mistake.
    with pytest.raises(augsim.AugsimError, match="given in mm where m were expected"):
        augsim.Registration(fem=case["scenario"], targets=case["rest"], units="m")
    # Metres declared as millimetres: 1,000 times too small, all at one point of the organ; read 1,000
    # times larger they lie in it: refused too, naming the mistake.
    with pytest.raises(augsim.AugsimError, match="given in m where mm were expected"):
        augsim.Registration(fem=case["scenario"], targets=case["rest"] * 1e-3, units="mm")


def test_a_structure_moves_with_the_organ(case, tmp_path):
    # An octahedron of 2 mm about the first target, as an ASCII STL in mm: it comes back moved with
    # the organ, its centre on the registered target, and is written beside the organ.
    corners = case["rest"][0] + 2.0 * np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]])
    faces = [(0, 2, 4), (2, 1, 4), (1, 3, 4), (3, 0, 4), (2, 0, 5), (1, 2, 5), (3, 1, 5), (0, 3, 5)]
    facets = "".join("facet normal 0 0 0\nouter loop\n" + "".join(f"vertex {x} {y} {z}\n" for x, y, z in corners[list(f)])
                     + "endloop\nendfacet\n" for f in faces)
    stl = tmp_path / "tumour.stl"
    stl.write_text(f"solid tumour\n{facets}endsolid tumour\n")
    reg = augsim.Registration(fem=case["scenario"], targets=case["targets"], units="mm", structures=[stl])
    r = reg.register(case["cloud"], out=tmp_path / "out")
    moved = r.structures["tumour"]
    assert list(r.structures) == ["tumour"] and moved.shape == (6, 3)
    np.testing.assert_allclose(moved.mean(axis=0), r.targets[0], atol=0.05)
    assert np.linalg.norm(moved - corners, axis=1).max() > 0.5, "moved with the organ"
    assert (tmp_path / "out" / "tumour_deformed.vtk").exists()
    assert augsim.Registration(fem=case["scenario"], targets=case["targets"], units="mm").register(
        case["cloud"]).structures == {}
    organ = tmp_path / "organ.stl"
    organ.write_text(stl.read_text())
    with pytest.raises(augsim.AugsimError, match="cannot be named `organ`"):
        augsim.Registration(fem=case["scenario"], targets=case["targets"], units="mm", structures=[organ])
    # One structure may be given alone, as a str or a path; anything else is a TypeError.
    for one in (str(stl), stl):
        alone = augsim.Registration(fem=case["scenario"], targets=case["targets"], units="mm", structures=one)
        np.testing.assert_allclose(alone.register(case["cloud"]).structures["tumour"], moved)
    with pytest.raises(TypeError, match="a path or a list of paths"):
        augsim.Registration(fem=case["scenario"], targets=case["targets"], units="mm", structures=3)


def test_register_writes_what_the_command_line_writes(case, tmp_path):
    reg = augsim.Registration(fem=case["scenario"], targets=case["targets"], units="mm")
    r = reg.register(case["cloud"], out=tmp_path / "out")
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == [
        "displacement.nrrd", "organ.vtu", "organ_deformed.vtk", "registration.html", "registration.png",
        "summary.json", "targets.csv", "targets.mrk.json"]
    import json

    # For 3D Slicer: the registered targets as markups in mm.
    markups = json.loads((tmp_path / "out" / "targets.mrk.json").read_text())["markups"][0]
    assert markups["coordinateUnits"] == "mm"
    np.testing.assert_allclose([p["position"] for p in markups["controlPoints"]], r.targets, atol=1e-6)
    written = np.loadtxt(tmp_path / "out" / "targets.csv", delimiter=",", skiprows=1)
    np.testing.assert_allclose(written[:, 3:6], r.targets, atol=1e-9)  # written in the registration's mm
    np.testing.assert_allclose(written[:, 0:3], case["rest"], atol=1e-9)

    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["frames"] == 1 and summary["per_frame"][0]["iterations"] == r.iterations
    assert (tmp_path / "out" / "targets.csv").read_text().startswith("x0_mm,y0_mm,z0_mm,x_mm,y_mm,z_mm\n")
    # An earlier run's results are not overwritten.
    with pytest.raises(augsim.AugsimError, match="results of an earlier run"):
        reg.register(case["cloud"], out=tmp_path / "out")
    # Labelled targets keep their labels in targets.csv.
    labelled = tmp_path / "labelled_mm.csv"
    rows = [f"T{k},{p[0]},{p[1]},{p[2]}" for k, p in enumerate(case["rest"])]
    labelled.write_text("label,x,y,z\n" + "\n".join(rows) + "\n")
    reg = augsim.Registration(fem=case["scenario"], targets=labelled, units="mm")
    reg.register(case["cloud"], out=tmp_path / "labelled")
    lines = (tmp_path / "labelled" / "targets.csv").read_text().splitlines()
    assert lines[0] == "x0_mm,y0_mm,z0_mm,x_mm,y_mm,z_mm,label"
    assert [line.rsplit(",", 1)[1] for line in lines[1:]] == [f"T{k}" for k in range(len(case["rest"]))]
    # A directory that cannot be made (under a file) raises before the cloud moves the warm start on:
    # the next cloud registers from rest, as a fresh registration's first does.
    reg = augsim.Registration(fem=case["scenario"], targets=case["targets"], units="mm")
    (tmp_path / "a_file").write_text("")
    with pytest.raises(augsim.AugsimError, match="a_file"):
        reg.register(case["cloud"], out=tmp_path / "a_file" / "out")
    again = reg.register(case["cloud"])
    assert again.iterations == r.iterations
    np.testing.assert_allclose(again.targets, r.targets, atol=1e-6)


def test_clouds_and_results_in_another_frame(case, tmp_path):
    """Targets saved by 3D Slicer in LPS name the organ's frame; clouds given in RAS (frame="RAS")
    register as the same clouds in LPS do, and the results come back in RAS."""
    import json

    points = [{"label": f"T{k}", "position": list(p)} for k, p in enumerate(case["rest"])]
    # A point Slicer has not placed yet: left out, with a warning naming it.
    points.append({"label": "T-later", "position": [0, 0, 0], "positionStatus": "undefined"})
    markups = {"markups": [{"type": "Fiducial", "coordinateSystem": "LPS", "coordinateUnits": "mm",
                            "controlPoints": points}]}
    targets = tmp_path / "targets.mrk.json"
    targets.write_text(json.dumps(markups))
    flip = np.array([-1.0, -1.0, 1.0])
    with pytest.warns(UserWarning, match="1 control point not placed in 3D Slicer .* left out: T-later"):
        lps = augsim.Registration(fem=case["scenario"], targets=targets, units="mm")
    with pytest.warns(UserWarning, match="T-later"):
        ras = augsim.Registration(fem=case["scenario"], targets=targets, units="mm", frame="RAS")
    assert (lps.frame, ras.frame) == ("LPS", "RAS")
    assert lps.target_labels == [f"T{k}" for k in range(len(case["rest"]))], "the file's labels, the placeholder left out"
    np.testing.assert_allclose(ras.targets, case["rest"] * flip, atol=1e-9)
    a, b = lps.register(case["cloud"]), ras.register(case["cloud"] * flip, out=tmp_path / "ras")
    np.testing.assert_allclose(b.targets, a.targets * flip, atol=1e-9)
    np.testing.assert_allclose(b.displacement, a.displacement * flip, atol=1e-9)
    # The files written are in the clouds' frame too, and name it.
    csv = (tmp_path / "ras" / "targets.csv").read_text().splitlines()
    assert csv[0] == "# CoordinateSystem = RAS", csv[0]
    written = np.loadtxt(csv[2:], delimiter=",", usecols=(3, 4, 5))
    np.testing.assert_allclose(written, b.targets, atol=1e-9)
    written = json.loads((tmp_path / "ras" / "targets.mrk.json").read_text())["markups"][0]
    assert written["coordinateSystem"] == "RAS"
    np.testing.assert_allclose([p["position"] for p in written["controlPoints"]], b.targets, atol=1e-6)
    assert json.loads((tmp_path / "ras" / "summary.json").read_text())["frame"] == "RAS"
    with pytest.raises(ValueError, match="frame"):
        augsim.Registration(fem=case["scenario"], targets=targets, frame="XYZ")


def test_predict_matches_the_command_line(tmp_path):
    grid = np.random.default_rng(2).normal(0.0, 1e-3, (3, 24, 24, 16)).astype(np.float32)
    u = augsim.predict(LIVER_AR, grid)
    assert u.shape == grid.shape and u.dtype == np.float32
    np.save(tmp_path / "in.npy", grid)
    run_augsim("predict", os.path.join(LIVER_AR, "model.json"), str(tmp_path / "in.npy"), "-o", str(tmp_path / "out.npy"),
        "--runs", "1")
    np.testing.assert_allclose(u, np.load(tmp_path / "out.npy"), rtol=0, atol=1e-7)
    # A cloud [N, 6]: displacements (m) at points of the organ, put on the grid as the CLI does.
    organ = augsim.Registration(model=LIVER_AR, scenario="liver_ar_t10").points
    cloud = np.hstack([organ[::50], np.full((len(organ[::50]), 3), 2e-3)])
    np.save(tmp_path / "cloud.npy", cloud)
    run_augsim("predict", os.path.join(LIVER_AR, "model.json"), str(tmp_path / "cloud.npy"), "-o",
        str(tmp_path / "cloud_out.npy"), "--runs", "1")
    u = augsim.predict(os.path.join(LIVER_AR, "model.json"), cloud)
    assert np.abs(u).max() > 1e-4
    np.testing.assert_allclose(u, np.load(tmp_path / "cloud_out.npy"), rtol=0, atol=1e-7)
    with pytest.raises(ValueError, match="without points"):
        augsim.predict(LIVER_AR, np.zeros((0, 6)))
    with pytest.raises(augsim.AugsimError, match=r"\[3, 24, 24, 16\]"):
        augsim.predict(LIVER_AR, grid[:, :10])
    with pytest.raises(augsim.AugsimError, match="model.json"):
        augsim.predict(tmp_path, grid)


def test_the_dataset_split_is_the_one_augsim_train_records(tmp_path):
    """The split `python -m augsim.train` uses (augsim's own, through the native module) is the one
    `augsim train` records for the same counts; counts that leave no training sample are refused."""
    import json

    from augsim._augsim import dataset_split

    data = tmp_path / "data"
    run_augsim("generate", "beam_target", "--out", str(data), "--samples", "24")
    run_augsim("train", str(data), "--out", str(tmp_path / "m"), "--iterations", "1", "--channels", "4", "--depth",
        "2", "--validation-samples", "4", "--test-samples", "5")
    with open(tmp_path / "m" / "model.json", encoding="utf-8") as f:
        recorded = json.load(f)["training"]["split"]
    with open(data / "manifest.json", encoding="utf-8") as f:
        indices = sorted(i for shard in json.load(f)["shards"] for i in shard["indices"])
    record, (train, validation, test) = dataset_split(str(data), indices, 4, 5)
    assert json.loads(record) == recorded
    assert (len(train), len(validation), len(test)) == (15, 4, 5)
    assert [indices[p] for p in test] == indices[-5:], "the last uniform draws are the test samples"
    with pytest.raises(augsim.AugsimError, match="leave no training sample"):
        dataset_split(str(data), indices, 20, 4)


def test_a_tracking_failure_is_left_out_by_the_validation_gate(tmp_path):
    scenario = tmp_path / "gated.toml"
    scenario.write_text(open(BEAM_ASSIMILATION).read() + "\n[filter]\ngate = 30.0\n")
    gated, plain = augsim.Assimilation(str(scenario)), augsim.Assimilation(BEAM_ASSIMILATION)
    for k, z in enumerate(gated.observations, 1):
        if k == 4:
            z = z.copy()
            z[2] += 0.05  # a tracker jumping by 5 cm on each axis
        e = gated.step(z)
        assert e.gated == (3 if k == 4 else 0), (k, e.gated)
        assert plain.step(z).gated == 0
    # The gated filter holds its estimate; the plain one is thrown off.
    assert abs(gated.mean[0] - 5000.0) < 50.0 < abs(plain.mean[0] - 5000.0)


def test_roukf_converges_to_the_young_modulus():
    a = augsim.Assimilation(BEAM_ASSIMILATION)
    assert a.names == ["young"] and a.scenario_values == [5000.0]
    observations = a.observations
    assert observations.shape == (8, 10, 3) and a.observed_points.shape == (10, 3)
    prior = a.mean[0]
    errors = []
    for k, z in enumerate(observations, 1):
        e = a.step(z)
        assert e.iteration == k == a.iteration and len(e.mean) == len(e.std) == 1
        assert repr(e) == f"Estimate(iteration={k}, mean=[{e.mean[0]}], std=[{e.std[0]}], gated={e.gated})"
        errors.append(abs(e.mean[0] - 5000.0))
    print(f"\nROUKF: E from {prior:.0f} Pa to {a.mean[0]:.1f} ± {a.std[0]:.1f} Pa (truth 5000 Pa)", file=sys.stderr)
    assert abs(prior - 5000.0) > 1000.0
    assert errors[-1] < 50.0 and errors[-1] < errors[0]
    assert a.std[0] < 0.1 * 5000.0
    with pytest.raises(ValueError, match=r"shape \[10, 3\]"):
        a.step(observations[0][:5])
    # A damaged measurement (a coordinate past a thousand kilometres) is refused, not assimilated.
    far = observations[0].copy()
    far[3, 1] = 1e300
    with pytest.raises(augsim.AugsimError, match="observed point 3 has the coordinate 1e300.*out of reach"):
        a.step(far)
    # A step in millimetres to a filter in metres would drive the estimate anywhere: refused.
    refused = "step 9 refused: the filter is left as it was, and the next call is step 9 again.*observed point 0 lies"
    with pytest.raises(augsim.AugsimError, match=refused + " .* mm from its rest position.*another unit"):
        a.step(observations[0] * 1000.0)
    # One in metres to a filter in millimetres leaves each point within the organ's size of its rest
    # position (near an origin the organ holds), but shrinks their span a thousand times: refused.
    with pytest.raises(augsim.AugsimError, match=r"observed points seen span .* [0-9.]+e-3 times .*another unit"):
        a.step(observations[0] * 1e-3)
    assert a.iteration == len(observations)
    with pytest.raises(augsim.AugsimError, match="missing"):
        augsim.Assimilation(os.path.join(ROOT, "missing.toml"))


def test_ctrl_c_stops_a_long_computation():
    # Building the reference of 100,000 steps takes 50 times as long as 2,000 steps; Ctrl-C half a
    # second in stops it at its next solver iteration, and the next call runs as usual.
    # A process started in the background by a shell ignores SIGINT, and Ctrl-C (interrupt_main)
    # then does nothing: Python's own handler is put back for the test.
    start = time.perf_counter()
    augsim.Assimilation(BEAM_ASSIMILATION, iterations=2000)
    fiftieth = time.perf_counter() - start
    handler = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        threading.Timer(0.5, _thread.interrupt_main).start()
        start = time.perf_counter()
        with pytest.raises(KeyboardInterrupt):
            augsim.Assimilation(BEAM_ASSIMILATION, iterations=100_000)
        stopped = time.perf_counter() - start
    finally:
        signal.signal(signal.SIGINT, handler)
    print(f"\nCtrl-C after 0.5 s: stopped after {stopped:.2f} s (the whole call: about {50 * fiftieth:.0f} s)")
    assert stopped < 0.5 + 10 * fiftieth
    assert augsim.Assimilation(BEAM_ASSIMILATION).names == ["young"]


def _box_obj(path, size):
    """A closed box surface of `size` (mm), corner at a scanner-like origin, as OBJ."""
    o = np.array([-120.0, 85.0, -310.0])
    corners = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], float) * size + o
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    with open(path, "w") as f:
        for c in corners:
            f.write("v %f %f %f\n" % tuple(c))
        for a, b, c, d in quads:
            f.write(f"f {a + 1} {b + 1} {c + 1}\nf {a + 1} {c + 1} {d + 1}\n")
    return o


def test_a_prepared_patient_registers(tmp_path):
    size = np.array([200.0, 150.0, 100.0])
    o = _box_obj(tmp_path / "organ.obj", size)
    bottom = [o + [x, y, 0.0] for x in (0.0, size[0]) for y in (0.0, size[1])]
    np.savetxt(tmp_path / "ligaments.csv", bottom, delimiter=",", header="x,y,z", comments="")
    centre = o + size / 2
    np.savetxt(tmp_path / "tumour.csv", [centre, centre + [20.0, 0.0, 0.0]], delimiter=",", header="x,y,z",
               comments="")
    camera = ",".join(str(v) for v in centre + [0.0, 0.0, 300.0])
    out = run_augsim("prepare", str(tmp_path / "organ.obj"), "--camera", camera, "--attach",
                     str(tmp_path / "ligaments.csv"), "--targets", str(tmp_path / "tumour.csv"), "--samples", "30",
                     "--tets", "500", "--out", str(tmp_path / "patient"))
    assert "step 7/7 report" in out and "units: mm" in out and "validation: FEM TRE" in out
    # By default the method the validation chose (registration.toml names it); use_fem=False: the ROM;
    # use_hybrid=True: the ROM from rest, then the FEM.
    set_up = (tmp_path / "patient" / "registration.toml").read_text()
    chosen = re.search(r'^method = "(\w+)"', set_up, re.M).group(1)
    for method, asked in ((chosen, {}), ("learned", {"use_fem": False}), ("hybrid", {"use_hybrid": True})):
        # In the patient's own unit (its files were in mm), in no named frame.
        reg = augsim.Registration(patient=tmp_path / "patient", **asked)
        assert reg.method.startswith("FEM" if method == "fem" else "ROM"), reg.method
        assert ("then FEM" in reg.method) == (method == "hybrid") and reg.targets.shape == (2, 3), reg.method
        assert (reg.units, reg.frame) == ("mm", None)
        np.testing.assert_allclose(reg.targets, [centre, centre + [20.0, 0.0, 0.0]], atol=1e-6)
        # The organ's top face at rest: the targets stay where they are.
        top = reg.points[reg.points[:, 2] > reg.points[:, 2].max() - 5.0]
        r = reg.register(top)
        assert np.abs(r.targets - reg.targets).max() < 2.0
    with pytest.raises(ValueError, match="patient DIR holds its method and targets: leave out --targets"):
        augsim.Registration(patient=tmp_path / "patient", targets=[[0.0, 0.0, 0.0]])


def test_the_pytorch_parts_without_torch_say_what_to_install():
    if importlib.util.find_spec("torch") is not None:
        pytest.skip("torch is installed: nothing to say")
    run = subprocess.run([sys.executable, "-m", "augsim.train", "--help"], capture_output=True, text=True)
    assert run.returncode == 1, run.stdout + run.stderr
    assert run.stderr.strip() == 'python -m augsim.train needs PyTorch: pip install "./python[torch]" (python/README.md)'
    with pytest.raises(ImportError, match=r'augsim.torch needs PyTorch: pip install "\./python\[torch\]"'):
        import augsim.torch  # noqa: F401


def test_errors_cross_process_boundaries_and_bad_shapes_are_value_errors():
    import pickle

    error = pickle.loads(pickle.dumps(augsim.AugsimError("a message")))
    assert type(error) is augsim.AugsimError and str(error) == "a message"
    for shape in [(24, 24, 16, 3), (1, 3, 24, 24, 16), (5,)]:
        with pytest.raises(ValueError, match=r"a grid tensor \[3, nx, ny, nz\] or a point cloud \[N, 6\]"):
            augsim.predict(LIVER_AR, np.zeros(shape))


def test_a_model_folder_holding_other_work_is_not_taken_for_a_training(tmp_path):
    # What python -m augsim.train would write over or mix with: a dataset, a reduced-order model, a run
    # of `augsim train`; an empty folder is taken, and given back.
    from augsim._augsim import lock_model_folder

    for name, held, message in [("dataset", "manifest.json", "holds a dataset"),
                                ("rom", "basis.npy", "holds a reduced-order model"),
                                ("unet", "checkpoint.bin", "holds a run of `augsim train`")]:
        folder = tmp_path / name
        folder.mkdir()
        (folder / held).write_text("")
        with pytest.raises(augsim.AugsimError, match=re.escape(message)):
            lock_model_folder(str(folder))
    lock_model_folder(str(tmp_path / "new")).release()
    assert (tmp_path / "new").is_dir()
