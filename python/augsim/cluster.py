"""Generates a FEM dataset over a cluster with Dask: the draws split into shards (``augsim generate
--shard i/n``), one task per shard on the cluster's workers, then joined (``augsim merge``) into the
dataset a single machine would have written, bit for bit (each draw's load comes from the
scenario's seed and the draw's index alone).

    python -m augsim.cluster SCENARIO --out DIR [--samples N] [--shards S]
                             [--local-workers K]                 # worker processes on this machine
                             [--scheduler tcp://HOST:8786]        # a running Dask cluster
                             [--slurm | --pbs] [--jobs J] [--cores C] [--memory 8GB] [--walltime 02:00:00]
                                                                  # batch jobs via dask-jobqueue

Dask rather than Ray: the tasks are independent runs of the ``augsim`` binary, which Dask schedules
on a laptop (``LocalCluster``), on a running cluster, or as Slurm / PBS batch jobs (dask-jobqueue,
which speaks to the queue directly) with the same few lines; both install from PyPI in seconds,
pure Python. Each worker needs the ``augsim`` binary (``--augsim PATH``, default: ``augsim`` on the
PATH) and sees the output directory (a shared file system on a cluster). A shard that stopped
resumes where it stopped when the run is repeated (``augsim generate`` resumes), and a shard
already complete for the same scenario and draws is not solved again; one made for other ones
(left by ``--keep-parts`` or a failed merge) is refused, naming what differs. A shard's directory has
one writer at a time: a shard run again while a killed worker's ``augsim`` still writes it is refused
(on Linux a worker's ``augsim`` is stopped when its worker dies).
The draws go to the shards in blocks of 32 (as ``augsim generate --shard`` splits them): a run of
fewer than 32 draws a shard leaves some shards without work.

Needs dask: ``pip install "./python[cluster]"`` (with dask-jobqueue for --slurm / --pbs).
"""

import argparse
import ctypes
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time


def shard_dir(out, index, count):
    """The directory of shard ``index`` of ``count`` beside the dataset ``out``."""
    return os.path.join(out + ".parts", f"part{index}of{count}")


def _parent_death_signal():
    """On Linux, a ``preexec_fn`` that has the child sent SIGTERM when the thread that started it
    dies: a Dask worker killed (by its nanny, the batch queue, an out-of-memory kill) takes its
    ``augsim`` with it instead of leaving it writing the shard. None elsewhere. ``prctl`` is looked
    up here, before any fork: the child only calls it."""
    if not sys.platform.startswith("linux"):
        return None
    prctl = ctypes.CDLL(None, use_errno=True).prctl
    pr_set_pdeathsig, parent = 1, os.getpid()

    def die_with_parent():
        prctl(pr_set_pdeathsig, int(signal.SIGTERM))
        if os.getppid() != parent:  # the worker died before the signal was asked for
            os._exit(1)

    return die_with_parent


def generate_shard(augsim, scenario, out, index, count, samples=None, threads=1):
    """Runs ``augsim generate SCENARIO --shard index/count`` into its shard directory (on a worker);
    returns the directory and the run's wall time (s)."""
    directory = shard_dir(out, index, count)
    command = [augsim, "generate", scenario, "--shard", f"{index}/{count}", "--out", directory]
    if samples is not None:
        command += ["--samples", str(samples)]
    env = dict(os.environ, RAYON_NUM_THREADS=str(threads))
    start = time.perf_counter()
    run = subprocess.run(command, capture_output=True, text=True, env=env, preexec_fn=_parent_death_signal())
    if run.returncode != 0:
        # Killed (a job's wall time, a node lost): rerunning resumes it; refused by augsim: the cause first.
        advice = RESUME if run.returncode < 0 else f"see to that, then {RESUME}"
        raise RuntimeError(f"shard {index}/{count} failed ({exit_cause(run.returncode)}): {last_words(run)}; {advice}")
    return directory, time.perf_counter() - start


def exit_cause(returncode):
    """How a process ended, in words: ``exit status 1``, ``killed by SIGKILL``."""
    if returncode < 0:
        try:
            return f"killed by {signal.Signals(-returncode).name}"
        except ValueError:
            return f"killed by signal {-returncode}"
    return f"exit status {returncode}"


def last_words(run):
    """What a finished ``augsim`` run said last: its error line, else its last line of output."""
    lines = [line.strip() for line in (run.stdout + run.stderr).splitlines() if line.strip()]
    errors = [line for line in lines if line.startswith("error")]
    return (errors or lines or ["no output"])[-1]


RESUME = "run the same command again to resume: the draws each shard saved are kept"


def scenario_problem(augsim, scenario):
    """What ``augsim`` finds wrong with ``scenario`` (a file it cannot read, no dataset scenario, a
    mesh that does not load), or None. It runs ``augsim generate`` for no draws, which loads the
    scenario and its mesh and then stops at the draw count, in a fraction of a second."""
    with tempfile.TemporaryDirectory(prefix="augsim_cluster_") as tmp:
        run = subprocess.run([augsim, "generate", scenario, "--samples", "0", "--out", os.path.join(tmp, "probe")],
                             capture_output=True, text=True)
    if run.returncode == 0 or "a dataset needs at least one sample" in run.stderr:
        return None
    message = (run.stderr.strip() or run.stdout.strip() or f"augsim generate failed ({run.returncode})")
    return message[len("error: "):] if message.startswith("error: ") else message


def make_cluster(args):
    """The Dask cluster the options ask for, or None for a running scheduler."""
    if args.scheduler:
        return None
    if args.slurm or args.pbs:
        try:
            import dask_jobqueue
        except ImportError as e:
            raise SystemExit("--slurm / --pbs need dask-jobqueue: pip install dask-jobqueue") from e
        kind = dask_jobqueue.SLURMCluster if args.slurm else dask_jobqueue.PBSCluster
        cluster = kind(cores=args.cores, processes=1, memory=args.memory, walltime=args.walltime)
        cluster.scale(jobs=args.jobs)
        return cluster
    from dask.distributed import LocalCluster

    return LocalCluster(n_workers=args.local_workers, threads_per_worker=1, processes=True,
                        dashboard_address=None)


def generate(args):
    """Generates the shards on the cluster and merges them; returns the merge's output."""
    from dask.distributed import Client, as_completed

    out = os.path.abspath(args.out)
    if os.path.exists(os.path.join(out, "manifest.json")):
        raise SystemExit(f"{out} already holds a dataset: give another --out (`augsim generate SCENARIO --out "
                         f"{args.out} --samples N` grows a complete one)")
    if not (args.scheduler or args.slurm or args.pbs) and shutil.which(args.augsim) is None:
        raise SystemExit(f"no augsim binary at '{args.augsim}': give its path with --augsim")
    shards = args.shards or (args.local_workers if not (args.scheduler or args.slurm or args.pbs) else args.jobs)
    cluster = make_cluster(args)
    client = Client(args.scheduler) if cluster is None else Client(cluster)
    try:
        threads = args.cores if (args.slurm or args.pbs) else 1
        futures = [client.submit(generate_shard, args.augsim, args.scenario, out, i, shards, args.samples, threads,
                                 pure=False, key=f"shard-{i}-of-{shards}")
                   for i in range(shards)]
        start = time.perf_counter()
        try:
            for done, future in enumerate(as_completed(futures), 1):
                directory, seconds = future.result()
                print(f"shard      {done}/{shards} done: {os.path.basename(directory)} ({seconds:.1f} s)", flush=True)
        except RuntimeError as e:
            client.cancel(futures)
            raise SystemExit(str(e)) from None
        print(f"shards     {time.perf_counter() - start:.1f} s on the cluster", flush=True)
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
    parts = [shard_dir(out, i, shards) for i in range(shards)]
    merged = subprocess.run([args.augsim, "merge", out, *parts], capture_output=True, text=True)
    if merged.returncode != 0:
        raise SystemExit(f"merging the shards failed:\n{merged.stdout}{merged.stderr}")
    if not args.keep_parts:
        shutil.rmtree(out + ".parts", ignore_errors=True)
    return merged.stdout


def main(argv=None):
    p = argparse.ArgumentParser(prog="python -m augsim.cluster", description=__doc__.split("\n\n")[0])
    p.add_argument("scenario", help="dataset scenario: a TOML file or a built-in name")
    p.add_argument("--out", required=True, help="the dataset's directory")
    p.add_argument("--samples", type=int, help="draws (default: the scenario's)")
    p.add_argument("--shards", type=int, help="tasks (default: one per worker or job)")
    p.add_argument("--augsim", default=shutil.which("augsim") or "augsim", help="the augsim binary on the workers")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--local-workers", type=int, default=2, help="worker processes on this machine")
    where.add_argument("--scheduler", help="address of a running Dask scheduler")
    where.add_argument("--slurm", action="store_true", help="Slurm batch jobs (dask-jobqueue)")
    where.add_argument("--pbs", action="store_true", help="PBS batch jobs (dask-jobqueue)")
    p.add_argument("--jobs", type=int, default=4, help="batch jobs (--slurm / --pbs)")
    p.add_argument("--cores", type=int, default=4, help="cores per batch job")
    p.add_argument("--memory", default="8GB", help="memory per batch job")
    p.add_argument("--walltime", default="02:00:00", help="wall time per batch job")
    p.add_argument("--keep-parts", action="store_true", help="keep the shard directories after the merge")
    args = p.parse_args(argv)
    for name in ("samples", "shards", "local_workers", "jobs", "cores"):
        value = getattr(args, name)
        if value is not None and value < 1:
            p.error(f"--{name.replace('_', '-')} must be at least 1, got {value}")
    if os.path.isfile(args.out):
        p.error(f"--out {args.out} is a file: give the dataset's folder")
    # Workers may start in another folder: files named relative to this one are given whole.
    if os.path.isfile(args.scenario):
        args.scenario = os.path.abspath(args.scenario)
    if os.sep in args.augsim and os.path.isfile(args.augsim):
        args.augsim = os.path.abspath(args.augsim)
    # Checked here, once: a bad scenario would otherwise fail in every shard, inside Dask.
    if shutil.which(args.augsim) is not None:
        problem = scenario_problem(args.augsim, args.scenario)
        if problem:
            p.error(problem)
    try:
        print(generate(args), end="")
    except KeyboardInterrupt:
        print(f"interrupted: {RESUME}", file=sys.stderr)
        return 130
    return 0


if __name__ == "__main__":
    sys.exit(main())
