"""Reports: an experiment's results as markdown tables, findings and figures.

    spec = load_experiment("experiments/sh_degree.toml")
    report = build_report(spec, "results")            # tables, findings, the run table
    write_report(report, "reports/sh_degree")          # report.md, figures/*.png, results.parquet

Every function is handed the run kind (`splatbench.experiments.RunKind`, from
`ExperimentSpec.run_kind`): what its result and `KindReport` declare, its hooks included.

Modules: `tables` (axis rows, mean ± 95 % interval, the metrics a kind shows), `findings`
(claims computed from the tables: paired differences with intervals), `settling` (whether a
cell's curves had flattened: the last quarter's slope, and its finding), `check` (the 7K check: the headline's two cells rerun at graphdeco's protocol, its
verdict), `ranks` (each scene's cells in order, Kendall's tau across scenes and against the
grid's quick version), `figures` (training curves, the
cells of the Pareto figures), `report` (assembly, markdown), `cli`
(``splatbench report``). Statistics are `splatbench.metrics.stats`. See docs/reports.md.
"""

from splatbench.reports.findings import Claim, Finding
from splatbench.reports.report import Report, build_report, report_from_table, write_report
from splatbench.reports.tables import AxisTable, Stat

__all__ = ["Report", "build_report", "report_from_table", "write_report", "AxisTable", "Stat", "Claim", "Finding"]
