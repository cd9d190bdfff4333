"""`FusedAdam`: one parameter group's Adam, torch's fused kernel called directly.

Training keeps one Adam per parameter group (`splatbench.train.params.make_optimizers`).
``torch.optim.Adam(fused=True)`` runs one kernel per step, ``torch._fused_adam_``, but
the ``torch.optim.Optimizer`` machinery around it imports ``torch._dynamo`` (and sympy)
the first time any of its methods runs (their ``_disable_dynamo`` wrappers): about
70 MB of a training process's resident memory that nothing else in training uses
(docs/benchmarks.md, "Training"), and a few Python layers per step. `FusedAdam` calls
the same kernel with the same arguments in the same order (the step count
incremented first, then ``torch._fused_adam_``), so its updates are bit-identical to
``torch.optim.Adam(fused=True)``'s (`tests/test_adam.py` compares them step by step,
and its ``state_dict`` has torch's layout, so checkpoints written by either load
into either).

What the strategies (`splatbench.strategies.ops`) and checkpoints use is kept:
``param_groups`` (one group: ``params``, ``lr``, ``name``, ``betas``, ``eps``, ...),
``state`` (tensor -> ``{"step", "exp_avg", "exp_avg_sq"}``, created at the first step a
tensor has a gradient), ``zero_grad``, ``step``, ``state_dict``, ``load_state_dict``.
Not supported (training never uses them): several groups, closures, weight decay,
AMSGrad, hooks.
"""

from __future__ import annotations

from typing import Any

import torch

from splatbench.errors import InputError

#: torch.optim.Adam's defaults for the hyperparameters training leaves alone (its state_dict keys).
_GROUP_DEFAULTS = {"betas": (0.9, 0.999), "weight_decay": 0, "amsgrad": False, "maximize": False, "foreach": None,
                   "capturable": False, "differentiable": False, "fused": True, "decoupled_weight_decay": False}
_MOMENTS = ("exp_avg", "exp_avg_sq")


class FusedAdam:
    """Adam on one tensor ``param`` [any shape], float32 on the CPU or CUDA.

    Args:
        param: the leaf tensor it updates (replaceable in ``param_groups[0]["params"]``).
        lr: learning rate (``param_groups[0]["lr"]``, read at every step).
        eps: Adam's epsilon (3DGS: 1e-15). name: the group's name (kept in its state dict).
    """

    def __init__(self, param: torch.Tensor, *, lr: float, eps: float, name: str = "") -> None:
        if not isinstance(param, torch.Tensor) or param.dtype != torch.float32:
            raise InputError(f"FusedAdam {name}: expected a float32 tensor, got "
                             f"{getattr(param, 'dtype', type(param).__name__)}")
        self.param_groups: list[dict[str, Any]] = [{"params": [param], "lr": lr, "eps": eps, "name": name,
                                                    **_GROUP_DEFAULTS}]
        self.state: dict[torch.Tensor, dict[str, torch.Tensor]] = {}

    def zero_grad(self, set_to_none: bool = True) -> None:
        """Drop (``set_to_none``) or zero the gradient of the group's tensor."""
        for p in self.param_groups[0]["params"]:
            if p.grad is None:
                continue
            if set_to_none:
                p.grad = None
            else:
                p.grad.detach_().zero_()

    @torch.no_grad()
    def step(self) -> None:
        """One Adam update of the group's tensor if it has a gradient (else nothing)."""
        group = self.param_groups[0]
        beta1, beta2 = group["betas"]
        for p in group["params"]:
            if p.grad is None:
                continue
            state = self.state.get(p)
            if not state:  # as torch's fused Adam: the step count a float32 scalar where the tensor lives
                state = self.state[p] = {"step": torch.zeros((), dtype=torch.float32, device=p.device),
                                         "exp_avg": torch.zeros_like(p, memory_format=torch.preserve_format),
                                         "exp_avg_sq": torch.zeros_like(p, memory_format=torch.preserve_format)}
            steps = [state["step"]]
            torch._foreach_add_(steps, 1)
            torch._fused_adam_([p], [p.grad], [state["exp_avg"]], [state["exp_avg_sq"]], [], steps,
                               amsgrad=False, lr=group["lr"], beta1=beta1, beta2=beta2, weight_decay=0.0,
                               eps=group["eps"], maximize=False, grad_scale=None, found_inf=None)

    def state_dict(self) -> dict[str, Any]:
        """torch.optim's layout: ``{"state": {0: {...}}, "param_groups": [{..., "params": [0]}]}``
        (the tensors themselves, not copies, as torch's)."""
        group = self.param_groups[0]
        p = group["params"][0]
        return {"state": {0: dict(self.state[p])} if self.state.get(p) else {},
                "param_groups": [{**{k: v for k, v in group.items() if k != "params"}, "params": [0]}]}

    def load_state_dict(self, state_dict: dict[str, Any]) -> None:
        """Restore a `state_dict` (this class's or ``torch.optim.Adam``'s, one group of one
        tensor): hyperparameters and the moments, moved to the tensor's device; the shapes
        are checked (a one-line `InputError` names the group)."""
        group = self.param_groups[0]
        p = group["params"][0]
        where = f"optimizer {group['name']!r}" if group["name"] else "optimizer"
        try:
            (saved,) = state_dict["param_groups"]
            states = state_dict["state"]
            if saved["params"] != [0] or set(states) - {0}:
                raise ValueError("expected one group of one tensor")
            for key in ("lr", "eps", "betas"):
                group[key] = saved[key] if key != "betas" else tuple(float(b) for b in saved[key])
            if states:
                s = states[0]
                for key in _MOMENTS:
                    if tuple(s[key].shape) != tuple(p.shape):
                        raise ValueError(f"{key} has shape {list(s[key].shape)}, the tensor {list(p.shape)}")
                self.state = {p: {"step": s["step"].to(device=p.device, dtype=torch.float32).reshape(()),
                                  **{key: s[key].to(device=p.device, dtype=p.dtype) for key in _MOMENTS}}}
            else:
                self.state = {}
        except (KeyError, TypeError, ValueError, AttributeError) as exc:
            raise InputError(f"{where}: the saved Adam state does not fit ({exc})") from None


__all__ = ["FusedAdam"]
