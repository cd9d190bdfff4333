"""`splatbench.train.adam.FusedAdam` against ``torch.optim.Adam(fused=True)``: the same
kernel with the same arguments, so every update is bit-identical (not merely close),
and state dicts load across the two (a training run never imports torch._dynamo:
`tests/test_train_step_path.py`)."""

from __future__ import annotations

import pytest
import torch

from splatbench.errors import InputError
from splatbench.train.adam import FusedAdam


def _pair(shape=(50, 3), lr=1e-2, eps=1e-15):
    g = torch.Generator().manual_seed(0)
    start = torch.randn(shape, generator=g)
    a = torch.nn.Parameter(start.clone())
    b = torch.nn.Parameter(start.clone())
    ours = FusedAdam(a, lr=lr, eps=eps, name="means")
    theirs = torch.optim.Adam([{"params": [b], "lr": lr, "name": "means"}], lr=lr, eps=eps, fused=True)
    return a, b, ours, theirs, g


def _steps(a, b, ours, theirs, g, k, lrs=None):
    for i in range(k):
        grad = torch.randn(a.shape, generator=g) * 10.0 ** (i % 5 - 2)  # gradients over five decades
        if lrs is not None:
            ours.param_groups[0]["lr"] = theirs.param_groups[0]["lr"] = lrs[i]
        a.grad, b.grad = grad.clone(), grad.clone()
        ours.step()
        theirs.step()
        ours.zero_grad(set_to_none=True)
        theirs.zero_grad(set_to_none=True)


def test_updates_are_bit_identical_to_torch_fused_adam():
    a, b, ours, theirs, g = _pair()
    _steps(a, b, ours, theirs, g, 25, lrs=[1e-2 * 0.9 ** i for i in range(25)])
    assert torch.equal(a, b)
    sa, sb = ours.state[a], theirs.state[b]
    for key in ("step", "exp_avg", "exp_avg_sq"):
        assert torch.equal(sa[key], sb[key]), key
        assert sa[key].dtype == sb[key].dtype and sa[key].device == sb[key].device, key
    assert float(sa["step"]) == 25


def test_no_gradient_no_update_no_state():
    a, _, ours, _, _ = _pair()
    before = a.detach().clone()
    ours.step()
    assert torch.equal(a, before) and not ours.state


def test_state_dicts_load_across_both_ways():
    """A checkpoint written with torch.optim.Adam (older runs) resumes into FusedAdam and
    continues bit-identically, and FusedAdam's state dict loads into torch's."""
    a, b, ours, theirs, g = _pair()
    _steps(a, b, ours, theirs, g, 7)
    a2, b2 = torch.nn.Parameter(a.detach().clone()), torch.nn.Parameter(b.detach().clone())
    ours2 = FusedAdam(a2, lr=1.0, eps=1.0, name="means")
    theirs2 = torch.optim.Adam([{"params": [b2], "lr": 1.0, "name": "means"}], lr=1.0, eps=1.0, fused=True)
    ours2.load_state_dict(theirs.state_dict())
    theirs2.load_state_dict(ours.state_dict())
    assert ours2.param_groups[0]["lr"] == 1e-2 and ours2.param_groups[0]["eps"] == 1e-15
    assert ours.state_dict()["param_groups"][0].keys() == theirs.state_dict()["param_groups"][0].keys()
    _steps(a2, b2, ours2, theirs2, g, 5)
    assert torch.equal(a2, b2)
    for key in ("step", "exp_avg", "exp_avg_sq"):
        assert torch.equal(ours2.state[a2][key], theirs2.state[b2][key]), key


def test_a_state_of_another_shape_is_one_line():
    a, b, ours, theirs, g = _pair()
    _steps(a, b, ours, theirs, g, 2)
    other = FusedAdam(torch.nn.Parameter(torch.zeros(7, 3)), lr=1e-3, eps=1e-15, name="means")
    with pytest.raises(InputError, match=r"optimizer 'means': the saved Adam state does not fit \(exp_avg has "
                                         r"shape \[50, 3\], the tensor \[7, 3\]\)"):
        other.load_state_dict(ours.state_dict())

