"""How many pixel-Gaussian evaluations compositing would perform with other lane layouts
(counts only, deterministic: valid on a loaded machine).

    python tools/lane_packing.py guitar            # a bundled model, view 0 of 1 at 400x300
    python tools/lane_packing.py biker 1280x720
    python tools/lane_packing.py synthetic:10000 256x256

A lane shades a B x B block of pixels and walks its own list (`splatbench.raster.blocks`);
the lanes of a SIMD packet (16 with AVX-512) run until the longest list among them ends,
so a packet costs 16 x B^2 x its longest list. For each (tile_size, B) this prints that
cost with the lanes as the rasterizer lays them out (tile by tile; within a tile of
more lanes than a packet, sorted by list length: `blocks.sort_lanes_by_length`; this is
`work_stats(..., RasterOptions(tile_size=T, pixel_block=B))`'s `performed`), with every tile's lanes sorted by list length
exactly (packets stay inside a tile),
and with all lanes sorted by length (packets mix tiles), beside the list entries x B^2
(no idle lane at all) and the useful evaluations (`work_stats(...).useful`, which no
layout changes). It says nothing about time: smaller blocks share each record load among
fewer pixels and cost more list building (issue 30; tools/lane_timing.py times the layouts,
docs/benchmarks.md "Lane layouts in wall time").
"""

from __future__ import annotations

import sys

import numpy as np

from splatbench.raster.api import to_tensor
from splatbench.raster.blocks import lanes_for
from splatbench.raster.compositing import splat_records
from splatbench.raster.device import dr, get_device
from splatbench.raster.options import RasterOptions
from splatbench.raster.binning import bin_gaussians
from splatbench.raster.projection import project
from splatbench.raster.work import work_stats
from splatbench.workloads import model_workload, synthetic

PACKET = 16  # lanes per SIMD packet (AVX-512)
LAYOUTS = ((16, 4), (16, 2), (32, 4), (32, 2), (8, 2))  # (tile_size, B)


def list_lengths(gaussians, camera, tile_size: int, block: int) -> np.ndarray:
    """[lanes] the length of each lane's list, lanes in tile order."""
    m = get_device("cpu").t
    opts = RasterOptions(device="cpu", tile_size=tile_size)
    with dr.suspend_grad():
        proj = project(*(to_tensor(m, getattr(gaussians, k)) for k in
                         ("means", "log_scales", "quats", "opacity_logits")), camera, opts)
        lanes = lanes_for(m, splat_records(proj), bin_gaussians(proj, camera, opts), block)
        return (lanes.end - lanes.start).numpy().astype(np.int64)


def packet_cost(lengths: np.ndarray, pixels: int) -> int:
    """Evaluations of consecutive packets of `PACKET` lanes, each running its longest list."""
    padded = np.pad(lengths, (0, -len(lengths) % PACKET))
    return int(padded.reshape(-1, PACKET).max(axis=1).sum()) * PACKET * pixels


def main(argv: list[str]) -> int:
    if not argv:
        print(__doc__)
        return 2
    size = argv[1] if len(argv) > 1 else "400x300"
    width, height = (int(v) for v in size.lower().split("x"))
    if argv[0].startswith("synthetic:"):
        workload = synthetic(int(argv[0].split(":", 1)[1]), width, height, 0)
    else:
        workload = model_workload(argv[0], 0, 1, width, height)
    g, cam = workload.gaussians, workload.camera
    useful = work_stats(g, cam, RasterOptions(device="cpu")).useful
    print(f"{workload.name} {width}x{height}: useful evaluations {useful:,}")
    print("tile  B  | entries x B^2   | as rasterized   | sorted in tile  | sorted overall")
    for tile_size, block in LAYOUTS:
        lengths = list_lengths(g, cam, tile_size, block)
        pixels = block * block
        per_tile = (tile_size // block) ** 2
        in_tile = np.sort(lengths.reshape(-1, per_tile), axis=1).reshape(-1)
        costs = [int(lengths.sum()) * pixels, packet_cost(lengths, pixels), packet_cost(in_tile, pixels),
                 packet_cost(np.sort(lengths), pixels)]
        print(f"{tile_size:4d}  {block}  | " + " | ".join(f"{c / 1e6:6.2f} M {100 * useful / c:4.1f} %" for c in costs))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
