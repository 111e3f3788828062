"""Generation over a Dask cluster (python -m augsim.cluster) against one machine: two local worker
processes, the draws split into shards and merged, give the dataset ``augsim generate`` writes
alone, byte for byte. Needs dask (``pip install "./python[cluster]"``; `.ci/run` installs it)."""

import filecmp
import os
import signal
import subprocess
import sys
import time

import pytest

from helpers import augsim_bin, run_augsim

pytest.importorskip("dask.distributed", reason="needs dask: pip install './python[cluster]'")

from augsim import cluster  # noqa: E402  (after the skip: the module needs dask to run)


def _same_tree(a, b):
    cmp = filecmp.dircmp(a, b)
    assert not cmp.left_only and not cmp.right_only and not cmp.funny_files, (cmp.left_only, cmp.right_only)
    _, mismatch, errors = filecmp.cmpfiles(a, b, cmp.common_files, shallow=False)
    assert not mismatch and not errors, (mismatch, errors)
    for sub in cmp.common_dirs:
        _same_tree(os.path.join(a, sub), os.path.join(b, sub))


def test_two_local_workers_write_the_single_machine_dataset(tmp_path):
    # 40 draws are two blocks of 32 (the second short): a shard each.
    single = tmp_path / "single"
    run_augsim("generate", "liver_ar", "--samples", "40", "--out", str(single))
    out = tmp_path / "cluster"
    assert cluster.main(["liver_ar", "--samples", "40", "--local-workers", "2", "--out", str(out),
                         "--augsim", augsim_bin()]) == 0
    _same_tree(single, out)
    assert not (tmp_path / "cluster.parts").exists(), "the shards are removed after the merge"


def test_a_failing_shard_is_reported(tmp_path):
    # Refused by augsim: its reason, to be seen to before a rerun.
    with pytest.raises(RuntimeError, match=r"shard 0/1 failed \(exit status 1\): error: .*missing\.toml.*; see to "
                                           r"that, then run the same command again"):
        cluster.generate_shard(augsim_bin(), str(tmp_path / "missing.toml"), str(tmp_path / "out"), 0, 1)
    assert cluster.exit_cause(-9) == "killed by SIGKILL"


def _children(pid):
    """The processes ``pid``'s threads started (Linux)."""
    found = []
    for task in os.listdir(f"/proc/{pid}/task"):
        with open(f"/proc/{pid}/task/{task}/children") as f:
            found += [int(c) for c in f.read().split()]
    return found


def _running(pid):
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] != "Z"
    except FileNotFoundError:
        return False


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the parent-death signal is Linux's")
def test_a_killed_worker_s_augsim_stops_with_it(tmp_path):
    # A worker runs its task in a thread, as Dask's do; killed, it must not leave its augsim writing.
    worker = subprocess.Popen([sys.executable, "-c", (
        "import sys, threading; from augsim import cluster; "
        "t = threading.Thread(target=cluster.generate_shard, args=(sys.argv[1], 'liver_ar', sys.argv[2], 0, 1, 100000)); "
        "t.start(); t.join()"), augsim_bin(), str(tmp_path / "out")])
    child = None
    try:
        deadline = time.monotonic() + 30
        while child is None and time.monotonic() < deadline:
            child = next(iter(_children(worker.pid)), None)
            time.sleep(0.05)
        assert child is not None, "the worker started no augsim"
        time.sleep(0.5)
        assert _running(child)
        worker.send_signal(signal.SIGKILL)
        worker.wait()
        deadline = time.monotonic() + 10
        while _running(child) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert not _running(child), "the killed worker's augsim still runs"
    finally:
        worker.kill()
        if child is not None and _running(child):
            os.kill(child, signal.SIGKILL)


def test_kept_shards_are_reused_only_for_the_same_draws_and_a_dataset_is_never_overwritten(tmp_path):
    out = str(tmp_path / "ds")
    # A shard made for 20 draws, kept: the same shard again solves nothing; for 24 draws it is refused.
    directory, _ = cluster.generate_shard(augsim_bin(), "liver_ar", out, 0, 1, samples=20)
    manifest = os.path.join(directory, "manifest.json")
    with open(manifest, "rb") as f:
        first = f.read()
    os.utime(manifest, (0, 0))
    cluster.generate_shard(augsim_bin(), "liver_ar", out, 0, 1, samples=20)
    with open(manifest, "rb") as f:
        assert f.read() == first
    assert os.stat(manifest).st_mtime == 0, "a complete shard is left as it is"
    with pytest.raises(RuntimeError, match=r"metadata\.dataset\.samples 20 there, 24 now"):
        cluster.generate_shard(augsim_bin(), "liver_ar", out, 0, 1, samples=24)
    os.makedirs(out)
    with open(os.path.join(out, "manifest.json"), "w") as f:
        f.write("{}")
    with pytest.raises(SystemExit, match="already holds a dataset"):
        cluster.main(["liver_ar", "--samples", "20", "--local-workers", "1", "--out", out, "--augsim", augsim_bin()])


def test_what_cannot_be_generated_is_refused_in_one_line_before_any_cluster(tmp_path, capsys):
    out = str(tmp_path / "ds")
    (tmp_path / "afile").write_text("")
    for args, message in [(["liver_ar", "--samples", "0"], "--samples must be at least 1, got 0"),
                          (["liver_ar", "--samples", "-1"], "--samples must be at least 1, got -1"),
                          ([str(tmp_path / "missing.toml")], "cannot read scenario"),
                          (["beam"], "one of kind `dataset` is needed here")]:
        with pytest.raises(SystemExit) as stop:
            cluster.main([*args, "--out", out, "--augsim", augsim_bin()])
        assert stop.value.code == 2, args
        err = capsys.readouterr().err
        assert "python -m augsim.cluster: error: " in err and message in err, (args, err)
        assert "Traceback" not in err and "Usage: augsim generate" not in err, err
    assert not os.path.exists(out) and not os.path.exists(out + ".parts")
    # An --out that is a file, refused before the shards (it failed at their merge).
    with pytest.raises(SystemExit) as stop:
        cluster.main(["liver_ar", "--out", str(tmp_path / "afile"), "--augsim", augsim_bin()])
    assert stop.value.code == 2 and "is a file: give the dataset's folder" in capsys.readouterr().err
    assert not os.path.exists(str(tmp_path / "afile.parts"))
