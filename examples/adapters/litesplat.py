"""splatbench backend for LiteSplat (PyPI `litesplat`, Apache-2.0): "a minimal, portable Gaussian
Splatting sandbox ... in pure Python and Keras".

Install it and Keras (whose torch backend LiteSplat's code needs: it assigns into tensors in place)
apart from splatbench's environment and put them on the path:

    pip install --no-deps --target out/conform_public/site-litesplat \
        litesplat==0.1.1 keras==3.15.1 absl-py==2.5.1 namex==0.1.0 optree==0.20.0 ml-dtypes==0.6.0 h5py==3.16.0
    KERAS_BACKEND=torch PYTHONPATH=.:out/conform_public/site-litesplat \
        splatbench conform examples.adapters.litesplat:render

Faithful: LiteSplat reads a scene folder (`gaussians.json`, `camera.json`, in the formats its own
COLMAP converter `litesplat/io/COLMAP.py` writes: camera `rotation` = COLMAP's world -> camera
matrix, `translation` = its t, intrinsics fx, fy, cx, cy; each Gaussian a `position`, an RGB `color`
in [0, 1], a `rotation` quaternion [w, x, y, z], linear `scale`s and an `opacity` in [0, 1]). The
adapter writes exactly that for each call, renders with its `Renderer([CameraLayer(...)], H, W)(camera_ids=[0], render=False)`
at full resolution, and turns the image top-down: LiteSplat's images are bottom-up (it flips its
training images with `FLIP_TOP_BOTTOM`, `core/camera_model.py`). It declares only what LiteSplat's
API fixes: colours are RGB (no SH: `sh_degree=0`, the colour is graphdeco's degree-0 colour
SH_C0 * sh[:, 0] + 0.5), no background argument (`background="ignored"`), only an RGB image comes
back (`outputs=("rgb",)`), and the Gaussians are Keras weights read from the files, so splatbench's
tensors get no gradients (`gradients=False`).
"""

from __future__ import annotations

import json
import os
import tempfile
from importlib.metadata import PackageNotFoundError, version

import numpy as np
import torch

from splatbench.backends import BackendInfo

os.environ.setdefault("KERAS_BACKEND", "torch")  # LiteSplat's in-place tensor writes need torch's
try:
    from litesplat.core import CameraLayer, GaussianParameterLayer
    from litesplat.utils import Renderer
except ImportError as e:  # one line, with the fix
    raise ImportError("examples.adapters.litesplat needs litesplat and keras on PYTHONPATH: see the "
                      "pip install line in examples/adapters/litesplat.py") from e

SH_C0 = 0.28209479177387814


def _version() -> str:
    try:
        return version("litesplat")
    except PackageNotFoundError:
        return "unknown"


def render(means, log_scales, quats, opacity_logits, sh, camera, *, sh_degree=None, background=None):
    """splatbench's backend signature (splatbench/backends/base.py) -> rgb [H, W, 3], alpha [H, W], depth [H, W]
    (alpha and depth zeros: LiteSplat returns an RGB image only).

    means [N, 3]; log_scales [N, 3]; quats [N, 4] (w, x, y, z); opacity_logits [N]; sh [N, K, 3]."""
    with torch.no_grad():
        colour = (SH_C0 * sh[:, 0, :] + 0.5).clamp_min(0.0)
        g = {"position": means, "color": colour, "rotation": quats, "scale": log_scales.exp(),
             "opacity": torch.sigmoid(opacity_logits)}
        g = {k: v.detach().cpu().double().numpy() for k, v in g.items()}
    n = g["position"].shape[0]
    gaussians = [{"position": g["position"][i].tolist(), "color": g["color"][i].tolist(),
                  "rotation": g["rotation"][i].tolist(), "translation": g["position"][i].tolist(),
                  "scale": g["scale"][i].tolist(), "opacity": float(g["opacity"][i])} for i in range(n)]
    w2c = np.asarray(camera.world_to_camera, dtype=np.float64)
    cam = [{"camera_id": 1, "model": "PINHOLE", "image_name": "probe.png",
            "width": camera.width, "height": camera.height,
            "fx": camera.fx, "fy": camera.fy, "cx": camera.cx, "cy": camera.cy,
            "rotation": w2c[:3, :3].tolist(), "translation": w2c[:3, 3].tolist()}]
    with tempfile.TemporaryDirectory() as scene:
        with open(os.path.join(scene, "gaussians.json"), "w") as f:
            json.dump(gaussians, f)
        with open(os.path.join(scene, "camera.json"), "w") as f:
            json.dump(cam, f)
        layer = CameraLayer(scene, GaussianParameterLayer(scene, trainable=False))
        img = Renderer([layer], camera.height, camera.width)(camera_ids=[0], render=False)[0]
    rgb = torch.as_tensor(np.asarray(img.detach().cpu() if hasattr(img, "detach") else img))
    rgb = rgb.flip(0).to(device=means.device, dtype=means.dtype)  # bottom-up -> top-down
    zeros = torch.zeros(rgb.shape[:2], dtype=means.dtype, device=means.device)
    return rgb, zeros, zeros


render.backend_info = BackendInfo(
    name="litesplat", version=_version(), devices=("cpu",), gradients=False, outputs=("rgb",),
    sh_degree=0, background="ignored",
    description="LiteSplat's CameraLayer (litesplat/core/camera_model.py) on its own scene files")
