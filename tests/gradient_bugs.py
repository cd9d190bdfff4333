"""Real-size backends with one gradient bug each, for `compare` and `check` on real models.

`tests/broken_backends.py` is dense (every Gaussian at every pixel): too slow for a real trained
model. These wrap the built-in ``torch`` backend (tiled, real-size) and change one line of its
maths while it renders: the same forward, one wrong gradient.

    conic_b_half   the gradient of the off-diagonal conic term B halved (a symmetric matrix's
                   off-diagonal counted once), as `tests/broken_backends.py` conic_b_grad_half
"""

from __future__ import annotations

import contextlib

from splatbench.backends import Backend, BackendInfo
from splatbench.backends.builtins import torch_backend

_SCREEN = torch_backend.screen
_TORCH = torch_backend.make_torch_backend()


def _screen_conic_b_half(*args, **kwargs):
    import torch

    out = _SCREEN(*args, **kwargs)
    A, B, C = out.conics.unbind(1)
    B = B.detach() + 0.5 * (B - B.detach())  # the bug: the same value, half its gradient
    return out._replace(conics=torch.stack([A, B, C], 1))


@contextlib.contextmanager
def _swapped(screen):
    torch_backend.screen = screen
    try:
        yield
    finally:
        torch_backend.screen = _SCREEN


def _conic_b_half(means, log_scales, quats, opacity_logits, sh, camera, *, sh_degree=None, background=None):
    with _swapped(_screen_conic_b_half):
        return _TORCH(means, log_scales, quats, opacity_logits, sh, camera, sh_degree=sh_degree, background=background)


#: `splatbench compare --backend tests.gradient_bugs:conic_b_half` (the repository root on PYTHONPATH).
conic_b_half = Backend(_conic_b_half, BackendInfo(name="torch[conic_b_half]", tile_size=0,
                                                  description="torch with the conic B gradient halved"))
