"""Ranks: each scene's cells in order of the kind's primary metric, and how far the orders agree.

A report ranks its grid's cells (not its extra cells, `ExperimentSpec.extra`, which are compared only
at a matched size) per scene by their mean over seeds of the primary metric (the
train kind's test PSNR; 1 is best, tied cells share their mean rank) and gives the rank agreement
of every pair of scenes as Kendall's tau-b over the cells both ranked
(`splatbench.metrics.stats.kendall_tau`: +1 the same order, -1 the reverse). Where the experiment
file names a quick version of the same grid (``[report] quick = "PATH"``: a report folder holding
its ``results.parquet``, or a run table, relative to the file), each scene the two share also gets
the agreement of the quick protocol's order with this report's, over the cells both have (cells
matched by their labels, `splatbench.reports.tables.cell_labels`): whether the cheap protocol ranks
the cells as this one does. Without one the section says "no quick version". The ranks come from
means: two cells whose difference is within the seeds' spread may swap between scenes by chance,
which the paired findings above judge and a tau does not (docs/reports.md, "Rank agreement").
"""

from __future__ import annotations

import math
from itertools import combinations
from pathlib import Path

import pandas as pd
from scipy.stats import rankdata

from splatbench.errors import InputError
from splatbench.experiments.kind_report import Claim, Finding, done_runs
from splatbench.experiments.kinds import RunKind
from splatbench.experiments.spec import ExperimentSpec
from splatbench.experiments.store import TABLE_NAME
from splatbench.metrics.spec import MetricSpec
from splatbench.metrics.stats import kendall_tau
from splatbench.report_files import markdown_table
from splatbench.reports.findings import rules_for, usable_runs
from splatbench.reports.tables import cell_labels, grid_runs, metric_specs, seed_values


def cell_means(spec: ExperimentSpec, runs: pd.DataFrame, metric: str) -> dict[str, dict[str, float]]:
    """scene -> cell label -> the mean over seeds of ``metric`` (a seed's runs averaged first) of the
    done runs of ``runs`` (cells without a finite value left out)."""
    done = done_runs(runs)
    if done.empty or f"metric.{metric}" not in done.columns:
        return {}
    labels = cell_labels(spec, done)
    out: dict[str, dict[str, float]] = {}
    for (scene, cell), group in done.groupby([done.scene, labels], sort=False):
        values = seed_values(group, metric)
        if values:
            out.setdefault(str(scene), {})[str(cell)] = sum(values.values()) / len(values)
    return out


def tied(means: dict[str, float], better: str, min_effect: float | None, ratio: bool = False) -> dict[str, float]:
    """``means`` with the cells that no minimum effect separates made equal: down the order (best
    first), each cell joins the group of the best cell not yet grouped while it is less than
    ``min_effect`` from that cell, and every cell of a group takes the group's mean. Means closer than
    the minimum effect order nothing worth ranking (glossy's SH 1 and 3, 0.07 dB apart under a 0.1 dB
    minimum effect, tie); a tie is about the order of the means, not a finding of no difference (that
    needs the paired interval within the minimum effect, `splatbench.reports.findings.reading`). ``ratio``: the minimum
    effect is a relative change (a "ratio" comparison: within ×(1 + min_effect)). ``None``: as given."""
    if not min_effect:
        return dict(means)
    sign = 1.0 if better == "lower" else -1.0
    order = sorted(means, key=lambda c: sign * means[c])
    out: dict[str, float] = {}
    while order:
        head = order[0]
        def near(c: str) -> bool:
            a, b = sorted((abs(means[c]), abs(means[head])))
            return (b < a * (1 + min_effect)) if ratio else abs(means[c] - means[head]) < min_effect

        group = [c for c in order if near(c)]  # a prefix: order is sorted
        value = sum(means[c] for c in group) / len(group)
        out.update({c: value for c in group})
        order = [c for c in order if c not in group]
    return {c: out[c] for c in means}


def ranks(means: dict[str, float], better: str) -> dict[str, float]:
    """cell -> its rank by ``means`` (1 the best: the highest, or the lowest where ``better`` is
    "lower"; tied cells share their mean rank)."""
    cells = list(means)
    sign = 1.0 if better == "lower" else -1.0
    return dict(zip(cells, (float(r) for r in rankdata([sign * means[c] for c in cells], method="average"))))


def quick_table(spec: ExperimentSpec) -> tuple[pd.DataFrame | None, str]:
    """(The quick version's run table named by ``[report] quick``, the path as the file writes it);
    (None, "") where the file names none. A path that holds no table is a one-line `InputError`."""
    if spec.quick is None:
        return None, ""
    path = Path(spec.source).parent / spec.quick
    table_path = path / TABLE_NAME if path.is_dir() else path
    if not table_path.is_file():
        raise InputError(f"{spec.source}: report.quick: {table_path} does not exist (expected a report folder "
                         f"holding {TABLE_NAME}, or a run table, of the same grid at the quick protocol)")
    try:
        table = pd.read_parquet(table_path)
    except Exception as exc:  # noqa: BLE001 - any unreadable table is one line
        raise InputError(f"{spec.source}: report.quick: {table_path} cannot be read as a run table "
                         f"({type(exc).__name__})") from None
    missing = [f"axis.{d}" for d in spec.dimensions if f"axis.{d}" not in table.columns]
    missing += [c for c in ("scene", "seed", "status") if c not in table.columns]
    if missing:
        raise InputError(f"{spec.source}: report.quick: {table_path} has no column {', '.join(missing)} (expected "
                         f"the run table of the same grid at the quick protocol)")
    return table, spec.quick


def _tau(value: float) -> str:
    return "n/a" if not math.isfinite(value) else f"{value:+.2f}"


def rank_finding(spec: ExperimentSpec, kind: RunKind, table: pd.DataFrame, quick: pd.DataFrame | None = None,
                 quick_path: str = "") -> Finding | None:
    """The section "Appendix: Ranks" (module doc): the cells' ranks per scene, the rank agreement of every pair
    of scenes and, with ``quick`` (the quick version's run table, named ``quick_path``), the quick
    protocol's against this report's per scene; None for a kind without findings rules or a grid
    of fewer than two cells with a result."""
    metrics = metric_specs(kind, table)
    rules = rules_for(kind, metrics, spec.min_effect)
    if rules is None:
        return None
    primary: MetricSpec = next(m for m in metrics if m.name == rules.primary)
    # not runs left out of every finding, nor the extra cells (compared only at a matched size)
    means = cell_means(spec, grid_runs(spec, usable_runs(table, kind)), primary.name)
    if not means or max(len(m) for m in means.values()) < 2:
        return None
    scenes = list(means)
    order = list(dict.fromkeys(c for m in means.values() for c in m))
    comparison = next((c for c in rules.comparisons if c.metric == primary.name), None)
    effect = comparison.min_effect if comparison is not None else None
    ratio = comparison is not None and comparison.how == "ratio"
    levels = {scene: tied(m, primary.better, effect, ratio) for scene, m in means.items()}  # what the ranks order
    ranked = {scene: ranks(m, primary.better) for scene, m in levels.items()}
    claims = [Claim("rank", scene, cell, primary.name, "rank", r, f"{r:g}") for scene, rs in ranked.items()
              for cell, r in rs.items()]
    name = primary.label.split(" (")[0]
    unit = f" {primary.unit}" if primary.unit else ""
    rows = [[f"`{cell}`", *(f"{ranked[s][cell]:g} ({format(means[s][cell], primary.fmt)}{unit})"
                            if cell in ranked[s] else "–" for s in scenes)] for cell in order]
    within = ("" if not effect else f"; cells within ×{1 + effect:g} of each other, the minimum effect, are tied"
              if ratio else f"; cells less than {effect:g}{unit} apart, the minimum effect, are tied")
    lines = [f"Each scene's cells ranked by mean {name} over seeds (1 the best; tied cells share their mean rank"
             f"{within}); "
             f"ranks come from means, so two cells within the seeds' spread of each other may swap by chance (the "
             f"paired findings above judge that; a rank does not):", "",
             *markdown_table(["cell", *scenes], rows, align="-" + "r" * len(scenes)).splitlines(), ""]
    if len(scenes) >= 2:
        pairs = []
        for a, b in combinations(scenes, 2):
            tau, n = kendall_tau(levels[a], levels[b])
            claims.append(Claim("tau", f"{a}/{b}", "", primary.name, "tau", tau, _tau(tau), n=n))
            pairs.append(f"{a} / {b} {_tau(tau)} ({n} cells)")
        taus = [c.value for c in claims if c.kind == "tau" and math.isfinite(c.value)]
        mean = f"; mean {sum(taus) / len(taus):+.2f}" if taus else ""
        lines.append(f"- **Rank agreement across scenes** (Kendall's τ-b of the cells' mean {name}, every pair of "
                     f"scenes: +1 the same order, −1 the reverse, 0 no agreement): " + "; ".join(pairs) + mean + ".")
    else:
        lines.append("- **Rank agreement across scenes**: one scene, nothing to agree with.")
    if quick is None:
        lines.append("- **Quick protocol against this one**: no quick version (the experiment file's `[report] quick` "
                     "names no run table of this grid at the quick protocol).")
    else:
        theirs = cell_means(spec, usable_runs(quick, kind), primary.name)
        shared = [s for s in scenes if s in theirs]
        parts = []
        for scene in shared:
            tau, n = kendall_tau(tied(theirs[scene], primary.better, effect, ratio), levels[scene])
            claims.append(Claim("quick tau", scene, "", primary.name, "tau", tau, _tau(tau), n=n))
            parts.append(f"{scene} {_tau(tau)} ({n} cells)")
        if parts:
            lines.append(f"- **Quick protocol against this one** (Kendall's τ-b of the quick version's cell means, "
                         f"`[report] quick` = `{quick_path}`, against this report's, per scene, over the cells both "
                         f"have): " + "; ".join(parts) + ".")
        else:
            lines.append(f"- **Quick protocol against this one**: no quick version on these scenes (`{quick_path}` "
                         f"has none of {', '.join(scenes)} done).")
    return Finding("ranks", lines, claims, summary=_summary(claims))


def _summary(claims: list[Claim]) -> list[str]:
    """The Summary's line of the ranks (the numbers of the lines above, in brief): the mean rank agreement
    across scenes and the quick version's per scene, with how coarse a τ over that few cells is."""
    taus = [c for c in claims if c.kind == "tau" and math.isfinite(c.value)]
    quick = [c for c in claims if c.kind == "quick tau"]
    if not taus and not quick:
        return []
    parts = []
    if len(taus) == 1:
        parts.append(f"the two scenes' orders agree by Kendall's τ {_tau(taus[0].value)}")
    elif taus:
        parts.append(f"agreement across scenes, mean Kendall's τ {sum(c.value for c in taus) / len(taus):+.2f} over "
                     f"{len(taus)} pairs of scenes")
    if quick:
        parts.append("the quick protocol's order against this one's: "
                     + ", ".join(f"{c.scene} {_tau(c.value)}" for c in quick))
    cells = max(c.n for c in (*taus, *quick))
    coarse = (f" (over {cells} cells a τ-b moves in steps of about {2 / (cells * (cells - 1) / 2):.2f})"
              if cells >= 2 else "")
    return ["- **Ranks**: " + "; ".join(parts) + coarse + " (\"Appendix: Ranks\")."]


__all__ = ["cell_means", "tied", "ranks", "quick_table", "rank_finding"]
