"""augsim's U-Net in PyTorch, rebuilt from a trained model directory.

Needs torch (``pip install "./python[torch]"``) and numpy; the safetensors file is parsed here. It
reproduces ``augsim predict`` on a grid tensor:

    import numpy as np
    from augsim.torch import load, predict
    model = load("models/liver_ar")                  # torch.nn.Module, eval mode, float32
    u = predict(model, np.load("input.npy"))         # [3, nx, ny, nz] displacement (m)

:class:`UNet` is the one PyTorch definition of the network: ``python -m augsim.train`` trains it
and ``bench/torch_unet_twin.py`` times it.

A model directory holds ``model.json`` (format "augsim-unet" v1: U-Net configuration,
normalisation, grid, units) and the weights file it names (``model.safetensors``), as written by
``augsim train``.

Conventions (crates/learn/src/net/unet.rs, net/inference.rs, net/predict.rs, data/grid.rs):

- Grid tensors are ``[channel, x, y, z]``, C order (z fastest), float32; the channels are the x, y,
  z components. Prediction input: the model's ``input_unit`` (N for forces, m for imposed
  displacements), shape ``[in_channels, nx, ny, nz]`` on the model's grid ``model.grid``;
  output: displacement in m, ``[out_channels, nx, ny, nz]``. Values outside the organ are
  meaningless (apply the dataset mask).
- Normalisation: one scale per field, no offset. The network sees
  ``float32(float64(x) * (1 / input_scale))`` and its output ``y`` becomes
  ``float32(float64(y) * target_scale)``; an input array of another dtype is first cast to
  float32, as augsim does with a float64 ``.npy``.
- Architecture: the one description in ``docs/method.md`` (section 5.2), which every augsim engine
  follows.
- Weights: burn's names and layouts, the same as PyTorch's (``encoder.0.conv1.weight``
  ``[c_out, c_in, k, k, k]``, ``up.0.weight`` ``[c_in, c_out, 2, 2, 2]``, every layer has a bias).

Point-cloud inputs (``augsim predict`` on .csv or ``[N, 6]`` .npy) are not handled here: encode
them on the grid with augsim first.

Command line: ``python -m augsim.torch MODEL_DIR INPUT.npy OUTPUT.npy``.
"""

import io
import json
import math
import os
import struct
import sys

import numpy as np

try:
    import torch
except ImportError as e:
    raise ImportError('augsim.torch needs PyTorch: pip install "./python[torch]" (python/README.md)') from e
import torch.nn as nn
import torch.nn.functional as F

MODEL_FORMAT = "augsim-unet"
MODEL_VERSION = 1
# The largest magnitude of a prediction input value that augsim accepts (crates/learn/src/data/grid.rs).
MAX_FIELD_VALUE = np.float32(1e6)

_DTYPES = {"F32": "<f4", "F64": "<f8", "F16": "<f2", "BF16": "<u2"}


def write_atomic(path, data):
    """Writes the bytes `data` to `path` whole or not at all (a temporary beside it, then renamed)."""
    tmp = f"{path}.tmp{os.getpid()}"
    with open(tmp, "wb") as f:
        f.write(data)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, path)


def read_safetensors(path):
    """Reads a safetensors file into a dict name -> float32 numpy array.

    Format: an 8-byte little-endian header length, a JSON header (name -> dtype, shape,
    data_offsets relative to the end of the header; optional ``__metadata__``), raw
    little-endian data.
    """
    with open(path, "rb") as f:
        data = f.read()
    if len(data) < 8:
        raise ValueError(f"{path}: too short for a safetensors file")
    (n,) = struct.unpack("<Q", data[:8])
    if 8 + n > len(data):
        raise ValueError(f"{path}: header length {n} runs past the end of the file")
    header = json.loads(data[8:8 + n].decode("utf-8"))
    body = memoryview(data)[8 + n:]
    tensors = {}
    for name, info in header.items():
        if name == "__metadata__":
            continue
        dtype, shape, (start, end) = info["dtype"], info["shape"], info["data_offsets"]
        if dtype not in _DTYPES:
            raise ValueError(f"{path}: tensor {name}: unsupported dtype {dtype}")
        if not 0 <= start <= end <= len(body):
            raise ValueError(f"{path}: tensor {name}: data offsets {start}..{end} outside the data")
        a = np.frombuffer(body[start:end], dtype=_DTYPES[dtype])
        if a.size != int(np.prod(shape, dtype=np.int64)):
            raise ValueError(f"{path}: tensor {name}: {a.size} values for shape {shape}")
        if dtype == "BF16":
            a = (a.astype(np.uint32) << 16).view(np.float32)
        tensors[name] = a.astype(np.float32).reshape(shape)
    return tensors


class ConvBlock(nn.Module):
    """Two same-size convolutions, each followed by ReLU."""

    def __init__(self, c_in, c_out, k):
        super().__init__()
        self.conv1 = nn.Conv3d(c_in, c_out, k, padding=k // 2)
        self.conv2 = nn.Conv3d(c_out, c_out, k, padding=k // 2)

    def forward(self, x):
        return F.relu(self.conv2(F.relu(self.conv1(x))))


class UNet(nn.Module):
    """augsim's 3D U-Net; parameter names match augsim's safetensors files.

    ``forward`` takes a normalised batch ``[batch, in_channels, nx, ny, nz]`` of any grid size
    (zero-padded internally to a multiple of ``2**depth``, cropped back) and returns
    ``[batch, out_channels, nx, ny, nz]`` in normalised units.
    """

    def __init__(self, in_channels=3, out_channels=3, base_channels=16, depth=3, kernel_size=3):
        super().__init__()
        if kernel_size % 2 == 0:
            raise ValueError(f"kernel_size {kernel_size} must be odd")
        if depth < 0:
            raise ValueError(f"depth {depth} must be at least 0")
        ch = lambda l: base_channels << l
        k = kernel_size
        self.depth = depth
        self.encoder = nn.ModuleList(
            [ConvBlock(in_channels if l == 0 else ch(l - 1), ch(l), k) for l in range(depth)])
        self.down = nn.ModuleList([nn.Conv3d(ch(l), ch(l), 2, stride=2) for l in range(depth)])
        self.bottleneck = ConvBlock(in_channels if depth == 0 else ch(depth - 1), ch(depth), k)
        self.up = nn.ModuleList([nn.ConvTranspose3d(ch(l + 1), ch(l), 2, stride=2) for l in range(depth)])
        self.decoder = nn.ModuleList([ConvBlock(2 * ch(l), ch(l), k) for l in range(depth)])
        self.head = nn.Conv3d(ch(0), out_channels, 1)

    def forward(self, x):
        nx, ny, nz = x.shape[2:]
        m = 1 << self.depth
        px, py, pz = (-nx) % m, (-ny) % m, (-nz) % m
        h = F.pad(x, (0, pz, 0, py, 0, px)) if px or py or pz else x
        skips = []
        for block, down in zip(self.encoder, self.down):
            h = block(h)
            skips.append(h)
            h = down(h)
        h = self.bottleneck(h)
        for l in reversed(range(self.depth)):
            h = self.decoder[l](torch.cat([self.up[l](h), skips[l]], 1))
        return self.head(h)[:, :, :nx, :ny, :nz]


def _model_json(model_dir):
    """The model.json of a model directory, or the file given; an error when there is none."""
    path = os.fspath(model_dir)
    if os.path.isdir(path):
        path = os.path.join(path, "model.json")
    if not os.path.isfile(path):
        raise FileNotFoundError(f"{path}: no such file: give the model directory or its model.json")
    return path


def _read_model_json(path):
    """The parsed model.json at ``path``; ValueError naming the file when it is not one."""
    hint = "give the model directory or its model.json"
    with open(path, "rb") as f:
        data = f.read()
    try:
        info = json.loads(data.decode("utf-8"))
    except UnicodeDecodeError:
        raise ValueError(f"{path}: not a model.json (not UTF-8 text): {hint}") from None
    except ValueError as e:
        raise ValueError(f"{path}: invalid model JSON: {e}" + ("" if path.endswith(".json") else f": {hint}")) from e
    if not isinstance(info, dict):
        raise ValueError(f"{path}: not a model.json (no JSON object): {hint}")
    return info


def load(model_dir, device="cpu"):
    """Loads a trained augsim model: a directory holding model.json, or the model.json path.

    Returns a :class:`UNet` in eval mode (float32, on ``device``) with the model file's
    metadata as attributes: ``config`` (the "unet" dict), ``input_scale``, ``target_scale``,
    ``grid`` ((nx, ny, nz)), ``input_unit``, ``target_unit``, ``placement`` (dict or None) and
    ``info`` (the whole model.json). The weights must fit the configuration exactly.
    """
    json_path = _model_json(model_dir)
    info = _read_model_json(json_path)
    if info.get("format") != MODEL_FORMAT or info.get("version") != MODEL_VERSION:
        raise ValueError(f"{json_path}: format {info.get('format')!r} v{info.get('version')} "
                         f"is not {MODEL_FORMAT!r} v{MODEL_VERSION}")
    try:
        weights, unet, norm, grid = info["weights"], info["unet"], info["normalization"], info["grid"]
    except KeyError as e:
        raise ValueError(f"{json_path}: no {e} field: not a model.json of `augsim train`") from None
    if os.path.basename(weights) != weights or os.path.isabs(weights):
        raise ValueError(f"{json_path}: weights {weights!r} must be a file name beside the model file")
    scales = [norm.get(name) if isinstance(norm, dict) else None for name in ("input_scale", "target_scale")]
    for name, x in zip(("input_scale", "target_scale"), scales):
        if isinstance(x, bool) or not isinstance(x, (int, float)) or not (math.isfinite(x) and x > 0):
            raise ValueError(f"{json_path}: normalization {name} must be finite and > 0, got {x}")
    config = {"in_channels": 3, "out_channels": 3, "base_channels": 16, "depth": 3, "kernel_size": 3}
    config.update(unet)
    try:
        net = UNet(**config)
    except (TypeError, ValueError) as e:
        raise ValueError(f"{json_path}: unet {config}: {e}") from e
    tensors = read_safetensors(os.path.join(os.path.dirname(os.path.abspath(json_path)), weights))
    state = {name: torch.from_numpy(a.copy()) for name, a in tensors.items()}
    try:
        net.load_state_dict(state, strict=True)
    except RuntimeError as e:
        raise ValueError(f"{json_path}: weights do not fit the configuration {config}: {e}") from e
    net.config = config
    net.input_scale, net.target_scale = (float(x) for x in scales)
    net.grid = tuple(int(n) for n in grid)
    net.input_unit = info.get("input_unit")
    net.target_unit = info.get("target_unit")
    net.placement = info.get("placement")
    net.info = info
    return net.to(device).eval()


def _rust_e(v):
    """A float32 as Rust's ``{:e}`` writes it (``2e6``, ``1.5e-3``, ``NaN``, ``-inf``)."""
    v = np.float32(v)
    if not np.isfinite(v):
        return "NaN" if np.isnan(v) else ("inf" if v > 0 else "-inf")
    mantissa, _, exponent = np.format_float_scientific(v, unique=True, trim="-").partition("e")
    return f"{mantissa}e{int(exponent)}"


def predict(model, grid_input):
    """Predicts the displacement (m) for a grid input, as ``augsim predict`` does.

    ``grid_input``: array ``[in_channels, nx, ny, nz]`` (``[channel, x, y, z]``, C order) on the
    model's grid, in the model's input unit; a batch ``[N, in_channels, nx, ny, nz]`` (a dataset
    shard's inputs) also works. Returns float32 ``[out_channels, nx, ny, nz]`` (or
    ``[N, out_channels, nx, ny, nz]``). Other grids, and values that augsim refuses (not finite, or
    beyond 1e6 in magnitude), raise ValueError.
    """
    try:
        with np.errstate(over="ignore"):  # beyond float32's range becomes inf, refused below as augsim does
            x = np.asarray(grid_input).astype(np.float32)
    except (TypeError, ValueError) as e:
        raise ValueError(f"prediction input is not an array of numbers: {e}") from e
    single = x.ndim == 4
    if single:
        x = x[None]
    want = (model.config["in_channels"],) + tuple(model.grid)
    if x.ndim != 5 or x.shape[1:] != want:
        cloud = "; a point cloud [N, 6] is put on the grid by augsim.predict or `augsim predict`" if x.ndim == 2 else ""
        raise ValueError(f"input shape {np.shape(grid_input)}, but the model expects {list(want)} "
                         f"(or a batch [N, {', '.join(map(str, want))}]){cloud}")
    unfit = np.flatnonzero(~(np.abs(x) <= MAX_FIELD_VALUE))  # NaN compares false
    if len(unfit):
        sample, i = divmod(int(unfit[0]), x[0].size)
        where = "" if single else f"sample {sample}: "
        raise ValueError(f"{where}prediction input value {i} is {_rust_e(x.flat[unfit[0]])}: inputs are finite "
                         f"displacements (m) or forces (N) within {_rust_e(MAX_FIELD_VALUE)}")
    xn = (x.astype(np.float64) * (1.0 / model.input_scale)).astype(np.float32)
    device = next(model.parameters()).device
    with torch.inference_mode():
        y = model(torch.from_numpy(xn).to(device)).cpu().numpy()
    out = (y.astype(np.float64) * model.target_scale).astype(np.float32)
    return out[0] if single else out


def main(argv=None):
    """``python -m augsim.torch MODEL_DIR INPUT.npy OUTPUT.npy``: writes the prediction as .npy."""
    argv = sys.argv[1:] if argv is None else argv
    if len(argv) != 3 or argv[0] in ("-h", "--help"):
        print("usage: python -m augsim.torch MODEL_DIR INPUT.npy OUTPUT.npy\n"
              "  INPUT: grid tensor [3, nx, ny, nz] on the model grid (model input unit);\n"
              "  OUTPUT: float32 displacement [3, nx, ny, nz] (m), as `augsim predict` writes",
              file=sys.stderr)
        return 2
    try:
        model = load(argv[0])
        with open(argv[1], "rb") as f:
            if f.read(6) != b"\x93NUMPY":
                raise ValueError(f"{argv[1]}: not a .npy file")
            f.seek(0)
            try:
                out = predict(model, np.load(f))
            except ValueError as e:
                raise ValueError(f"{argv[1]}: {e}") from e
        buffer = io.BytesIO()
        np.save(buffer, out)
        write_atomic(argv[2], buffer.getvalue())
    except OSError as e:
        print(f"error: {e.filename}: {e.strerror}" if e.filename and e.strerror else f"error: {e}", file=sys.stderr)
        return 1
    except ValueError as e:
        print(f"error: {e}", file=sys.stderr)
        return 1
    print(f"wrote {argv[2]}: shape {list(out.shape)}, max |u| component {np.abs(out).max():.4e} m")
    return 0


if __name__ == "__main__":
    sys.exit(main())
