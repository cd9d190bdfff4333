"""Whether a cell's curves had flattened when its runs ended ("settled"), and whether a
paired difference still moved: the rule every training finding is marked with.

A kind names its curves in its `KindReport` (``settling``: the test and train curve keys
and the metric they measure); the rule (docs/reports.md, "Settled"):

* **the last quarter** of a run: the curve points at steps >= ``end - end / 4`` (``end`` the
  last evaluated step); where that holds fewer than two points, the last two;
* **slope**: the least-squares slope of the test curve over those points, per seed, then the
  mean over seeds (a row's runs of one seed averaged first), in units per 1,000 steps;
* **a cell is settled** when ``|slope| < min_effect`` per `SETTLE_STEPS` (1,000) steps: 1,000
  more steps at that slope -- half the quick protocol's run again, and the slope only falls
  as the learning rate decays -- would move it by less than the minimum effect (0.1 dB PSNR
  by default: 0.1 dB per 1,000 steps). A falling curve is not settled either;
* **past its peak**: the test curve's last value (mean over seeds at each evaluation step the
  seeds share) is more than the minimum effect below its best value at an earlier step (above,
  for a metric where lower is better): such a cell is "past its peak (best at step N)", never
  settled, however flat its last quarter (a curve that peaked at 2,100 steps and fell 0.3 dB by
  7,000 may end flat); where a reset the kind names falls between the best step and the end, and
  the curve was still within the minimum effect of its best at its last evaluation before that
  reset, it says so ("; the reset at step 6,000 lies between": the fall came after the reset, maybe
  its dip; the rule unchanged);
* **past its peak** is judged on the fall as written (`FALL_FMT`, two decimals): a printed
  0.10 dB is never "more than the 0.1 dB minimum effect" (docs/reports.md, "Minimum effects");
* **overfitting**: the test curve is flat or falling (slope below the threshold) while the
  training-view curve, where recorded, still rises faster than the test curve by at least
  the threshold: the cell fits its training views, it has not converged. The training-view
  points logged within `RESET_RECOVERY` steps after a reset the kind names
  (`SettlingCurves.resets`: the train kind's opacity resets) are left out of its slope and of
  the train–test gap: they measure the reset, not the fit;
* **a difference is settled** when both its cells are and the paired difference moved over
  the last quarter by less than `DRIFT_SHARE` (a quarter) of its final size (of the minimum
  effect, for a difference smaller than that).
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import pandas as pd

from splatbench.experiments.configs import run_config
from splatbench.experiments.kind_report import Claim, Finding, SettlingCurves, done_runs
from splatbench.experiments.kinds import RunKind

#: Share of the run, at its end, whose slope decides.
LAST_SHARE = 0.25
#: The slope threshold is the minimum effect per this many steps.
SETTLE_STEPS = 1000
#: A paired difference is settled when it moved over the last quarter by less than this share of its size.
DRIFT_SHARE = 0.25
#: Training-view points logged this many steps or fewer after a reset (`SettlingCurves.resets`) are left
#: out of the overfitting slope and the gap. sh_degree's graphdeco-7k runs (fox, log_every 100): the point
#: logged at the reset (step 6,000) is 28-31 dB below its neighbours, the one 100 steps later 4-6 dB, the
#: one 200 steps later 1-2 dB (within a point's own scatter, ±2 dB between neighbours before the reset).
RESET_RECOVERY = 100
#: The precision a fall below the peak is written with, and judged at (`CellSettling.past_peak`).
FALL_FMT = ".2f"


@dataclass(frozen=True)
class Slope:
    """One curve's least-squares slope over the last quarter of a run (per 1,000 steps),
    the points it is fitted on (first and last step), the value at the window's end and the
    window itself (``lo``: its first step, ``end - end / 4``, or the first point where the last
    two are used)."""

    slope: float
    start: int
    end: int
    last: float
    lo: int | None = None


def last_quarter_slope(steps, values, end: int | None = None, skip=()) -> Slope | None:
    """`Slope` of the finite points of one curve over the last quarter of a run that ends at
    ``end`` (default: the curve's last step), the steps in ``skip`` left out; None with fewer
    than two points."""
    skipped = set(skip)
    pts = [(float(s), float(v)) for s, v in zip(steps or [], values or [])
           if s is not None and v is not None and math.isfinite(float(v)) and int(s) not in skipped]
    if len(pts) < 2:
        return None
    end = pts[-1][0] if end is None else float(end)
    lo = end - LAST_SHARE * end
    sel = [p for p in pts if lo <= p[0] <= end]
    if len(sel) < 2:
        sel = [p for p in pts if p[0] <= end][-2:]
        lo = sel[0][0] if sel else lo
    if len(sel) < 2 or sel[-1][0] == sel[0][0]:
        return None
    x, y = np.array([p[0] for p in sel]), np.array([p[1] for p in sel])
    slope = float(np.polyfit(x, y, 1)[0]) * SETTLE_STEPS
    return Slope(slope, int(sel[0][0]), int(sel[-1][0]), float(sel[-1][1]), int(math.ceil(lo)))


def recovering(steps, resets) -> list[int]:
    """The steps of ``steps`` logged ``RESET_RECOVERY`` steps or fewer after one of ``resets``
    (a reset at count ``r`` is applied after ``r`` iterations: the step logged as ``r`` is the first
    after it)."""
    return [int(s) for s in steps or [] if s is not None and any(0 <= int(s) - r <= RESET_RECOVERY for r in resets)]


@dataclass(frozen=True)
class CellSettling:
    """The curves of one cell (or row) at one scene over the last quarter.

    test / train: slope per 1,000 steps, mean over seeds (train None when not recorded);
    start / end: the test window (steps; the widest over the seeds); per_seed: seed -> test
    slope; threshold: the settled threshold (the minimum effect per 1,000 steps).
    """

    test: float
    train: float | None
    start: int
    end: int
    per_seed: dict[int, float]
    threshold: float
    gap: float | None = None  # train − test over the window (mean over seeds; None: no training curve)
    best: float | None = None  # the mean curve's best value (None: no step every seed evaluated)
    best_step: int | None = None  # the step of ``best`` (the first, on a tie)
    last: float | None = None  # the mean curve's value at its last step
    lo: int | None = None  # the window's first step (``end - end / 4``; the test points start at ``start``)
    resets: tuple[int, ...] = ()  # the resets (`SettlingCurves.resets`) in the window, over the runs
    left_out: tuple[int, ...] = ()  # the training-view steps left out of the window (`RESET_RECOVERY`)
    gap_counts: tuple[tuple[int, int], ...] = ()  # each run's (training-view points, test points) in the gap
    reset_after_best: int | None = None  # the last reset (`SettlingCurves.resets`) after ``best_step``, by the end,
    #   before which the curve was still within the minimum effect of its best (the fall came after it)

    @property
    def flat(self) -> bool:
        """The last quarter's slope is below the threshold."""
        return abs(self.test) < self.threshold

    @property
    def fall(self) -> float:
        """How far the mean curve's last value is below its best (>= 0, in the curve's unit; 0 unknown)."""
        return 0.0 if self.best is None or self.last is None else abs(self.best - self.last)

    @property
    def past_peak(self) -> bool:
        """The last value is more than the minimum effect (the threshold per 1,000 steps) below the best,
        as written (`FALL_FMT`: a fall printed 0.10 dB is not more than 0.1 dB)."""
        return float(format(self.fall, FALL_FMT)) > self.threshold + 1e-12

    @property
    def settled(self) -> bool:
        """Flat over the last quarter and not past its peak (module doc)."""
        return self.flat and not self.past_peak

    def why_not(self, unit: str = "dB") -> str:
        """Why the cell is not settled: its slope, and / or ``past its peak (best at step 2,100, 0.31 dB
        above its last value)``; "" when settled."""
        parts = [] if self.flat else [f"{self.test:+.2f} {unit} / 1,000 steps over the last quarter"]
        if self.past_peak:
            parts.append(f"past its peak ({self.peak(unit)})")
        return ", ".join(parts)

    def peak(self, unit: str = "dB") -> str:
        """``best at step 5,600, 0.13 dB above its last value``, and ``; the reset at step 6,000 lies
        between`` where one does (the fall may be the reset's dip, not yet recovered)."""
        between = (f"; the reset at step {self.reset_after_best:,} lies between"
                   if self.reset_after_best is not None else "")
        return f"best at step {self.best_step:,}, {self.fall:{FALL_FMT}} {unit} above its last value{between}"

    @property
    def overfitting(self) -> bool:
        return self.train is not None and self.test < self.threshold and self.train - self.test >= self.threshold

    def describe(self, unit: str = "dB") -> str:
        """``+0.42 dB / 1,000 steps (train +0.90)``."""
        train = f" (train {self.train:+.2f})" if self.train is not None else ""
        return f"{self.test:+.2f} {unit} / 1,000 steps{train}"


def _curves(value) -> dict | None:
    if not isinstance(value, str):
        return None
    try:
        parsed = json.loads(value)
    except ValueError:
        return None
    return parsed if isinstance(parsed, dict) else None


def mean_curve(runs: pd.DataFrame, keys: SettlingCurves) -> list[tuple[int, float]]:
    """(step, value) of the test curve averaged over seeds at each step every seed of ``runs`` evaluated
    (a seed's runs averaged first); [] when the seeds share no step."""
    seeds = _seed_curves(runs, keys.test_step, keys.test_value)
    if not seeds:
        return []
    steps = sorted(set.intersection(*(set(c) for c in seeds.values())))
    return [(s, float(np.mean([c[s] for c in seeds.values()]))) for s in steps]


def mean_peak(mean: list[tuple[int, float]], better: str) -> tuple[float, int, float] | None:
    """(best value, its step, last value) of a `mean_curve`; best is the highest, or the lowest where
    ``better`` is "lower"; None for an empty curve (the seeds shared no step)."""
    if not mean:
        return None
    sign = -1.0 if better == "lower" else 1.0
    step, best = max(mean, key=lambda p: (sign * p[1], -p[0]))
    return best, step, mean[-1][1]


def _fell_after(mean: list[tuple[int, float]], best: float, reset: int, min_effect: float) -> bool:
    """Whether the curve was still within ``min_effect`` of its ``best`` at its last evaluation before
    ``reset``: the fall came after that reset (fox's SH 3 at 7K), not before it (glossy, falling from
    step 3,500 on, past its peak before the reset at 6,000)."""
    before = [v for s, v in mean if s < reset]
    return bool(before) and abs(best - before[-1]) <= min_effect + 1e-12


def cell_settling(runs: pd.DataFrame, keys: SettlingCurves, min_effect: float) -> CellSettling | None:
    """`CellSettling` of the done runs ``runs`` (one cell or row at one scene; a seed's runs
    averaged first); None when no run has two points of the test curve."""
    if "curves" not in runs.columns:
        return None
    test: dict[int, list[float]] = {}
    train: dict[int, list[float]] = {}
    gaps: dict[int, list[float]] = {}
    counts: list[tuple[int, int]] = []  # per run: (training-view points, test points) its gap averages
    starts, ends, los = [], [], []
    resets: set[int] = set()
    every_reset: set[int] = set()  # over the run, for `CellSettling.reset_after_best`
    left_out: set[int] = set()
    for (_, run), raw in zip(runs.iterrows(), runs.curves):
        seed = run.seed
        c = _curves(raw)
        if c is None:
            continue
        s = last_quarter_slope(c.get(keys.test_step), c.get(keys.test_value))
        if s is None:
            continue
        test.setdefault(int(seed), []).append(s.slope)
        starts.append(s.start)
        ends.append(s.end)
        los.append(s.lo)
        every_reset |= {r for r in _resets(run, keys) if r <= s.end}
        if keys.train_step and keys.train_value and c.get(keys.train_value):
            ran = _resets(run, keys)
            resets |= {r for r in ran if s.lo <= r <= s.end}
            skip = [st for st in recovering(c.get(keys.train_step), ran) if s.lo <= st <= s.end]
            left_out |= set(skip)
            t = last_quarter_slope(c.get(keys.train_step), c.get(keys.train_value), end=s.end, skip=skip)
            if t is not None:
                train.setdefault(int(seed), []).append(t.slope)
            points = gap_points(c, keys, s.lo, s.end, skip)
            g = _gap(*points)
            if g is not None:
                gaps.setdefault(int(seed), []).append(g)
                counts.append((len(points[0]), len(points[1])))
    if not test:
        return None
    per_seed = {k: float(np.mean(v)) for k, v in sorted(test.items())}
    train_mean = float(np.mean([np.mean(v) for v in train.values()])) if train else None
    gap = float(np.mean([np.mean(v) for v in gaps.values()])) if gaps else None
    curve = mean_curve(runs, keys)
    peak = mean_peak(curve, keys.better)
    best, best_step, last = peak if peak is not None else (None, None, None)
    after = [r for r in every_reset if best_step is not None and r > best_step
             and _fell_after(curve, best, r, min_effect)]
    return CellSettling(float(np.mean(list(per_seed.values()))), train_mean, min(starts), max(ends), per_seed,
                        min_effect, gap, best, best_step, last, min(los), tuple(sorted(resets)),
                        tuple(sorted(left_out)), tuple(sorted(set(counts))), max(after) if after else None)


def _span(values: list[int]) -> str:
    """``12`` or ``11–12`` (the fewest and most over the runs)."""
    return f"{values[0]}" if len(values) == 1 else f"{values[0]}–{values[-1]}"


def _resets(run: pd.Series, keys: SettlingCurves) -> tuple[int, ...]:
    """The reset steps of one run (`SettlingCurves.resets` of its recorded config); () without."""
    if keys.resets is None or not any(str(c).startswith("config.") for c in run.index):
        return ()
    return tuple(int(r) for r in keys.resets(run_config(run)))


def window_gap(curves: dict, keys: SettlingCurves, start: int, end: int, skip=()) -> float | None:
    """The train–test gap of one run over the steps ``start..end`` (the last quarter): the mean of
    the training-view curve's points there (the steps in ``skip`` left out: just after a reset) minus
    the mean of the test curve's; None when either has no finite point there. The training-view value
    is the view each step trained on, measured before its update and logged every ``log_every`` steps:
    a noisy but unbiased sample of the fit to the training views."""
    return _gap(*gap_points(curves, keys, start, end, skip))


def _gap(train: list[float], test: list[float]) -> float | None:
    """The mean of ``train`` minus the mean of ``test`` (`gap_points`); None when either is empty."""
    return None if not train or not test else float(np.mean(train)) - float(np.mean(test))


def gap_points(curves: dict, keys: SettlingCurves, start: int, end: int, skip=()) -> tuple[list[float], list[float]]:
    """(The training-view points, the test points) of one run that `window_gap` averages: the finite
    values logged at steps ``start..end``, the training-view steps in ``skip`` left out."""
    def points(steps, values, leave=frozenset()) -> list[float]:
        return [float(v) for s, v in zip(steps or [], values or []) if s is not None and v is not None
                and start <= float(s) <= end and math.isfinite(float(v)) and int(s) not in leave]

    return (points(curves.get(keys.train_step), curves.get(keys.train_value), set(skip)),
            points(curves.get(keys.test_step), curves.get(keys.test_value)))


def _seed_curves(runs: pd.DataFrame, step_key: str, value_key: str) -> dict[int, dict[int, float]]:
    """seed -> step -> value of one curve (a seed's runs averaged per step; non-finite points left out)."""
    out: dict[int, dict[int, list[float]]] = {}
    if "curves" not in runs.columns:
        return {}
    for seed, raw in zip(runs.seed, runs.curves):
        c = _curves(raw)
        if c is None:
            continue
        for s, v in zip(c.get(step_key) or [], c.get(value_key) or []):
            if s is not None and v is not None and math.isfinite(float(v)):
                out.setdefault(int(seed), {}).setdefault(int(s), []).append(float(v))
    return {seed: {s: float(np.mean(v)) for s, v in steps.items()} for seed, steps in out.items()}


def paired_curve(a: pd.DataFrame, b: pd.DataFrame, keys: SettlingCurves) -> list[tuple[int, float]]:
    """The paired difference ``b - a`` of the test curve at every evaluation step both cells'
    runs share: (step, mean over the seeds both have of ``b_s - a_s``), in step order; [] when
    they share none. Whether a gap is stable while the cells still rise shows here."""
    ca, cb = _seed_curves(a, keys.test_step, keys.test_value), _seed_curves(b, keys.test_step, keys.test_value)
    seeds = sorted(set(ca) & set(cb))
    steps = sorted(set.intersection(*(set(ca[s]) & set(cb[s]) for s in seeds))) if seeds else []
    return [(step, float(np.mean([cb[s][step] - ca[s][step] for s in seeds]))) for step in steps]


def drift(a: CellSettling, b: CellSettling) -> float:
    """How far the paired difference ``b - a`` moved over the last quarter (in the curve's unit):
    the mean over the seeds both have of the slope difference times the window."""
    seeds = sorted(set(a.per_seed) & set(b.per_seed))
    if not seeds:
        return math.nan
    window = (max(a.end, b.end) - min(a.start, b.start)) / SETTLE_STEPS
    return float(np.mean([b.per_seed[s] - a.per_seed[s] for s in seeds])) * window


def difference_settled(a: CellSettling, b: CellSettling, diff: float) -> bool:
    """Both cells settled and the difference moved by less than `DRIFT_SHARE` of its size
    (``|diff|``, at least the minimum effect: a difference below it has no size to keep)."""
    moved = drift(a, b)
    size = max(abs(diff), a.threshold)  # the threshold is the minimum effect per 1,000 steps
    return a.settled and b.settled and math.isfinite(moved) and abs(moved) < DRIFT_SHARE * size


def unsettled_reason(a: CellSettling | None, b: CellSettling | None, labels: tuple[str, str], diff: float,
                     unit: str) -> str:
    """Why the difference ``b - a`` (cells labelled ``labels``, a first) is not settled: the cells
    whose own curves still moved (``b`` first), else how far the difference moved over the last
    quarter; "" when it is settled, or not judged (a cell without a curve)."""
    if a is None or b is None:
        return ""
    moving = [f"`{label}` {c.why_not(unit)}" for label, c in ((labels[1], b), (labels[0], a)) if not c.settled]
    if moving:
        return "; ".join(moving)
    if not difference_settled(a, b, diff):
        return f"the difference moved {drift(a, b):+.2f} {unit} over the last quarter"
    return ""


# --------------------------------------------------------------------------- the finding
def _cell_label(done: pd.DataFrame, axes: list[str]):
    """A row's cell as ``axis=value, ...``; in a one-at-a-time grid (every cell differs from the
    most common one in at most one axis, with more than one axis) only the axis that differs,
    or ``base``."""
    common = {c: done[c].mode().iloc[0] for c in axes}

    def moved(row) -> list[str]:
        return [c for c in axes if row[c] != common[c]]

    one_at_a_time = len(axes) > 1 and all(len(moved(row)) <= 1 for _, row in done.iterrows())
    if one_at_a_time:
        return lambda row: ", ".join(f"{c[5:]}={row[c]}" for c in moved(row)) or "base"
    return lambda row: ", ".join(f"{c[5:]}={row[c]}" for c in axes)


def settling_finding(runs: pd.DataFrame, kind: RunKind, min_effect: Mapping[str, float] | None = None
                     ) -> Finding | None:
    """Whether each cell had settled when its runs ended, for a kind that declares its curves
    (`KindReport.settling`; the train kind's test PSNR):
    the slope of its test curve over the last quarter of the run (mean over seeds, per 1,000
    steps) against the threshold, the minimum effect of the curves' metric (test PSNR: 0.1 dB, or the
    experiment file's) per 1,000 steps; and, where the training-view PSNR is recorded, whether the test
    curve is flat or falling while the training curve still rises (overfitting, not
    convergence). One claim per cell: ``significant`` is True when it is *not* settled."""
    declared = kind.report
    done = done_runs(runs)
    keys = declared.settling if declared is not None else None
    if done.empty or "curves" not in done.columns or keys is None:
        return None
    effect = dict(min_effect or {}).get(keys.metric)
    if effect is None:
        effect = next((c.min_effect for c in declared.rules.comparisons if c.metric == keys.metric), None)
    if effect is None:
        return None
    axes = [c for c in done.columns if c.startswith("axis.")]
    label = _cell_label(done, axes) if axes else (lambda row: "all")
    labels = done.apply(label, axis=1) if len(done) else pd.Series([], dtype=object)
    cells: dict[tuple[str, str], CellSettling] = {}
    unknown = []
    for (scene, cell), group in done.groupby([done.scene, labels], sort=False):
        c = cell_settling(group, keys, effect)
        if c is not None:
            cells[(scene, cell)] = c
        else:
            unknown.append(f"{scene} `{cell}`")
    cannot_tell = (f"- **Cannot tell whether {'any cell' if not cells else ', '.join(unknown)} settled**: "
                   "no run of it evaluated the test views twice or more (set `eval.every`, e.g. a quarter of "
                   "`iterations`), so its findings say nothing about convergence.") if unknown else None
    if not cells:
        return Finding("settling", [cannot_tell], [], summary=[cannot_tell])
    windows = sorted({(c.lo if c.lo is not None else c.start, c.end) for c in cells.values()})
    span = ", ".join(f"{a:,}–{b:,}" for a, b in windows)
    evals = sorted({(c.start, c.end) for c in cells.values()})
    firsts = ", ".join(f"{a:,}" for a, _ in evals)
    threshold = f"{effect:g} dB per 1,000 steps"
    lines = [f"- Test PSNR slope over the last quarter of the run (steps {span}: its test evaluations from step "
             f"{firsts} on; least squares, mean over seeds; a cell is settled below {threshold}, the minimum effect "
             f"per 1,000 steps: docs/reports.md), with the training-view PSNR's slope where recorded: "
             + "; ".join(f"{scene} `{cell}` {c.describe()}" for (scene, cell), c in cells.items()) + "."]
    resets = sorted({r for c in cells.values() for r in c.resets})
    left = sorted({st for c in cells.values() for st in c.left_out})
    if resets:
        steps = ", ".join(f"{r:,}" for r in resets)
        lines.append(f"- **An opacity reset in the window** (step{'s' if len(resets) > 1 else ''} {steps}): the test "
                     f"slope and the past-its-peak test are judged across it, the evaluations after it still "
                     f"recovering, so a cell's settledness here is this run length's, not convergence"
                     + (f"; the training-view points logged {RESET_RECOVERY} steps or fewer after it (steps "
                        f"{', '.join(f'{st:,}' for st in left)}) are left out of the training slope, the train–test "
                        f"gap and the overfitting test" if left else "") + ".")
    claims = []
    for (scene, cell), c in cells.items():
        claims.append(Claim("settling", scene, cell, keys.metric, "slope", c.test, f"{c.test:+.2f} dB / 1,000 steps",
                            n=len(c.per_seed), significant=not c.settled, settled=c.settled))
    gaps = [(scene, cell, c.gap) for (scene, cell), c in cells.items() if c.gap is not None]
    if gaps:
        counts = [n for c in cells.values() for n in c.gap_counts]
        n_train = _span(sorted({a for a, _ in counts}))
        n_test = _span(sorted({b for _, b in counts}))
        lines.append(f"- Train–test gap over the same window (steps {span}"
                     + (", less the training-view points just after a reset" if left else "")
                     + f"; the mean of {n_train} logged training-view PSNRs minus the mean of {n_test} test "
                     f"evaluations there, per run, mean over seeds. **Each training-view PSNR is one sampled training "
                     f"view**, the one its step trained on, before its update (the runs record no evaluation of all "
                     f"training views): a noisy, view-dependent estimate; a larger gap is a cell fitting its training "
                     f"views more than it generalises): "
                     + "; ".join(f"{scene} `{cell}` {g:+.2f} dB" for scene, cell, g in gaps) + ".")
    moving = [f"{scene} `{cell}` ({c.test:+.2f})" for (scene, cell), c in cells.items() if not c.flat]
    peaked = [f"{scene} `{cell}` ({c.peak()})"
              for (scene, cell), c in cells.items() if c.past_peak]
    overfit = [f"{scene} `{cell}` (test {c.test:+.2f}, train {c.train:+.2f})" for (scene, cell), c in cells.items()
               if c.overfitting]
    heads = []  # the report's summary: each mark's count, its cells in the section
    if moving:
        heads.append(f"**Not settled**: {len(moving)} of {len(cells)} cells still moved by {threshold} or more over "
                     f"the last quarter")
        lines.append(f"- {heads[-1]}: " + ", ".join(moving) + ". Their differences above are what this run length "
                     "gives, not where the cells converge (each such comparison is marked **not settled**).")
    if peaked:
        heads.append(f"**Past its peak**: {len(peaked)} of {len(cells)} cells ended more than the {effect:g} dB "
                     f"minimum effect below their best test PSNR")
        lines.append(f"- **Past its peak** (not settled, however flat its end): {len(peaked)} of {len(cells)} cells "
                     f"ended more than the {effect:g} dB minimum effect below their best test PSNR (the curve's mean "
                     f"over seeds): " + ", ".join(peaked) + ". Their numbers are the last step's, not the best's.")
    if not moving and not peaked:
        heads.append(f"Settled: every cell{' with a slope' if unknown else ''}'s test curve moved by less than "
                     f"{threshold} over the last quarter, and none ended more than the minimum effect below its best")
        lines.append(f"- {heads[-1]}.")
    if cannot_tell:
        lines.append(cannot_tell)
    if overfit:
        heads.append(f"**Overfitting**: {len(overfit)} of {len(cells)} cells (the test curve flat or falling while the "
                     f"training-view PSNR still rises)")
        lines.append("- **Overfitting**: the test curve is flat or falling while the training-view PSNR still rises "
                     f"(by {threshold} or more beyond the test curve's slope): " + ", ".join(overfit)
                     + ". Such a cell has stopped generalising; it has not converged.")
    if cannot_tell:
        heads.append(cannot_tell[2:].rstrip("."))
    either = sum(1 for c in cells.values() if not c.flat or c.past_peak)
    if moving and peaked:  # the two marks overlap: how many cells either leaves unsettled
        both = len(moving) + len(peaked) - either
        heads.insert(0, f"**{either} of {len(cells)} cells not settled or past their peak** ({len(moving)} still "
                        f"moving, {len(peaked)} past their peak, {both} both) at this run length, so each difference "
                        f"is this checkpoint's, not where the cells converge")
    summary = [f"- {'; '.join(heads)} (which cells: \"Appendix: Settling\")."]
    return Finding("settling", lines, claims, summary=summary)


__all__ = ["LAST_SHARE", "SETTLE_STEPS", "DRIFT_SHARE", "Slope", "CellSettling", "last_quarter_slope",
           "cell_settling", "window_gap", "gap_points", "recovering", "RESET_RECOVERY", "FALL_FMT", "paired_curve", "drift", "difference_settled", "unsettled_reason", "settling_finding"]
