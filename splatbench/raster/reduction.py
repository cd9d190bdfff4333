"""Per-pair gradient buffers of the compositing backward pass (`PairBuffers`) and their
deterministic reduction per Gaussian (used by `compositing._CompositeOp`)."""

from __future__ import annotations

from typing import NamedTuple

from splatbench.raster.device import dr
from splatbench.raster.binning import Bins
from splatbench.raster.blocks import Lanes
from splatbench.raster.records import COL, COLOUR_GRAD_KEYS, GEO, GEO_GRAD_KEYS

# Per-pair gradient accumulators, packed like the records (`records.GeoRecord` order) so
# that the backward loop does one packet scatter-add per group and the reduction one packet
# load per pair: name -> (width, the gradient key of each slot; None: padding, never read).
PAIR_GROUPS = {
    "geo": (GEO, tuple(GEO_GRAD_KEYS)),
    "col": (COL, (*COLOUR_GRAD_KEYS, None)),
    "abs": (2, ("ax", "ay")),
}


def bucket(n: int) -> int:
    """``n`` rounded up to 8 steps per power of two (<= 12.5% more). The Expand-mode
    scatter bakes its target's size into the kernel, so sizing the per-pair buffers by
    the exact pair count compiled a new backward kernel (seconds) for almost every
    training step; bucketed sizes reuse a few cached kernels."""
    p = 1 << max(int(n).bit_length() - 4, 0)
    return -(-n // p) * p


def lane_slots(m) -> bool:
    """Whether each lane of a tile accumulates into a slot of its own (True except on
    LLVM, whose Expand mode makes the shared slot deterministic). Per-lane slots cost
    lanes_per_tile (16 at the default sizes) times the per-pair buffer memory."""
    return not m.__name__.startswith("drjit.llvm")


class PairBuffers(NamedTuple):
    """Per-pair gradient accumulators, `PAIR_GROUPS` name -> Float buffer. Slot p
    belongs to one (tile, Gaussian) pair, so only the lanes of one tile ever add into it.
    Expand (LLVM): per-thread copies, non-atomic updates; still deterministic: a slot is
    only written by the lanes of one tile, and a tile never spans two threads. Per-lane
    slots (CUDA, `lane_slots`): each slot is written once, by one lane, without atomics."""

    groups: dict
    slots_per_pair: int  # L: lanes per tile with per-lane slots, else 1
    sub_slot: object     # UInt32 lane % L with per-lane slots, else None

    @classmethod
    def allocate(cls, m, bins: Bins, lanes: Lanes, keys) -> PairBuffers:
        cap = bucket(bins.num_pairs)  # slots past num_pairs stay zero and are never read
        per_lane = lane_slots(m)
        L = lanes.lanes_per_tile if per_lane else 1
        groups = {name: dr.zeros(m.Float, size * cap * L) for name, (size, group) in PAIR_GROUPS.items()
                  if any(key in keys for key in group)}
        sub_slot = dr.arange(m.UInt32, dr.width(lanes.start)) % L if per_lane else None
        return cls(groups, L, sub_slot)

    def add(self, m, p, sums: dict, active) -> None:
        """Add one step's terms (``sums``: key -> Float, summed over a lane's pixels) into pair slot ``p``."""
        for name, buffer in self.groups.items():
            values = m.ArrayXf([sums[key] if key in sums else 0.0 for key in PAIR_GROUPS[name][1]])
            if self.sub_slot is not None:
                dr.scatter(buffer, values, p * self.slots_per_pair + self.sub_slot, active)
            else:
                dr.scatter_add(buffer, values, p, active, mode=dr.ReduceMode.Expand)


def reduce_pairs(m, bins: Bins, pair: dict, n: int, slots_per_pair: int = 1) -> dict:
    """Sum per-pair gradient records per Gaussian, deterministically.

    With ``slots_per_pair`` L > 1 (per-lane slots), pair p's records sit at slots
    p * L .. p * L + L - 1 and are summed in that order.

    The pairs of Gaussian g sit at Gaussian-major positions offsets[g] ..
    offsets[g] + counts[g], i.e. at sorted positions inverse_order[j]; each Gaussian
    lane sums its own pairs in ascending order, so the result does not depend on
    thread scheduling.
    """
    Float, UInt32 = m.Float, m.UInt32
    inverse = dr.zeros(UInt32, bins.num_pairs)
    dr.scatter(inverse, dr.arange(UInt32, bins.num_pairs), bins.order, mode=dr.ReduceMode.Permute)
    end = bins.offsets + bins.counts
    groups = [(name, PAIR_GROUPS[name]) for name in pair]

    def cond(j, *acc):
        return j < end

    def body(j, *acc):
        slot = dr.gather(UInt32, inverse, j) * slots_per_pair
        out, pos = [j + 1], 0
        for name, (width, _) in groups:
            total = list(acc[pos: pos + width])
            for sub in range(slots_per_pair):
                rec = dr.gather(m.ArrayXf, pair[name], slot + sub, shape=(width, dr.width(j)))
                total = [total[k] + rec[k] for k in range(width)]
            out += total
            pos += width
        return tuple(out)

    zero = dr.zeros(Float, n)
    state = [UInt32(bins.offsets)] + [Float(zero) for _, (width, _) in groups for _ in range(width)]
    final = dr.while_loop(tuple(state), cond, body, mode="symbolic")[1:]
    sums, pos = {}, 0
    for _, (width, keys) in groups:
        for k, key in enumerate(keys):
            if key is not None:
                sums[key] = final[pos + k]
        pos += width
    # A kernel of its own: fused with the preprocess's AD backward that reads the sums, the
    # loop carried that code's loop-invariant inputs through every iteration (measured 7.7 ms
    # for the fused kernel against 0.5 + 2.2 ms split, 10k Gaussians at 256^2, one thread).
    dr.eval(sums)
    return sums
