"""Numerical-stability stress test: degenerate and non-finite input through
`splatbench.rasterize`, forward and backward (docs/stress.md).

    report = splatbench.stress.run(cases=200, seed=0)
    report.ok, [(c.category, c.nonfinite_grads) for c in report.categories]
"""

from splatbench.stress.cases import CATEGORIES, FIELDS, StressCase, build_case
from splatbench.stress.runner import CaseResult, CategoryReport, StressReport, run, run_case

__all__ = ["CATEGORIES", "FIELDS", "StressCase", "build_case", "CaseResult", "CategoryReport", "StressReport",
           "run", "run_case"]
