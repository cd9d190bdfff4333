"""Experiments: declarative grids in TOML, resumable parallel runs, a results table.

    spec = load_experiment("experiments/sh_degree.toml")   # ExperimentSpec, fully checked
    runs = expand(spec)                                      # list[RunSpec], deterministic order
    checks = check_runs(spec)                                # its [check]: the headline at another protocol
    summary = run_experiment(spec, workers=2, executor="local", results_dir="results")
    summary.line()        # "done 12, skipped 0 (finished), 0 claimed by another runner, failed 0 of 12"
    table = read_table("results/sh_degree")                  # pandas DataFrame, one row per run

Modules: `configs` (dotted keys, canonical JSON), `spec` (file format), `grid`
(expansion, run ids, `load_experiment`), `kinds`
(the run-kind contract: its Config read from a run's dotted keys, its typed result, the
registry), `kind_report` (what a kind declares about its reports, its hooks included:
`splatbench.reports` is handed the kind), `train_kind`, `raster_kind` (the built-in kinds;
`train_report`: the train kind's report hooks), `store` (atomic per-run files, the
parquet table), `runner` (drives the runs), `one_run` (one run, worker side), `executors`
(local and Dask), `claims` (per-run claims shared
by concurrent runners), `workers` (worker processes that die with their runner),
`cli` (``splatbench run``).
See docs/experiments.md.
"""

from splatbench.experiments.configs import canonical_json
from splatbench.experiments.one_run import execute_run
from splatbench.experiments.grid import (RunSpec, check_cells, check_runs, expand, load_experiment, make_run_id,
                                        published_runs)
from splatbench.experiments.kinds import KindProtocols, RunKind, RunResult, get_kind, metric, read_config, register_kind
from splatbench.experiments.runner import RunSummary, run_experiment
from splatbench.experiments.spec import CheckSpec, ExperimentSpec, PublishedSpec, RunnerDefaults, parse_experiment
from splatbench.experiments.store import RunRecord, read_records, read_table

__all__ = ["ExperimentSpec", "CheckSpec", "PublishedSpec", "RunnerDefaults", "load_experiment", "parse_experiment",
           "RunSpec", "expand", "check_cells", "check_runs", "published_runs", "make_run_id", "canonical_json",
           "RunKind", "RunResult", "metric", "read_config", "KindProtocols", "get_kind", "register_kind", "RunSummary",
           "run_experiment", "execute_run", "RunRecord", "read_records", "read_table"]
