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


@pytest.mark.parametrize("sorted_lanes", [True, False])
@pytest.mark.parametrize("slots_per_pair", [1, 4])
def test_reduce_pairs_adds_each_gaussians_pairs_in_generation_order(slots_per_pair, sorted_lanes, monkeypatch):
    """`reduce_pairs` gives, bit for bit, the float32 sum that adds Gaussian g's pair records
    in generation order (``offsets[g]`` upwards; a pair's S slots in slot order), whatever
    order it runs its lanes in (index order, or ascending pair count, `binning.count_order`,
    from `SORT_MIN_PAIRS` pairs on: forced here). NumPy's element-wise float32 adds in that
    order are the specification: same operands, same order, so the same bits."""
    from splatbench.raster.binning import bin_gaussians
    from splatbench.raster.device import get_device
    from splatbench.raster.reduction import PAIR_GROUPS, reduce_pairs

    monkeypatch.setattr(reduction, "SORT_MIN_PAIRS", 0 if sorted_lanes else 1 << 31)
    from tests.test_raster_binning import bins_of, culling_scene

    workload = culling_scene(600, seed=5)
    bins, _ = bins_of(workload, bin_gaussians)
    m = get_device("cpu").t
    counts, offsets, order = bins.counts.numpy(), bins.offsets.numpy(), bins.order.numpy()
    assert counts.max() >= 4 * max(np.median(counts[counts > 0]), 1)  # packets of unequal loops
    rng = np.random.default_rng(slots_per_pair)
    width = PAIR_GROUPS["geo"][0]
    slots = rng.standard_normal(width * bins.num_pairs * slots_per_pair).astype(np.float32)
    sums = reduce_pairs(m, bins, {"geo": m.Float(slots)}, len(counts), slots_per_pair)
    inverse = np.empty_like(order)
    inverse[order] = np.arange(len(order))
    records = slots.reshape(-1, width)
    expected = np.zeros((len(counts), width), np.float32)
    for step in range(counts.max()):
        live = counts > step
        slot = inverse[offsets[live] + step] * slots_per_pair
        for sub in range(slots_per_pair):
            expected[live] = expected[live] + records[slot + sub]
    for k, key in enumerate(PAIR_GROUPS["geo"][1]):
        if key is None:  # padding, never read
            continue
        np.testing.assert_array_equal(sums[key].numpy(), expected[:, k], err_msg=key)
