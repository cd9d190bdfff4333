"""Per-pair gradient buffers of the compositing backward pass (`PairBuffers`) and their
deterministic reduction per Gaussian (used by `compositing._CompositeOp`)."""

from __future__ import annotations

from typing import NamedTuple

from splatbench.raster.device import dr, packet_width
from splatbench.raster.binning import Bins, count_order
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


def lane_group(m) -> int:
    """How many consecutive lanes of a tile share one accumulator slot per pair: a SIMD
    packet's worth on LLVM (`device.packet_width`), where ``ReduceMode.Expand`` adds the
    lanes of one packet in a fixed order into a per-thread copy; 1 elsewhere (CUDA), where
    each lane writes a slot of its own without atomics.

    Why a packet and not a tile: Dr.Jit's LLVM backend splits a launch into blocks of
    whole packets, but not of whole tiles (with two threads and a few packets, a block
    is half of them), and two threads adding into one slot, or one thread adding two
    blocks in either order, rounds differently from run to run. A tile wider than a
    packet (tile_size 32 with 16-lane packets: 64 lanes) therefore gets one slot per
    packet, summed in packet order by the reduction."""
    return packet_width(m)


class PairBuffers(NamedTuple):
    """Per-pair gradient accumulators, `PAIR_GROUPS` name -> Float buffer of S slots per
    pair (S = lanes_per_tile / `lane_group`, at least 1). Slot (p, s) belongs to one
    (tile, Gaussian) pair and one group of consecutive lanes of that tile: on LLVM the
    lanes of one SIMD packet, which add into it with ``ReduceMode.Expand`` (per-thread
    copies, non-atomic, in a fixed lane order: a packet never spans two threads); elsewhere
    (CUDA) one lane, which writes it once, without atomics. Either way no slot's value
    depends on thread scheduling."""

    groups: dict
    slots_per_pair: int  # S
    sub_slot: object     # UInt32 (lane % lanes_per_tile) // lane_group: the lane's slot of a pair
    expand: bool         # True: several lanes add into a slot (LLVM); False: one lane writes it

    @classmethod
    def allocate(cls, m, bins: Bins, lanes: Lanes, keys) -> PairBuffers:
        cap = bucket(bins.num_pairs)  # slots past num_pairs stay zero and are never read
        L = lanes.lanes_per_tile
        group = min(lane_group(m), L)
        S = L // group  # powers of two
        groups = {name: dr.zeros(m.Float, size * cap * S) for name, (size, group_keys) in PAIR_GROUPS.items()
                  if any(key in keys for key in group_keys)}
        sub_slot = (dr.arange(m.UInt32, dr.width(lanes.start)) % L) // group
        return cls(groups, S, sub_slot, group > 1)

    def add(self, m, p, sums: dict, active) -> None:
        """Add one step's terms (``sums``: key -> Float, summed over a lane's pixels) into pair slot ``p``."""
        for name, buffer in self.groups.items():
            values = m.ArrayXf([sums[key] if key in sums else 0.0 for key in PAIR_GROUPS[name][1]])
            slot = p * self.slots_per_pair + self.sub_slot
            if self.expand:
                dr.scatter_add(buffer, values, slot, active, mode=dr.ReduceMode.Expand)
            else:
                dr.scatter(buffer, values, slot, active)


#: The fewest pairs at which `reduce_pairs` runs its lanes in order of pair count (a power of
#: two, from tools/reduction_ab.py: at 1.9 M pairs the sort saved 24 ms of a 53 ms reduction; at
#: 156 k pairs the reduction took 0.9 ms in either order).
SORT_MIN_PAIRS = 1 << 19


def reduce_pairs(m, bins: Bins, pair: dict, n: int, slots_per_pair: int = 1) -> dict:
    """Sum per-pair gradient records per Gaussian, deterministically.

    With ``slots_per_pair`` S > 1, pair p's records sit at slots p * S .. p * S + S - 1
    and are summed in that order.

    The pairs of Gaussian g sit at generation positions offsets[g] .. offsets[g] + counts[g]
    (binning generates them Gaussian by Gaussian, in ascending tile order), i.e. at sorted
    positions inverse_order[j]; each Gaussian lane sums its own pairs in that order, so the
    result does not depend on thread scheduling.
    """
    Float, UInt32 = m.Float, m.UInt32
    inverse = dr.zeros(UInt32, bins.num_pairs)
    dr.scatter(inverse, dr.arange(UInt32, bins.num_pairs), bins.order, mode=dr.ReduceMode.Permute)
    # With many pairs, lane k sums the pairs of Gaussian by_count[k]: the Gaussians in
    # ascending order of their pair counts, so the lanes of a SIMD packet loop about equally
    # long (in index order a packet runs as long as its largest Gaussian: 2.6x the pairs' work
    # at 128^2 with 20k Gaussians, 4.3x at 800^2 with 100k). Each lane still sums its own pairs
    # in generation order, so the sums are bit-identical either way; the sort waits for the
    # backward walk (a counting sort runs synchronously), which costs more than it saves
    # where the reduction takes a millisecond or two (`SORT_MIN_PAIRS`).
    by_count = count_order(bins.counts) if bins.num_pairs >= SORT_MIN_PAIRS else None
    begin = bins.offsets if by_count is None else dr.gather(UInt32, bins.offsets, by_count)
    end = begin + (bins.counts if by_count is None else dr.gather(UInt32, bins.counts, by_count))
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
    state = [begin] + [Float(zero) for _, (width, _) in groups for _ in range(width)]
    final = dr.while_loop(tuple(state), cond, body, mode="symbolic")[1:]
    sums, pos = {}, 0
    for _, (width, keys) in groups:
        for k, key in enumerate(keys):
            if key is None:
                continue
            if by_count is None:
                sums[key] = final[pos + k]
            else:
                sums[key] = dr.zeros(Float, n)
                dr.scatter(sums[key], final[pos + k], by_count, mode=dr.ReduceMode.Permute)
        pos += width
    # A kernel of its own: fused with the preprocess's AD backward that reads the sums, the
    # loop carried that code's loop-invariant inputs through every iteration (measured 7.7 ms
    # for the fused kernel against 0.5 + 2.2 ms split, 10k Gaussians at 256^2, one thread).
    dr.eval(sums)
    return sums
