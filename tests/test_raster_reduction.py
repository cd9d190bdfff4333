"""The per-lane-slot gradient reduction (the CUDA path), exercised on LLVM.

`reduction.lane_group` picks it (a group of one lane) wherever Dr.Jit's LLVM-only
Expand mode is unavailable. No GPU is needed to check its arithmetic: forcing it on LLVM must give
the gradients of the default path up to float32 summation order.
"""

from __future__ import annotations

import numpy as np
import pytest

from splatbench.raster import reduction
from tests.compare import assert_grads_agree
from tests.gradcheck import GROUPS, Cotangents, fast_vjp
from tests.scenes import parity_scene

# The two paths add the same per-(pixel block, pair) terms in different orders: the
# default adds a tile's 16 lanes into one slot, the per-lane path adds the 16 lane
# slots one by one into the Gaussian's running sum. Each reordering of a float32 sum
# of M terms changes it by at most (M - 1) * 2^-24 * sum|terms|; a Gaussian here sums
# at most a few hundred terms, so the relative L2 difference stays well below
# 300 * 6e-8 = 2e-5 unless cancellation is severe, which a relative L2 over all
# Gaussians averages out.
REL_L2 = 2e-5
COSINE = 1 - 1e-9


@pytest.mark.parametrize("seed", [0, 4])
def test_per_lane_slots_match_the_shared_slot(seed, monkeypatch):
    workload, background = parity_scene(seed)
    c = workload.camera
    v = Cotangents.standard_normal(seed, c.height, c.width)
    shared = fast_vjp(workload, v, background=background, device="cpu")
    monkeypatch.setattr(reduction, "lane_group", lambda m: 1)
    per_lane = fast_vjp(workload, v, background=background, device="cpu")
    again = fast_vjp(workload, v, background=background, device="cpu")
    np.testing.assert_array_equal(shared.rgb, per_lane.rgb)  # the forward pass is the same
    for k in GROUPS:
        assert np.abs(shared.grads[k]).max() > 0, k
        assert_grads_agree(f"{workload.name} {k}", per_lane.grads[k], shared.grads[k], rel_l2=REL_L2, cosine=COSINE)
        np.testing.assert_array_equal(per_lane.grads[k], again.grads[k])  # reproducible


def test_lanes_share_a_slot_per_packet_on_llvm_only():
    import drjit.llvm.ad as llvm

    from splatbench import _llvm

    assert reduction.lane_group(llvm) == _llvm.packet_width() >= _llvm.MIN_PACKET_WIDTH
    assert reduction.lane_group(type("cuda", (), {"__name__": "drjit.cuda.ad"})) == 1


@pytest.mark.parametrize("features, width", [("+sse4.2,+avx,+avx2,+avx512f,+avx512vl", 16),
                                             ("+sse4.2,+avx,+avx2,+avx512f,-avx512vl", 8),
                                             ("+sse4.2,-avx,-avx2", 4), ("+neon", 4), ("", 4)])
def test_packet_width_follows_drjits_rule(features, width):
    from splatbench import _llvm

    assert _llvm.packet_width(features) == width
