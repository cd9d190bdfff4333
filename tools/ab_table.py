"""The A/B table of `bench train` runs made old/new in turns on one machine (reports/cuda).

    python tools/ab_table.py DIR [--out DIR/ab_train.csv]

DIR holds one folder per run, ``ab_<old|new>_<pair>/train.json`` (`splatbench bench train
--out`), and ``old_commit.txt`` / ``new_commit.txt``. Writes one CSV line per run and size
(variant, pair, the run's start time and load, it/s, step ms, loss share) and prints, per
size, each pair's ratio new/old, their range and the ratio of the medians.
"""

from __future__ import annotations

import argparse
import csv
import json
import statistics
from pathlib import Path


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("dir", type=Path)
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args()
    commits = {v: (args.dir / f"{v}_commit.txt").read_text().strip() for v in ("old", "new")}
    rows = []
    for path in sorted(args.dir.glob("ab_*_*/train.json")):
        _, variant, pair = path.parent.name.split("_")
        data = json.loads(path.read_text())
        machine = data["machine"]
        for r in data["results"]:
            rows.append({"variant": variant, "commit": commits[variant], "pair": int(pair),
                         "started": machine["started"], "load_start": machine["loadavg_start"][0],
                         "size": r["width"], "gaussians": r["n"], "torch_threads": data["settings"]["torch_threads"],
                         "it_per_s": r["it_per_s"], "step_ms": r["step_ms"], "loss_pct": r["loss_pct"]})
    rows.sort(key=lambda r: (r["started"], r["size"]))
    out = args.out or args.dir / "ab_train.csv"
    with open(out, "w", newline="", encoding="utf-8") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(rows[0]), lineterminator="\n")
        writer.writeheader()
        writer.writerows(rows)
    for size in sorted({r["size"] for r in rows}):
        by = {(r["variant"], r["pair"]): r["it_per_s"] for r in rows if r["size"] == size}
        pairs = sorted({p for _, p in by})
        ratios = [by[("new", p)] / by[("old", p)] for p in pairs]
        old = statistics.median(by[("old", p)] for p in pairs)
        new = statistics.median(by[("new", p)] for p in pairs)
        print(f"{size}x{size}: old {[by[('old', p)] for p in pairs]} new {[by[('new', p)] for p in pairs]} it/s; "
              f"pair ratios {[round(x, 2) for x in ratios]} (range {min(ratios):.2f}-{max(ratios):.2f}); "
              f"ratio of medians {new / old:.2f}")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
