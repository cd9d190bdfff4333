"""Checks the findings of reports/conform_public/litesplat/report.md: LiteSplat 0.1.1 with its four
bugs corrected in memory, through the same adapter, under conform. Not a backend anyone should use:
a what-if.

    KERAS_BACKEND=torch PYTHONPATH=.:out/conform_public/site-litesplat \
        python tools/verify_litesplat.py [rot,pix,flip,sort] [--declare-dense]

Each name corrects one bug (all four by default), by editing LiteSplat's source text of
`CameraLayer.render_pixel_color` / replacing `get_sorted_keys` in this process only:
  rot   camera_model.py:396  net_rot = R * rot^T elementwise  ->  R @ rot
  pix   camera_model.py:431  pixels sampled at integer coordinates  ->  at pixel centres (+0.5)
  flip  camera_model.py:388  the 2D mean is flipped (v -> H - v), its covariance is not  ->  flip both
  sort  camera_model.py:169  sorted by distance to the translation vector t  ->  to the camera centre -R^T t
--declare-dense adds what LiteSplat does by design and the vocabulary can say: no eps2d, no
Jacobian clamp, no alpha clamp or skip, no cutoff (dense), no early stop, sorted by distance.
"""

from __future__ import annotations

import dataclasses
import inspect
import os
import sys
import textwrap

os.environ.setdefault("KERAS_BACKEND", "torch")

import keras  # noqa: E402
from litesplat.core import camera_model as cm  # noqa: E402

import examples.adapters.litesplat as adapter  # noqa: E402
from splatbench.backends import Backend  # noqa: E402
from splatbench.conform import conform  # noqa: E402

FIXES = {
    "rot": ("keras.ops.einsum('ij, bji -> bij', keras.ops.array(R), self.gaussians.get_rotations())",
            "keras.ops.einsum('ij, bjk -> bik', keras.ops.array(R), self.gaussians.get_rotations())"),
    "pix": ("delta = XY[:, None, :]", "delta = (XY + 0.5)[:, None, :]"),
    "flip": ("Sigma_inv = keras.ops.inv(Sigma2D)",
             "Sigma2D = Sigma2D * keras.ops.convert_to_tensor([[1.0, -1.0], [-1.0, 1.0]]); "
             "Sigma_inv = keras.ops.inv(Sigma2D)"),
}
DENSE = dict(eps2d=0.0, jacobian_clamp="none", alpha_max=1.0, alpha_min=0.0, radius="none",
             transmittance_min=0.0, tile_size=0, sort_key="distance")


def _sorted_keys_from_camera_centre(self):
    R, t = keras.ops.convert_to_tensor(self.rotations), keras.ops.convert_to_tensor(self.translations)
    centre = -keras.ops.einsum("ji,j->i", R, t)
    d = keras.ops.sqrt(keras.ops.sum((self.gaussians.positions - centre) ** 2, axis=-1))
    self.sorted_indices = keras.ops.argsort(d, axis=0)


def main(argv: list[str]) -> None:
    names = [a for a in argv if not a.startswith("--")]
    fixes = names[0].split(",") if names else ["rot", "pix", "flip", "sort"]
    src = textwrap.dedent(inspect.getsource(cm.CameraLayer.render_pixel_color))
    for f in fixes:
        if f in FIXES:
            old, new = FIXES[f]
            assert old in src, f"LiteSplat's source changed: {old!r} not found"
            src = src.replace(old, new)
    ns: dict = {}
    exec(compile(src, cm.__file__, "exec"), cm.__dict__, ns)  # LiteSplat's own code, edited as above
    cm.CameraLayer.render_pixel_color = ns["render_pixel_color"]
    if "sort" in fixes:
        cm.CameraLayer.get_sorted_keys = _sorted_keys_from_camera_centre
    info = adapter.render.backend_info
    if "--declare-dense" in argv:
        info = dataclasses.replace(info, **DENSE)
    rep = conform(Backend(adapter.render, info), device="cpu")
    print(f"fixed: {','.join(fixes)}; declared: {', '.join(info.declared)}")
    for status in ("pass", "explained", "warn", "fail", "skip"):
        names = [r.name for r in rep.results if r.status == status]
        print(f"  {status} ({len(names)}): {' '.join(names)}")
    print("  diagnosis:", "; ".join(f"{d.axis}: {d.found}" + "".join(f" or {v}" for v in d.alike)
                                    for d in rep.diagnosis) or "none")
    print("  defects:", "; ".join(d.probe for d in rep.defects) or "none")
    for d in rep.defects:
        print(f"    {d.probe} (+{len(d.follows)} follow): {d.cause}")


if __name__ == "__main__":
    main(sys.argv[1:])
