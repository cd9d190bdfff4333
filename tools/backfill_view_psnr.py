"""Backfill each test view's PSNR into train runs finished before runs recorded it (e5194ed).

    python tools/backfill_view_psnr.py RESULTS_DIR EXPERIMENT [--dry-run]

For each done record of ``RESULTS_DIR/EXPERIMENT/`` without ``curves.test_view_psnr`` whose work
folder (``work/<run_id>/``) holds the run's final model, evaluates that model again on the run's
test views exactly as the run's final evaluation did (`splatbench.train.reevaluate`:
`Trainer.evaluate` of the saved PLY at the SH degree the run ended at), checks that the views'
mean is the record's ``metric.test_psnr`` to within float32 rendering noise (`splatbench.train.reevaluate.tolerance_db`; a
run that disagrees is refused and left as it is), and rewrites the record atomically
(`splatbench.experiments.store.write_record`) with ``curves.test_view_psnr``,
``curves.test_view_psnr_from`` (`FROM`) and ``metrics.worst_view_psnr``, as a run made since
would have recorded them. Then rewrites the experiment's ``results.parquet`` from the records
on disk (`store.save_table` of the table's own runs, under the runners' lock). A run a runner holds
(``claims/<run_id>.claim``) is never touched. One line per run; errors are one line each.
``--dry-run``: evaluate and check, write nothing.

Only evaluation runs (no training); safe beside a runner working in the same folder: records
are replaced whole, only those of finished runs nobody holds, and the table is rewritten under
the runners' lock.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
from pathlib import Path

import numpy as np

from splatbench.errors import InputError
from splatbench.experiments.store import (RunRecord, experiment_dir, read_records, read_table, save_table,
                                          write_record)

#: What a backfilled record says of where its per-view PSNRs came from (``curves.test_view_psnr_from``).
FROM = "recomputed from the run's saved final model (tools/backfill_view_psnr.py)"
def needs_backfill(record: RunRecord) -> bool:
    """A done run whose curves lack each test view's PSNR."""
    return record.status == "done" and not (isinstance(record.curves, dict) and record.curves.get("test_view_psnr"))


def backfilled(record: RunRecord, views: list[float]) -> RunRecord:
    """``record`` with the per-view PSNRs as a run records them (`splatbench.train.loop`: each
    rounded to 1e-6 dB; `TrainRun.of`: the worst in ``metrics.worst_view_psnr``) and `FROM`."""
    rounded = [round(float(p), 6) for p in views]
    curves = {**(record.curves or {}), "test_view_psnr": rounded, "test_view_psnr_from": FROM}
    return dataclasses.replace(record, curves=curves, metrics={**record.metrics, "worst_view_psnr": min(rounded)})


def backfill_run(folder: Path, record: RunRecord) -> tuple[RunRecord, str]:
    """(The backfilled record, its line) for one run of the experiment folder ``folder``;
    `InputError` (one line) where its model is missing or its evaluation disagrees with its record."""
    from splatbench.train.reevaluate import MODEL_FILE, evaluate_saved_run, tolerance_db  # late: torch and Dr.Jit

    # a reused run's model is where it ran: its original experiment's folder (`reused_from`)
    work = folder.parent / (record.reused_from or folder.name) / "work" / record.run_id
    if not (work / MODEL_FILE).is_file():
        raise InputError(f"{record.run_id}: no final model {work / MODEL_FILE} (its work folder is gone: a results "
                         f"folder copied without work/, or removed)")
    want = record.metrics.get("test_psnr")
    if not isinstance(want, (int, float)) or not math.isfinite(want):
        raise InputError(f"{record.run_id}: the record has no test PSNR to check the evaluation against")
    ev = evaluate_saved_run(work)
    views = [float(p) for p in ev.per_view_psnr]
    got, tol = float(np.mean(views)), tolerance_db(views)
    if len(views) != record.metrics.get("test_views", len(views)):
        raise InputError(f"{record.run_id}: {len(views)} test views now, the record says "
                         f"{record.metrics.get('test_views')}: the dataset changed; refused")
    if not abs(got - want) <= tol:
        raise InputError(f"{record.run_id}: the saved model evaluates to {got:.6f} dB, the record says {want:.6f} dB "
                         f"(differ by {got - want:+.2e}, beyond the {tol:.1e} dB of float32 rendering noise); refused")
    worst = int(np.argmin(views))
    line = (f"{record.run_id} {record.scene} {record.labels} seed {record.seed}: {len(views)} views, mean "
            f"{got:.4f} dB (record {want:.4f}, {got - want:+.1e}); worst view {worst} at {views[worst]:.2f} dB, "
            f"{float(np.median(views)) - views[worst]:.2f} dB below the run's median view")
    return backfilled(record, views), line


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("results", type=Path, help="the results folder (e.g. ~/.cache/splatbench/results)")
    parser.add_argument("experiment", help="the experiment's name (its folder under RESULTS_DIR)")
    parser.add_argument("--dry-run", action="store_true", help="evaluate and check; write nothing")
    args = parser.parse_args(argv)
    folder = experiment_dir(args.results, args.experiment)
    if not (folder / "results.parquet").is_file():
        print(f"error: {folder}: no results.parquet there (not an experiment's results folder)", file=sys.stderr)
        return 2
    records = read_records(folder)
    pending = [r for r in records.values() if needs_backfill(r)]
    print(f"{args.experiment}: {len(records)} records, {len(pending)} done without per-view PSNRs", flush=True)
    written = failed = 0
    for record in pending:
        if (folder / "claims" / f"{record.run_id}.claim").exists():
            print(f"{record.run_id}: held by a runner (claims/{record.run_id}.claim); left alone", flush=True)
            continue
        try:
            new, line = backfill_run(folder, record)
        except InputError as exc:
            print(f"error: {exc}", flush=True)
            failed += 1
            continue
        if not args.dry_run:
            write_record(args.results, new)
            written += 1
        print(line + ("" if not args.dry_run else " (dry run: not written)"), flush=True)
    if written:
        print(f"{args.experiment}: {written} records rewritten; results.parquet rewritten "
              f"({len(read_table(save_table(folder).parent))} runs)")
    return 1 if failed else 0





if __name__ == "__main__":
    sys.exit(main())
