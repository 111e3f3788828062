"""Trains augsim's U-Net with PyTorch (on GPUs when there are some) and writes a model directory
that ``augsim eval``, ``augsim predict`` and ``augsim register`` load unchanged.

    python -m augsim.train DATASET --out DIR [--iterations N] [--channels C] [--depth D]
                           [--batch B] [--lr LR] [--final-lr LR] [--validate-every K]
                           [--validation-samples N | --validation-fraction F]
                           [--test-samples N | --test-fraction F] [--train-samples N]
                           [--seed S] [--device cuda|cpu]
    torchrun --nproc_per_node=4 -m augsim.train ...        # data-parallel on 4 GPUs (DDP)

It follows ``augsim train``: the same architecture (``docs/method.md``, section 5.2; the module of
``augsim.torch``), the same split rule (by generation index: the last uniform draws test, those
before them validate, the rest and every σ-chosen draw train; recorded in model.json with the dataset's identity, so that
``augsim eval`` evaluates on the test samples only), the same normalisation (one scale per field:
the RMS vector norm of the training inputs over their non-zero nodes and of the training targets
over the organ), the same loss (masked MSE in normalised units), Adam (β = 0.9, 0.999, ε = 1e-5)
with an optional half-cosine decay of the rate, and the checkpoint chosen on the validation mean
Euclidean error. Batches are drawn by PyTorch's generator, so the run is reproducible from the seed
but its batches differ from ``augsim train``'s. ``DIR/checkpoint.pt`` is written at every
validation; rerunning the same command resumes from it.

Needs torch: ``pip install "./python[torch]"`` (see python/README.md).
"""

import argparse
import json
import math
import os
import struct
import sys
import time

import numpy as np

try:
    import torch
except ImportError as e:
    raise SystemExit('python -m augsim.train needs PyTorch: pip install "./python[torch]" (python/README.md)') from e

from ._augsim import CANDIDATE_BASE, AugsimError, dataset_split, lock_model_folder, weights_digest
from .torch import MODEL_FORMAT, MODEL_VERSION, UNet, write_atomic

# augsim's bounds on a U-Net (crates/learn/src/net/unet.rs, UNetConfig::validate).
MAX_CHANNELS = 4096
MAX_DEPTH = 6

LAYOUT = ("[channel, x, y, z], C order, z fastest: index = ((c*nx + i)*ny + j)*nz + k; shards prepend the "
          "sample axis; masks are [x, y, z]")


# ---------------------------------------------------------------- the dataset, as augsim reads it


def read_dataset(path):
    """The manifest and every sample of an augsim dataset directory, in generation-index order:
    (manifest, indices [N] int64, inputs [N, 3, nx, ny, nz] f32, targets (same), masks [N, nx, ny, nz] u8)."""
    manifest_path = os.path.join(path, "manifest.json")
    with open(manifest_path, encoding="utf-8") as f:
        try:
            manifest = json.load(f)
        except ValueError as e:
            raise ValueError(f"{manifest_path}: not valid JSON: {e}") from e
    if not isinstance(manifest, dict) or manifest.get("format") != "augsim-dataset":
        raise ValueError(f"{path}: not an augsim dataset (its manifest.json is not of format 'augsim-dataset')")
    if not manifest.get("complete", False):
        raise ValueError(f"{path}: the dataset is incomplete; finish it with `augsim generate` first")
    parts = [[], [], [], []]
    for shard in manifest["shards"]:
        arrays = [np.load(os.path.join(path, shard[key])) for key in ("inputs", "targets", "masks")]
        n = shard["num_samples"]
        if any(a.shape[0] != n for a in arrays) or len(shard["indices"]) != n:
            raise ValueError(f"{path}: shard {shard['name']} does not hold {n} samples")
        parts[0].append(np.asarray(shard["indices"], dtype=np.int64))
        for part, a in zip(parts[1:], arrays):
            part.append(a)
    indices, inputs, targets, masks = (np.concatenate(p) for p in parts)
    order = np.argsort(indices, kind="stable")
    return manifest, indices[order], inputs[order].astype(np.float32), targets[order].astype(np.float32), \
        masks[order].astype(np.uint8)


def normalization(inputs, targets, masks):
    """(input_scale, target_scale): RMS vector norms of the inputs over their non-zero nodes and of
    the targets over the organ's nodes (1 where there is nothing to measure)."""
    def rms(fields, nodes):
        squared = (fields.astype(np.float64) ** 2).sum(axis=1)
        count = int(nodes.sum())
        value = math.sqrt(squared[nodes].sum() / count) if count else 0.0
        return value if value > 0 and math.isfinite(value) else 1.0
    return rms(inputs, np.any(inputs != 0, axis=1)), rms(targets, masks != 0)


# ---------------------------------------------------------------- training


def he_uniform_(net, generator):
    """augsim's initialisation: He-uniform weights (bound sqrt(6 / fan-in), fan-in = the weight's
    second dimension times the kernel volume), zero biases."""
    with torch.no_grad():
        for name, p in net.named_parameters():
            if name.endswith("bias"):
                p.zero_()
            else:
                fan_in = p.shape[1] * int(np.prod(p.shape[2:]))
                bound = math.sqrt(6.0 / fan_in)
                p.copy_((torch.rand(p.shape, generator=generator) * 2 - 1) * bound)


def masked_mse(pred, target, mask):
    """Mean over the organ's nodes of the squared error vector norm (normalised units)."""
    return ((pred - target) ** 2).sum(1).mul(mask).sum() / mask.sum().clamp_min(1.0)


def mean_euclidean_errors(net, inputs, targets, masks, scales, device, batch):
    """Per-sample mean Euclidean error (m) over the organ's nodes."""
    errors = []
    net.eval()
    with torch.inference_mode():
        for s in range(0, len(inputs), batch):
            x = torch.from_numpy(inputs[s:s + batch] * np.float32(1.0 / scales[0])).to(device)
            y = net(x).double().cpu().numpy() * scales[1]
            d = np.sqrt(((y - targets[s:s + batch].astype(np.float64)) ** 2).sum(axis=1))
            m = masks[s:s + batch] != 0
            errors.extend((d * m).sum(axis=(1, 2, 3)) / np.maximum(m.sum(axis=(1, 2, 3)), 1))
    net.train()
    return np.asarray(errors)


def learning_rate(args, it):
    """The rate of (0-based) step `it`: constant, or a half cosine from --lr to --final-lr."""
    if args.final_lr is None:
        return args.lr
    t = min(it / (max(args.iterations, 2) - 1), 1.0)
    return args.final_lr + 0.5 * (args.lr - args.final_lr) * (1.0 + math.cos(math.pi * t))


def write_safetensors(path, tensors):
    """Writes name -> float32 array as safetensors, atomically."""
    header, offset, blobs = {}, 0, []
    for name in sorted(tensors):
        data = np.ascontiguousarray(tensors[name], dtype="<f4").tobytes()
        header[name] = {"dtype": "F32", "shape": list(tensors[name].shape), "data_offsets": [offset, offset + len(data)]}
        offset += len(data)
        blobs.append(data)
    text = json.dumps(header, separators=(",", ":")).encode("utf-8")
    text += b" " * (-len(text) % 8)
    write_atomic(path, struct.pack("<Q", len(text)) + text + b"".join(blobs))


def model_json(args, manifest, config, scales, best, split, digest):
    metadata = manifest.get("metadata") or {}
    placement = None
    if "grid_origin" in metadata and "grid_spacing" in metadata:
        placement = {"origin": metadata["grid_origin"], "spacing": metadata["grid_spacing"]}
    return {
        "format": MODEL_FORMAT,
        "version": MODEL_VERSION,
        "layout": LAYOUT,
        "unet": config,
        "normalization": {"input_scale": scales[0], "target_scale": scales[1]},
        "grid": manifest["grid"],
        "placement": placement,
        "input_unit": manifest["units"]["input"],
        "target_unit": manifest["units"]["target"],
        "weights": "model.safetensors",
        "weights_digest": digest,
        "training": {
            "iterations": args.iterations,
            # Without validation nothing chose the weights: the last step's are kept.
            "best_iteration": None if best["error"] is None else best["iteration"],
            "best_val_mean_error": best["error"],
            "train_samples": split["train_samples"],
            "val_samples": split["val_samples"],
            "seed": args.seed,
            "fine_tuned_from": None,
            "frozen_encoder": False,
            "corruption": {"sparsity": None, "noise_std": 0.0},  # trained on clean, whole inputs
            "split": split["record"],
            "schedule": {"batch_size": args.batch, "learning_rate": args.lr, "final_learning_rate": args.final_lr,
                         "validate_every": args.validate_every},
        },
    }


def parse_args(argv):
    """The parser (for its errors) and the checked arguments."""
    p = argparse.ArgumentParser(prog="python -m augsim.train", description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("dataset", help="augsim dataset directory (from `augsim generate`)")
    p.add_argument("--out", required=True, help="model directory to write (model.json, model.safetensors)")
    p.add_argument("--iterations", type=int, default=2000, help="optimiser steps (default 2000)")
    p.add_argument("--batch", type=int, default=4, help="samples per step, over all GPUs (default 4)")
    p.add_argument("--lr", type=float, default=1e-3, help="Adam learning rate (default 1e-3)")
    p.add_argument("--final-lr", type=float, default=None, help="decay the rate to this along a half cosine")
    p.add_argument("--channels", type=int, default=16, help="channels of the first level (default 16)")
    p.add_argument("--depth", type=int, default=3, help="down-sampling steps (default 3)")
    p.add_argument("--validate-every", type=int, default=100, help="validate and checkpoint every K steps")
    p.add_argument("--test-fraction", type=float, default=0.2)
    p.add_argument("--test-samples", type=int, default=None)
    p.add_argument("--validation-fraction", type=float, default=0.1)
    p.add_argument("--validation-samples", type=int, default=None)
    p.add_argument("--train-samples", type=int, default=None, help="train on the first N training samples only")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--device", choices=("cuda", "cpu"), default=None, help="cuda or cpu (default: cuda when available)")
    args = p.parse_args(argv)
    for name in ("iterations", "batch", "channels", "validate_every"):
        if getattr(args, name) < 1:
            p.error(f"--{name.replace('_', '-')} must be at least 1, got {getattr(args, name)}")
    if args.channels > MAX_CHANNELS:
        p.error(f"--channels must be at most {MAX_CHANNELS} (augsim's U-Net), got {args.channels}")
    if not 0 <= args.depth <= MAX_DEPTH:
        p.error(f"--depth must lie in 0..{MAX_DEPTH} (augsim's U-Net), got {args.depth}")
    for name in ("validation_samples", "test_samples"):
        if getattr(args, name) is not None and getattr(args, name) < 0:
            p.error(f"--{name.replace('_', '-')} must be at least 0, got {getattr(args, name)}")
    if args.train_samples is not None and args.train_samples < 1:
        p.error(f"--train-samples must be at least 1, got {args.train_samples}")
    if not (args.lr > 0 and (args.final_lr is None or 0 < args.final_lr <= args.lr)):
        p.error("--lr must be > 0 and --final-lr in (0, lr]")
    for name in ("test_fraction", "validation_fraction"):
        if not 0 <= getattr(args, name) < 1:
            p.error(f"--{name.replace('_', '-')} must lie in [0, 1)")
    if args.device == "cuda" and not torch.cuda.is_available():
        p.error(f"--device cuda: PyTorch {torch.__version__} sees no CUDA GPU here; give --device cpu")
    if not os.path.isfile(os.path.join(args.dataset, "manifest.json")):
        what = "no augsim dataset (no manifest.json)" if os.path.isdir(args.dataset) else "not a directory"
        p.error(f"{args.dataset}: {what}; give a dataset directory from `augsim generate`")
    return p, args


def main(argv=None):
    p, args = parse_args(sys.argv[1:] if argv is None else argv)
    distributed = int(os.environ.get("WORLD_SIZE", "1")) > 1
    rank, world = 0, 1
    if distributed:
        torch.distributed.init_process_group("nccl" if torch.cuda.is_available() else "gloo")
        rank, world = torch.distributed.get_rank(), torch.distributed.get_world_size()
    device = torch.device(args.device or ("cuda" if torch.cuda.is_available() else "cpu"))
    if device.type == "cuda":
        device = torch.device("cuda", int(os.environ.get("LOCAL_RANK", "0")))
        torch.cuda.set_device(device)
        torch.backends.cudnn.benchmark = True  # the grid never changes: pick the fastest convolutions once
    say = print if rank == 0 else (lambda *a, **k: None)

    try:
        manifest, indices, inputs, targets, masks = read_dataset(args.dataset)
        uniform = int(np.count_nonzero(indices < CANDIDATE_BASE))
        count = lambda fraction, given: given if given is not None else int(round(uniform * fraction))  # noqa: E731
        record, (train, val, test) = dataset_split(args.dataset, indices.tolist(),
                                                   count(args.validation_fraction, args.validation_samples),
                                                   count(args.test_fraction, args.test_samples))
    except KeyError as e:
        p.error(f"{args.dataset}: manifest.json lacks the field {e}: not a dataset of `augsim generate`")
    except (OSError, ValueError, AugsimError) as e:
        p.error(str(e))
    record = json.loads(record)
    train, val, test = (np.asarray(positions, dtype=np.int64) for positions in (train, val, test))
    if args.train_samples is not None:
        if args.train_samples > len(train):
            p.error(f"--train-samples {args.train_samples}: the training split has {len(train)}")
        train = train[:args.train_samples]
    scales = normalization(inputs[train], targets[train], masks[train])
    say(f"split      {len(train)} training, {len(val)} validation, {len(test)} test samples; grid "
        f"{'x'.join(map(str, manifest['grid']))}; {world} process(es) on {device}")
    if not len(val):
        say("warning    no validation sample: nothing selects a checkpoint, and the last iteration's weights are kept "
            "(give --validation-samples, or more data)")

    config = {"in_channels": 3, "out_channels": 3, "base_channels": args.channels, "depth": args.depth,
              "kernel_size": 3}
    torch.manual_seed(args.seed)
    net = UNet(**config)
    he_uniform_(net, torch.Generator().manual_seed(args.seed))
    net.to(device)
    model = torch.nn.parallel.DistributedDataParallel(net, device_ids=[device] if device.type == "cuda" else None) \
        if distributed else net
    optimiser = torch.optim.Adam(net.parameters(), lr=args.lr, betas=(0.9, 0.999), eps=1e-5)
    folder = None
    if rank == 0:
        try:
            folder = lock_model_folder(args.out)  # a second training into --out is refused while this one runs
        except AugsimError as e:
            p.error(str(e))
    try:
        checkpoint_path = os.path.join(args.out, "checkpoint.pt")
        start, best = 0, {"iteration": 0, "error": None, "state": None}
        if os.path.exists(checkpoint_path):
            state = torch.load(checkpoint_path, map_location=device, weights_only=False)
            if state["config"] != config or state["split"] != record:
                raise SystemExit(f"{checkpoint_path} is of another configuration or split; remove it to start afresh")
            net.load_state_dict(state["net"])
            optimiser.load_state_dict(state["optimiser"])
            start, best = state["iteration"], state["best"]
            say(f"resumed    from step {start}")

        # On a GPU the training set lives in its memory, so that a step moves no data from the host.
        home = device if device.type == "cuda" else torch.device("cpu")
        x_train = torch.from_numpy(inputs[train] * np.float32(1.0 / scales[0])).to(home)
        y_train = torch.from_numpy(targets[train] * np.float32(1.0 / scales[1])).to(home)
        m_train = torch.from_numpy(masks[train].astype(np.float32)).to(home)
        per_rank = max(args.batch // world, 1)
        began = time.time()
        for it in range(start, args.iterations):
            generator = torch.Generator().manual_seed(args.seed * 1_000_003 + it)
            drawn = torch.randint(len(train), (per_rank * world,), generator=generator)
            batch = drawn[rank * per_rank:(rank + 1) * per_rank]
            for group in optimiser.param_groups:
                group["lr"] = learning_rate(args, it)
            batch = batch.to(home)
            x, y, m = (t[batch].to(device, non_blocking=True) for t in (x_train, y_train, m_train))
            loss = masked_mse(model(x), y, m)
            optimiser.zero_grad(set_to_none=True)
            loss.backward()
            optimiser.step()
            done = it + 1
            if done % args.validate_every == 0 or done == args.iterations:
                if rank == 0:
                    errors = mean_euclidean_errors(net, inputs[val], targets[val], masks[val], scales, device, 8) \
                        if len(val) else np.zeros(0)
                    error = float(errors.mean()) if len(errors) else None
                    if best["error"] is None or (error is not None and error < best["error"]) or not len(errors):
                        best = {"iteration": done, "error": error,
                                "state": {k: v.detach().cpu().clone() for k, v in net.state_dict().items()}}
                    rate = (done - start) / max(time.time() - began, 1e-9)
                    shown = "—" if error is None else f"{error * 1e3:.4f} mm"
                    say(f"step {done:>7}  loss {loss.item():.4e}  validation ē {shown}  ({rate:.1f} steps/s)")
                    torch.save({"config": config, "split": record, "iteration": done, "best": best,
                                "net": net.state_dict(), "optimiser": optimiser.state_dict()}, checkpoint_path + ".tmp")
                    os.replace(checkpoint_path + ".tmp", checkpoint_path)
        if rank == 0:
            weights = {k: v.numpy() for k, v in (best["state"] or net.state_dict()).items()}
            weights_path = os.path.join(args.out, "model.safetensors")
            write_safetensors(weights_path, weights)
            split = {"train_samples": len(train), "val_samples": len(val), "record": record}
            text = json.dumps(model_json(args, manifest, config, scales, best, split, weights_digest(weights_path)),
                              indent=2)
            write_atomic(os.path.join(args.out, "model.json"), text.encode("utf-8"))
            if best["error"] is None:
                say("kept       the last iteration's weights (no validation sample chose them)")
            else:
                say(f"best       validation ē {best['error'] * 1e3:.4f} mm at step {best['iteration']}")
            say(f"wrote      {os.path.join(args.out, 'model.json')}")
    finally:
        if folder is not None:
            folder.release()
    if distributed:
        torch.distributed.destroy_process_group()
    return 0


if __name__ == "__main__":
    sys.exit(main())
