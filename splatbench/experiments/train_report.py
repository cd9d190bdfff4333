"""The train kind's report hooks (`KindReport.header_notes`, ``axis_notes``, ``metric_notes``):
what its reports say beyond the tables, from what the runs recorded (their resolved
``config.*`` columns and metrics, and, for how a capture's photos were read, the loader's notes
the runs recorded: ``notes``, `_READ_NOTES`), never from prose written here.

* header: `protocol_lines`, the protocol the runs followed (below);
* axis notes: `auto_sh_degree_note` (the degree ``auto`` ended at), `schedule_confound_note`
  (what a densification-schedule setting changes besides itself);
* metric notes: `lpips_note` (which LPIPS the column is);
* run finding and check note: `outlier_view_finding` / `outlier_view_note` (a run with a test view
  far below the same view in its cell's other seeds: a floater in front of that camera).

`protocol_lines(table)`: one markdown list of the fields that change a 3DGS number
(PROTOCOL.md; NerfBaselines): the named protocol, the schedule (iterations, scaled or
absolute steps, learning rates), the evaluation steps, the split, the resolution and how it
was made, the background, the metrics' conventions, the initialisation, and the seeds and
what they vary. A field that differs between runs is listed with each value. A config
without a ``protocol`` field (every run before the named presets) reads as today's quick
scaled protocol.
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

from splatbench.experiments.configs import cell_value, decode, run_config
from splatbench.experiments.kind_report import AxisRows, Claim, Finding, RunNotes, done_runs
from splatbench.strategies import refines_at

#: What the runs' protocol is called when their config names none (`TrainConfig.protocol` absent).
DEFAULT_PROTOCOL = ("quick (graphdeco's 30,000-step schedule scaled to the run's length): a smoke test, not evidence "
                    "about a 3DGS method (the field's numbers come from graphdeco's 7K and 30K protocols)")


def _values(done: pd.DataFrame, column: str) -> list[Any]:
    """The distinct values of a column over the done runs (NaN / NA as None), in order."""
    if column not in done.columns:
        return []
    out: list[Any] = []
    for v in map(cell_value, done[column]):
        if v not in out:
            out.append(v)
    return out


def _one(done: pd.DataFrame, column: str, show: Callable[[Any], str] = str) -> str | None:
    """The column's value as written, ``a / b`` when runs differ; None when absent or all None."""
    values = [v for v in _values(done, column) if v is not None]
    if not values:
        return None
    return " / ".join(show(v) for v in values) + (" (differs by cell)" if len(values) > 1 else "")


def _interval(value: Any) -> str:
    """A step setting as written: ``100 steps``, ``5% of the run`` (a run table's mixed column as JSON text)."""
    v = decode(value)
    return f"{v:,} steps" if isinstance(v, int) else f"{v} of the run"


def _g(v: Any) -> str:
    return f"{v:g}" if isinstance(v, float) else str(v)


def seed_varies(config: dict[str, Any]) -> tuple[list[str], list[str]]:
    """(What a run's seed varies, what it does not) for one run's resolved config (flat
    ``config.*`` keys without the prefix): `splatbench.train` seeds torch and numpy, the
    view order, random backgrounds, the strategy's draws (its ``seed`` field is the run's)
    and a random initialisation; the initial points of ``init = surface`` / ``sfm`` and the
    rendered dataset do not move with it (as recorded: a config field that seeds them, when
    one exists, is read here too)."""
    varies = ["torch / numpy random state", "training-view order"]
    fixed = []
    if config.get("random_background"):
        varies.append("random backgrounds")
    if config.get("strategy.name") not in (None, "none") and config.get("strategy.seed") is not None:
        varies.append("the strategy's random draws (split children, MCMC relocation and noise)")
    init = config.get("init.method")
    if init == "random":
        varies.append("the random initial points")
    elif config.get("init.jitter"):
        varies.append(f"the initial points (init = {init}, seeded)")
    elif init is not None:
        fixed.append(f"the initial points of init = {init}")
    fixed.append("the dataset (rendered or read once per scene)")
    return varies, fixed


#: The first line of a quick-protocol report, right under its title.
SMOKE_TEST = ("**A smoke test, not evidence**: this grid's runs follow the quick protocol (graphdeco's schedule "
              "compressed into {iters} steps, its learning rates not scaled: docs/training.md, \"Protocols\"), whose "
              "results graphdeco's 7K column has not confirmed; no number below is evidence about a 3DGS method "
              "(a `[check]` rerun at a graphdeco protocol, where there is one, is reported apart).")


def smoke_test_line(table: pd.DataFrame) -> list[str]:
    """`SMOKE_TEST` for a report any of whose done runs follow the quick protocol (``config.protocol``
    "quick", or absent: a config from before the named protocols); [] otherwise (`KindReport.title_notes`)."""
    done = done_runs(table)
    if done.empty or "config.iterations" not in done.columns:
        return []
    protocol = done["config.protocol"] if "config.protocol" in done.columns else pd.Series(None, index=done.index)
    quick = done[[v is None or v is pd.NA or v == "quick" or (isinstance(v, float) and math.isnan(v))
                  for v in protocol]]
    if quick.empty:
        return []
    iters = _one(quick, "config.iterations", lambda v: f"{int(v):,}") or "the run's"
    return [SMOKE_TEST.format(iters=iters)]


def protocol_lines(table: pd.DataFrame) -> list[str]:
    """The header's protocol list of a train report (module doc); [] without config columns."""
    done = done_runs(table)
    if done.empty or "config.iterations" not in done.columns:
        return []
    lines = []
    protocol = _one(done, "config.protocol") or "quick"
    lines.append(f"- **Protocol**: {DEFAULT_PROTOCOL if protocol == 'quick' else protocol}.")
    iters = _one(done, "config.iterations", lambda v: f"{int(v):,}")
    schedules = _values(done, "config.schedule")
    every = _one(done, "config.strategy.refine_every", _interval)  # as each run set it
    how = {"scaled": "graphdeco's 30,000-step schedule scaled to the run (refine window, opacity resets, SH steps "
                     f"times iterations / 30,000; the refine interval{', ' + every + ',' if every else ''} is not "
                     "scaled, so a short run refines fewer times)",
           "absolute": "schedule steps as written"}
    sched = " / ".join(how.get(s, str(s)) for s in schedules if s is not None) or "not recorded"
    lr = _one(done, "config.optim.lr_means", _g)
    lr_final = _one(done, "config.optim.lr_means_final", _g)
    lrs = (f"; learning rates not scaled: positions {lr} → {lr_final} × scene extent, decayed over the run's "
           f"iterations, the other groups constant" if lr and lr_final else "")
    if protocol == "quick":
        lines.append(f"- **Schedule**: {iters} iterations, {sched}{lrs}.")
    else:  # a graphdeco protocol: its schedule as written, whatever length the runs stopped at
        lines.append(f"- **Schedule**: {iters} iterations of graphdeco's 30,000-step schedule as written (refine "
                     f"window, opacity resets, SH steps and the position learning-rate decay "
                     f"{(lr + ' → ' + lr_final + ' × scene extent ') if lr and lr_final else ''}over 30,000 steps, "
                     f"not scaled to the run; the protocol sets it, so the runs' recorded `schedule` field "
                     f"({' / '.join(repr(str(x)) for x in schedules if x is not None) or 'none'}) is not what they "
                     f"ran)" + (f"; {white}" if (white := _white_reset(done)) else "") + ".")
    evals = _eval_steps(done)
    late = refined_at_end(done) if protocol != "quick" else 0
    order = (f" {late} of {len(done)} runs refined at their last step (its refine interval divides it, inside the "
             f"refine window), after that step's optimizer update and before the evaluation, as at every evaluation "
             f"step the refine interval divides; graphdeco's train.py evaluates first, so its model at that step has "
             f"had one refinement fewer (docs/training.md, \"Evaluation order\")." if late else "")
    if first := int(_evaluated_first(done).sum()):
        order += (f" {first} of {len(done)} runs evaluated each test step before its refinement and left out their "
                  f"last step's, as graphdeco's train.py (`eval.before_refine`).")
    lines.append(f"- **Evaluation**: the test views at steps {evals}; the reported numbers are the last step's.{order}"
                 if evals else f"- **Evaluation**: the test views at the end.{order}")
    test_every = _one(done, "config.data.test_every")
    views = _view_counts(done) or (_one(done, "config.data.views") or "") and f"{_one(done, 'config.data.views')} views"
    split = (f"where the dataset gives none, view i is a test view when i % {test_every} = 0 (every {test_every}th "
             f"from the first, by sorted image name or render order, as graphdeco's --eval)") if test_every \
        else "the dataset's own split"
    lines.append(f"- **Split**: {split}" + (f"; {views}" if views else "") + ".")
    lines.append(f"- **Resolution**: {_resolution(done)}.")
    lines.append(f"- **Scenes**: {_scenes(done)}")
    rnd = _values(done, "config.random_background")
    lines.append(f"- **Background** (the RGB behind the splats in every render, and under the targets where a "
                 f"dataset has alphas or masks): {background_text(done)}"
                 + ("; a random background per training step (the one above in the evaluations)"
                    if True in rnd else "") + ".")
    lines.append(f"- **Metrics**: {_metrics(done)}.")
    lines.append(f"- **Initialisation**: {init_text(done)}.")
    ran = schedule_as_run(done)
    if ran:
        lines.append(f"- **Schedule as run** (each run's recorded counts, in its {iters} steps): {ran}.")
    lines.append(f"- **Seeds**: {_seeds(done)}")
    return ["**Protocol** (from the runs' recorded configs):", "", *lines]


#: Where each run's background came from (``metric.background_source``: `splatbench.train.loop.resolve_background`).
_BACKGROUND_FROM = {"config": "set by the config",
                    "masks": "masked capture: its photos composited over it with their masks (auto)",
                    "alpha": "the mean colour of the pixels its alpha marks empty (auto)",
                    "depth": "the mean colour of the pixels its depth marks empty, nothing hit (auto)",
                    "none": "black: the dataset marks no empty pixels (auto)"}
#: What ``background = "auto"`` resolves to, for runs that did not record the RGB.
_AUTO_RULE = ("white for a masked capture, else the mean colour of the pixels the dataset marks empty, black where it "
              "marks none")


def carried(done: pd.DataFrame, columns: tuple[str, ...], also: tuple[str, ...] = ()) -> pd.DataFrame:
    """``done`` with each of ``columns`` (metrics a run records since some commit: image size,
    view counts, background) filled in for the runs that predate it from the same scene's runs
    whose data config is the same (every ``config.data.*`` column and those named in ``also``:
    the fields that decide the value), where those recorded exactly one value; left empty otherwise."""
    columns = tuple(c for c in columns if c in done.columns)
    if not columns or done.empty:
        return done
    keys = ["scene", *sorted(c for c in done.columns if c.startswith("config.data.")), *(a for a in also
                                                                                           if a in done.columns)]
    out = done.copy()
    group = [tuple(cell_value(v) if not isinstance(v, (list, np.ndarray)) else str(v) for v in row)
             for row in done[keys].itertuples(index=False)]
    for col in columns:
        out[col] = out[col].astype(object)
        known: dict[tuple, set] = {}
        for g, v in zip(group, done[col]):
            if cell_value(v) is not None:
                known.setdefault(g, set()).add(cell_value(v))
        out[col] = [v if cell_value(v) is not None else (next(iter(known[g])) if len(known.get(g, ())) == 1 else None)
                    for g, v in zip(group, out[col])]
    return out


def background_text(done: pd.DataFrame) -> str:
    """Each scene's background as its runs recorded it: the RGB they rendered and evaluated
    against (``metric.background``) and where it came from (``metric.background_source``),
    ``guitar (0, 0, 0), auto: the mean colour of the pixels its depth marks empty``; for runs
    from before it was recorded, the config's value (an RGB is what they used; ``auto`` is named
    with its rule and said to be unresolved). Values that differ between a scene's runs are
    joined with " / "; scenes with the same text share it (``guitar and textured `auto` (...)``)."""
    texts: dict[str, list[str]] = {}
    done = carried(done, ("metric.background", "metric.background_source"), ("config.background",))
    for scene, rows in done.groupby("scene", sort=True):
        shown = []
        rgbs = rows.get("metric.background", pd.Series(None, index=rows.index, dtype=object))
        sources = rows.get("metric.background_source", pd.Series(None, index=rows.index, dtype=object))
        recorded = rgbs.notna()
        for rgb, source in dict.fromkeys(zip(rgbs[recorded], sources[recorded])):
            how = _BACKGROUND_FROM.get(source, f"source {source}" if isinstance(source, str) else "source not recorded")
            shown.append(f"({rgb}), {how}")
        older = rows[~recorded]
        values: list[Any] = []
        for v in older.get("config.background", []):
            if decode(v) not in values:
                values.append(decode(v))
        for value in values:
            if value == "auto":
                shown.append(f"`auto` (the RGB it resolved to is not recorded: these runs predate "
                             f"`metric.background`; auto is {_AUTO_RULE})")
            elif isinstance(value, list):
                shown.append(f"({', '.join(_g(float(c)) for c in value)}), set by the config")
            elif value is not None:
                shown.append(f"config {value}")
        texts.setdefault(" / ".join(shown) or "not recorded", []).append(str(scene))
    return "; ".join(f"{_names(scenes)} {text}" for text, scenes in texts.items()) or "not recorded"


def _start_count(raw: Any) -> int | None:
    """The Gaussians at the first logged step of a run's curves (step 0: before any refinement,
    which starts later in every schedule `check_final_window` accepts), i.e. its initial points."""
    try:
        c = json.loads(raw) if isinstance(raw, str) else {}
    except ValueError:
        return None
    steps, counts = c.get("step") or [], c.get("num_gaussians") or []
    return int(counts[0]) if steps and counts and steps[0] == 0 and counts[0] is not None else None


#: What each initialisation starts from, in words (`splatbench.train.initializers`).
_INIT_WHAT = {"surface": "the scene's own surface points (exact geometry: a rendered scene's surfaces, a teacher's "
                         "rendered depth; not SfM's)", "sfm": "SfM points triangulated from the training views",
              "random": "random points"}


def init_text(done: pd.DataFrame) -> str:
    """The initialisation the runs asked for and what it resolved to, per scene: the method that
    ran (``metric.init_method``; for a run from before it was recorded, ``surface`` where
    ``auto`` met a rendered scene, which always has its surface points, else "not recorded"),
    the initial count (``metric.init_points``, else the curves' step-0 count) and the jitter
    that a seed moves the given points by (``config.init.jitter``)."""
    asked = _one(done, "config.init.method")
    if asked is None:
        return "not recorded"
    kinds = scene_kinds(done)
    parts = []
    for scene, rows in done.groupby("scene", sort=False):
        for init, cell in rows.groupby(rows["config.init.method"].astype(str), sort=False):
            methods = [m for m in _values(cell, "metric.init_method") if m is not None]
            how = ""
            if not methods and init in _INIT_WHAT:
                methods = [init]
            elif not methods and init == "auto" and kinds.get(str(scene)) == "rendered":
                methods, how = ["surface"], " (inferred: these runs did not record it; a rendered scene has its points)"
            counts = [int(v) for v in _values(cell, "metric.init_points") if v is not None]
            if not counts:
                counts = [n for n in dict.fromkeys(_start_count(r) for r in cell.get("curves", [])) if n is not None]
            count = " / ".join(f"{n:,}" for n in counts)
            method = " / ".join(methods)
            what = " / ".join(_INIT_WHAT.get(m, m) for m in methods) if methods else \
                ("the method it resolved to is not recorded by these runs (auto: the dataset's own points when it "
                 "has them, else SfM with its known poses)" if init == "auto" else "not recorded")
            jit = [v for v in _values(cell, "config.init.jitter") if v]
            given = any(m in ("surface", "sfm") for m in methods)
            moved = (f", jittered {' / '.join(_g(v) for v in jit)} × their neighbour spacing per seed"
                     if given and jit else "")
            region = _one(cell, "config.init.region") if "random" in methods else None
            where = f" in region {region}" if region else ""
            arrow = f"{init} → {method}" if method and method != init else init
            parts.append(f"{arrow} on {scene}: {what}{where}" + (f", {count} Gaussians at step 0" if count else "")
                         + moved + how)
    return "; ".join(parts)


def schedule_as_run(done: pd.DataFrame) -> str:
    """The schedule's counts as the runs made them: refinements and opacity resets (the
    strategy's recorded counts, per cell where they differ) and the SH schedule (one band more
    every ``sh.interval`` steps as the run reads it, `TrainConfig.sh_steps`: scaled by
    `splatbench.train.schedule.scale_step` over the protocol's schedule length, 30,000 under a
    graphdeco protocol, which so keeps its steps as written: `sh_interval_steps`); "" without those columns."""
    axes = [c for c in done.columns if c.startswith("axis.")]
    parts = []
    counted = [c for c in ("metric.refinements", "metric.opacity_resets") if c in done.columns
               and pd.to_numeric(done[c], errors="coerce").notna().any()]
    if counted:
        def counts(rows: pd.DataFrame) -> str:
            out = []
            for col, word in zip(counted, ("refinements", "opacity resets")):
                vals = sorted({int(v) for v in pd.to_numeric(rows[col], errors="coerce").dropna()})
                shown = f"{vals[0]}–{vals[-1]}" if len(vals) > 1 else str(vals[0]) if vals else ""
                out.append(f"{shown} {word}" if vals else f"{word} not recorded")
            return ", ".join(out)

        cells = {}
        for key, rows in (done.groupby(axes, sort=False) if axes else [((), done)]):
            key = key if isinstance(key, tuple) else (key,)
            label = ", ".join(f"{a[5:]}={v}" for a, v in zip(axes, key)) or "every run"
            cells[label] = counts(rows)
        if len(set(cells.values())) == 1:
            parts.append(f"{next(iter(cells.values()))} (every run)")
        else:
            parts.append("; ".join(f"`{label}` {text}" for label, text in cells.items()))
    if {"config.sh.interval", "config.iterations", "config.schedule"} <= set(done.columns):
        steps = sh_interval_steps(done)
        if steps:
            every = " / ".join(f"{s:,}" for s in steps)
            bands = " / ".join(", ".join(f"{k * s:,}" for k in (1, 2, 3)) for s in steps)
            parts.append(f"SH degree raised one band every {every} step{'' if steps == [1] else 's'} (bands 1, 2, 3 at "
                         f"steps {bands}, up to each cell's maximum degree)")
    return "; ".join(parts)


def sh_interval_steps(done: pd.DataFrame) -> list[int]:
    """The distinct steps between SH band raises of the runs, each as its recorded config makes it
    (`splatbench.experiments.train_config.sh_steps`, `TrainConfig.sh_steps`: ``sh.interval`` scaled
    over the protocol's schedule length, 30,000 under a graphdeco protocol, which so keeps its steps
    as written); [] without those columns. A run that recorded no interval, iterations or schedule
    (today's defaults are not what it ran), or whose config no longer validates, is left out."""
    from splatbench.experiments.train_config import sh_steps  # late: it loads splatbench.train (torch)

    if not {"config.sh.interval", "config.iterations", "config.schedule"} <= set(done.columns):
        return []
    recorded = done[done["config.sh.interval"].notna() & done["config.iterations"].notna()
                    & done["config.schedule"].isin(("scaled", "absolute"))]
    return sorted({s for s in (sh_steps(run_config(run)) for _, run in recorded.iterrows()) if s is not None})


def _white_reset(done: pd.DataFrame) -> str:
    """Where runs of a graphdeco protocol rendered on white (``metric.background`` 1, 1, 1), the opacity
    reset graphdeco's train.py adds at its refine start under --white_background, which these runs do
    not make; "" where none did."""
    if "metric.background" not in done.columns:
        return ""
    white = sorted({str(s) for s, rgb in zip(done.scene, done["metric.background"])
                    if isinstance(rgb, str) and [x.strip() for x in rgb.split(",")] == ["1", "1", "1"]})
    if not white:
        return ""
    return (f"on a white background ({', '.join(white)}) graphdeco's train.py, given --white_background, also "
            f"resets opacities at its refine start (step 500), which these runs do not (docs/training.md, "
            f"\"Evaluation order\")")


def _evaluated_first(done: pd.DataFrame) -> pd.Series:
    """Per run, whether it set ``eval.before_refine`` (evaluated before a step's refinement, left its last
    step's out); a record from before the field (no column, or no value) did not."""
    col = done.get("config.eval.before_refine", pd.Series(False, index=done.index))
    return col.map(lambda v: isinstance(v, (bool, np.bool_)) and bool(v))


def refined_at_end(done: pd.DataFrame) -> int:
    """How many of the ``done`` runs refined at their last step, from their recorded configs: a strategy
    other than "none" whose schedule refines after ``iterations`` completed steps (`splatbench.strategies.
    refines_at`, the strategies' own test, on the steps as written: the graphdeco protocols'), unless it
    evaluated before that refinement (``eval.before_refine``: it left it out); 0 where a column is missing."""
    cols = ["config.strategy.name", "config.strategy.refine_every", "config.strategy.refine_start",
            "config.strategy.refine_stop", "config.iterations"]
    if not set(cols) <= set(done.columns):
        return 0
    first = _evaluated_first(done)
    n = 0
    for (name, every, start, stop, iters), evaluated_first in zip(done[cols].itertuples(index=False), first):
        try:
            every, start, stop, iters = int(every), int(start), int(stop), int(iters)
        except (TypeError, ValueError):
            continue
        n += name != "none" and not evaluated_first and refines_at(iters, start, stop, every)
    return n


def _eval_steps(done: pd.DataFrame) -> str:
    steps: list[int] = []
    for raw in done.get("curves", pd.Series([], dtype=object)):
        try:
            c = json.loads(raw) if isinstance(raw, str) else {}
        except ValueError:
            continue
        for s in c.get("eval_step") or []:
            if s not in steps:
                steps.append(int(s))
    return ", ".join(f"{s:,}" for s in sorted(steps))


def _image_size(rows: pd.DataFrame) -> str:
    """``89×158`` (width × height in pixels, ``metric.image_width`` / ``image_height``, `carried`
    to runs of the scene's data config that predate them; ``a / b`` where runs differ); "" where
    no run of it recorded them."""
    if "metric.image_width" not in rows.columns or "metric.image_height" not in rows.columns:
        return ""
    rows = carried(rows, ("metric.image_width", "metric.image_height"))
    sizes = [f"{int(w)}×{int(h)}" for w, h in dict.fromkeys(zip(rows["metric.image_width"], rows["metric.image_height"]))
             if pd.notna(w) and pd.notna(h)]
    return " / ".join(sizes)


def _view_counts(done: pd.DataFrame) -> str:
    """Per scene, the views trained on / tested on as the runs recorded them (``metric.train_views``,
    ``metric.test_views``, `carried` within the scene's data config; a rendered or teacher scene's
    ``config.data.views`` is their sum), e.g. ``fox 58 / 9, maryrose – / 9 (train / test views; –:
    not recorded)``; "" where nothing was recorded."""
    kinds = scene_kinds(done)
    done = carried(done, ("metric.train_views", "metric.test_views"))
    parts, unknown = [], False
    for scene, rows in done.groupby("scene", sort=False):
        def counts(column: str) -> list[int]:
            return [int(v) for v in _values(rows, column) if v is not None]

        train, test = counts("metric.train_views"), counts("metric.test_views")
        total = counts("config.data.views") if kinds.get(str(scene)) != "capture" else []
        if not train and len(test) == 1 and len(total) == 1:
            train = [total[0] - test[0]]
        elif train and "metric.train_views" in rows.columns and rows["metric.train_views"].isna().any():
            train.append("–")  # some of its runs (another data config) did not record theirs
        if test:
            unknown = unknown or not train or "–" in train
            parts.append(f"{scene} {' / '.join(map(str, train)) or '–'} / {' / '.join(map(str, test))}")
    return ", ".join(parts) + (" (train / test views" + ("; –: not recorded)" if unknown else ")")) if parts else ""


def _resolution(done: pd.DataFrame) -> str:
    parts = []
    if "config.data.model" in done.columns and done["config.data.model"].notna().any():
        res = _one(done[done["config.data.model"].notna()], "config.data.resolution")
        parts.append(f"teacher scenes rendered from their PLY at {res} px wide (splatbench.experiments.teacher)")
    if "config.data.spp" in done.columns and done["config.data.spp"].notna().any():
        sel = done[done["config.data.spp"].notna()]
        res, spp = _one(sel, "config.data.resolution"), _one(sel, "config.data.spp")
        test_spp = _one(sel, "config.data.test_spp")
        parts.append(f"rendered scenes at {res} px wide by Mitsuba, {spp} spp"
                     + (f" ({test_spp} spp for the test views)" if test_spp and test_spp != spp else ""))
    kinds = scene_kinds(done)
    captures, unsized = [], []
    for scene, rows in done.groupby("scene", sort=False):
        if kinds.get(str(scene)) != "capture":
            continue
        down = _one(rows, "config.data.downscale", _g)
        size, read = _image_size(rows), _how_read(rows)
        detail = "; ".join(([f"{size} px"] if size else []) + ([read] if read else []))
        captures.append(f"{scene} " + (f"1/{down}" if down else "at full size") + (f" ({detail})" if detail else ""))
        sizes = carried(rows, ("metric.image_width",)).get("metric.image_width", pd.Series([None]))
        unsized += [str(scene)] if pd.isna(sizes).any() else []
    if captures:
        parts.append("captures at 1/`data.downscale` of their photos (`images_N/` where the capture has it, else "
                     "the nearest finer images folder reduced on load: LLFF's by area averaging, as OpenCV's INTER_AREA, "
                     "other layouts' by PIL's bicubic, after undistortion by pycolmap where the camera has lens "
                     "coefficients; each run's notes say which): " + ", ".join(captures)
                     + (f" (image size not recorded by {_names(unsized)}'s runs"
                        + (", or some of them" if any(_image_size(r) for sc, r in done.groupby("scene") if str(sc) in
                                                      unsized) else "") + ")" if unsized else ""))
    return "; ".join(parts) or "not recorded"


#: How a capture's photos were read, as the Resolution line says it, from the loader's notes its runs recorded
#: (`RunRecord.notes`, in `splatbench.data.load_dataset`'s words): (pattern, the words said).
_READ_NOTES = tuple((re.compile(pattern), words) for pattern, words in (
    (r"\d+ images with ([\w/]+) lens distortion (?:would be )?undistorted by pycolmap",
     r"\1 lens distortion undistorted by pycolmap"),
    (r"(images(?:_\d+)?)/ read and reduced by ([\d.]+) ", r"\1/ reduced by \2 on load"),
    (r"(images(?:_\d+)?)/ read at ", r"\1/ as stored"),
    (r"downscale \d+: reading (images_\d+)/", r"\1/ as stored"),
    (r"^masks: (masks(?:_\d+)?)/ \(", r"\1/ as alphas")))


def _how_read(rows: pd.DataFrame) -> str:
    """How a capture's photos were read (the images folder, a reduction on load, undistortion, masks),
    from the loader's notes its runs recorded (`_READ_NOTES`), each once, in order; "" where they
    recorded none (runs before notes were recorded)."""
    notes = [note for raw in (rows["notes"].dropna() if "notes" in rows.columns else ())
             for note in (json.loads(raw) if isinstance(raw, str) else raw)]
    return how_read(notes)


def how_read(notes: Sequence[str]) -> str:
    """How a capture's photos were (or, in a dry check, would be) read, from the loader's notes
    (`_READ_NOTES`): each reading once, in order, "; "-joined; "" where none says."""
    said = [m.expand(words) for note in notes for pattern, words in _READ_NOTES for m in [pattern.search(note)] if m]
    return "; ".join(dict.fromkeys(said))


#: The evidence rule for a headline's scenes (docs/reports.md, "How many scenes a finding stands on"): 3 scenes, 2
#: of them real captures (a teacher scene is rendered from a model trained on photos: not a capture).
SCENES_WANTED, REAL_WANTED = 3, 2


def scene_kinds(done: pd.DataFrame) -> dict[str, str]:
    """scene -> "capture" (a dataset folder of photos), "teacher" (rendered from a real trained
    model's PLY) or "rendered" (a Mitsuba catalog scene), from the runs' recorded configs."""
    kinds = {}
    for scene, rows in done.groupby("scene", sort=True):
        def has(col: str) -> bool:
            return col in rows.columns and rows[col].notna().any()

        kinds[str(scene)] = ("teacher" if has("config.data.model") else
                             "capture" if has("config.data.path") or has("config.data.downscale") else "rendered")
    return kinds


def _scenes(done: pd.DataFrame) -> str:
    """The scenes and what each is (a dataset folder of photos, ``config.data.path``, is "(a real
    capture)"); whether they meet the evidence rule's count (3 scenes, 2 real captures)."""
    kinds = scene_kinds(done)
    what = {"rendered": "rendered by Mitsuba", "teacher": "a teacher scene rendered from a trained model, not a "
            "capture", "capture": "a real capture"}
    real = [s for s, k in kinds.items() if k == "capture"]
    listed = ", ".join(f"{s} ({what[k]})" for s, k in kinds.items())
    if len(kinds) >= SCENES_WANTED and len(real) >= REAL_WANTED:
        rule = f"enough scenes for a headline ({SCENES_WANTED}, {REAL_WANTED} of them real captures: docs/reports.md)."
    else:
        rule = (f"{len(real)} real capture{'s' if len(real) != 1 else ''}; a finding here holds on "
                f"{'this scene' if len(kinds) == 1 else 'these scenes'} only: the evidence rule asks a headline to "
                f"hold on {SCENES_WANTED} scenes, {REAL_WANTED} of them real captures (docs/reports.md), which this "
                f"grid does not test.")
    notes = []
    teachers = [s for s, k in kinds.items() if k == "teacher"]
    if teachers:
        notes.append(f" Inverse crime: {_names(teachers)} {'was' if len(teachers) == 1 else 'were'} rendered by "
                     f"this project's rasterizer from a trained 3DGS model and {'is' if len(teachers) == 1 else 'are'}"
                     f" fit by the same model family and rasterizer, which inflates absolute PSNR and can favour "
                     f"choices that match the teacher: {'its' if len(teachers) == 1 else 'their'} absolute numbers "
                     f"are not comparable with captures or published numbers.")
    rendered = [s for s, k in kinds.items() if k == "rendered"]
    if rendered:
        one = len(rendered) == 1
        notes.append(f" {_names(rendered)}, rendered by Mitsuba (not by this rasterizer: no inverse crime in the "
                     f"images, though a start from the scene's own surface is exact geometry no capture has), "
                     f"{'is' if one else 'are'} no published benchmark: {'its' if one else 'their'} absolute numbers "
                     f"are not the field's.")
    return f"{len(kinds)}: {listed}; {rule}" + "".join(notes)


def _names(scenes: list[str]) -> str:
    """``a``, ``a and b``, ``a, b and c``."""
    return scenes[0] if len(scenes) == 1 else ", ".join(scenes[:-1]) + f" and {scenes[-1]}"


def _metrics(done: pd.DataFrame) -> str:
    from splatbench.metrics.perceptual import convention  # late: the reports start without torch

    text = ("PSNR of the model's image clamped to [0, 1] against the target, on float images (the prediction "
            f"is not quantized to uint8{_uint8_shift(done)}), SSIM with an 11-pixel Gaussian window (σ 1.5; kornia's "
            "reflect padding at the borders, where graphdeco's SSIM pads with zeros)")
    if "metric.lpips_net" in done.columns:
        kinds = sorted({(str(n), bool(s)) for n, s in zip(done["metric.lpips_net"], done["metric.lpips_scale_inputs"])
                        if isinstance(n, str) and n})
        if kinds:
            text += "; " + " / ".join(convention(*k) for k in kinds)
    else:
        text += "; LPIPS not recorded"
    return text + "; " + AGGREGATION.format(views=_test_views(done))


#: The MSE that rounding a [0, 1] image to uint8 adds against uint8 targets: Sheppard's correction, one step
#: (1/255) squared over 12, for residuals spread over several steps (a view at 34 dB: RMSE 0.02, 5 steps).
UINT8_MSE = 1.0 / (12 * 255**2)


def _uint8_shift(done: pd.DataFrame) -> str:
    """``; quantizing it, as the field's metrics do, adds about 1/(12·255²) to a view's MSE: at 34.1 dB, this
    grid's highest run mean, about 0.014 dB lower`` (`UINT8_MSE`); "" without a recorded test PSNR."""
    psnr = pd.to_numeric(done.get("metric.test_psnr"), errors="coerce") if "metric.test_psnr" in done else None
    if psnr is None or not psnr.notna().any():
        return ""
    top = float(psnr.max())
    drop = 10.0 * math.log10(1.0 + UINT8_MSE * 10.0 ** (top / 10.0))
    return (f"; quantizing it, as the field's metrics do, adds about 1/(12·255²) to a view's MSE: at {top:.1f} dB, "
            f"this grid's highest run mean, about {drop:.3f} dB lower")


#: How the test metrics are aggregated over the test views (`splatbench.train.loop.Trainer.evaluate`).
AGGREGATION = ("each metric is computed per test view (PSNR from that view's MSE over its pixels and channels) and "
               "averaged over the {views}: the mean of the views' PSNRs, as graphdeco's metrics.py and its training "
               "evaluation report it, not the PSNR of the pooled MSE (which is never higher than this mean: −10 log10 is "
               "convex); SSIM and LPIPS likewise")


def _test_views(done: pd.DataFrame) -> str:
    """``8 test views`` (every scene), ``test views (8 on fox, 24 on lego)`` where scenes differ,
    from ``metric.test_views``; ``test views`` where not recorded."""
    if "metric.test_views" not in done.columns:
        return "test views"
    per = {str(scene): [int(v) for v in _values(rows, "metric.test_views") if v is not None]
           for scene, rows in done.groupby("scene", sort=True)}
    counts = {" / ".join(map(str, v)) for v in per.values() if v}
    if not counts:
        return "test views"
    if len(counts) == 1 and all(per.values()):
        count = next(iter(counts))
        return f"{count} test view{'' if count == '1' else 's'}"
    return "test views (" + ", ".join(f"{' / '.join(map(str, v))} on {s}" for s, v in per.items() if v) + ")"


def _seeds(done: pd.DataFrame) -> str:
    seeds = sorted({int(s) for s in done.seed})
    varies: list[str] = []
    fixed: list[str] = []
    cols = [c for c in done.columns if c.startswith("config.")]
    for _, row in done.iterrows():
        config = {c[len("config."):]: (None if row[c] is pd.NA else row[c]) for c in cols}
        v, f = seed_varies(config)
        varies += [x for x in v if x not in varies]
        fixed += [x for x in f if x not in fixed]
    inits = [f[len("the initial points of init = "):] for f in fixed if f.startswith("the initial points of init")]
    fixed = ([f"the initial points of init = {' / '.join(inits)} (the same points for every seed)"] if inits else []) \
        + [f for f in fixed if not f.startswith("the initial points of init")]
    where = ("; not " + ", not ".join(fixed)) if fixed else ""
    return (f"{', '.join(map(str, seeds))}, paired across cells. A seed varies {', '.join(varies)}{where}: an "
            f"interval covers what these vary, not a rerun's other sources (a different start, another "
            f"scene) (docs/reports.md, \"What an interval covers\").")


# --------------------------------------------------------------------------- axis and metric notes
def _auto_rule(done: pd.DataFrame) -> tuple[str, str]:
    """(What ``sh.degree = auto`` does, in one clause; the holdout it trains without, or ""), from the
    auto runs' configs (`splatbench.train.sh_schedule`; docs/training.md, "SH degree"): a band added every
    ``sh.interval`` steps (`schedule_as_run`'s reading) is kept if it gains ``auto_min_gain_db`` per band
    on every ``auto_holdout_every``-th training view, held out of training until the degree settles: with
    ``auto_lookahead`` 2, when band 3 has been measured, one interval after it starts (4 intervals)."""
    def one(col: str) -> Any:
        values = [v for v in _values(done, f"config.sh.{col}") if v is not None]
        return values[0] if len(values) == 1 else None

    from splatbench.train.sh_schedule import MAX_LOOKAHEAD  # late: as `sh_interval_steps`

    gain, every, ahead = one("auto_min_gain_db"), one("auto_holdout_every"), one("auto_lookahead")
    steps = sh_interval_steps(done)
    if gain is None or len(steps) != 1:
        return "", ""
    iters = [int(v) for v in _values(done, "config.iterations") if v is not None]
    on = f"every {int(every)}th training view, held out of training until the degree settles" if every else \
        "training views"
    rule = f"a band added every {steps[0]:,} steps is kept if it gains ≥ {_g(float(gain))} dB per band on {on}"
    if not every:
        return rule, ""
    settle = 4 * steps[0]
    until = (f"until step {settle:,}" if ahead == MAX_LOOKAHEAD and iters and settle <= min(iters) else
             f"until it settled (by step {settle:,} at the latest)")
    return rule, f"it trained on about {int(every) - 1}/{int(every)} of the training views {until}"


def auto_sh_degree_note(table: AxisRows, runs: pd.DataFrame, scenes: list[str]) -> tuple[list[str], list[Claim]]:
    """The ``sh.degree`` axis: what ``auto`` is and the holdout it trains without (`_auto_rule`), the
    degree its rows ended at per scene, and where that degree is a fixed row's: its difference from
    that row there is the holdout's and the trials' cost, not a degree's."""
    lines: list[str] = []
    claims: list[Claim] = []
    if table.axis != "sh.degree" or "metric.sh_degree" not in runs.columns:
        return lines, claims
    auto = [r for r in table.rows if r.value == "auto"]
    if auto:
        parts, same = [], []
        done = done_runs(runs)
        fixed = {decode(r.value): r.label for r in table.rows if r.value != "auto"}
        for scene in scenes:
            sel = done[(done.scene == scene) & done.run_id.isin(auto[0].run_ids)]
            degrees = [int(d) for d in pd.to_numeric(sel["metric.sh_degree"], errors="coerce").dropna()]
            if not degrees:
                continue
            mean = sum(degrees) / len(degrees)
            if len(set(degrees)) == 1:
                text = f"{degrees[0]}"
                where = "every seed" if len(degrees) > 1 else "one seed"
            else:
                text = f"{min(degrees)}–{max(degrees)}"
                where = "per seed: " + ", ".join(map(str, degrees))
            claims.append(Claim("auto", scene, auto[0].label, "sh_degree", "mean", mean, text))
            parts.append(f"{text} on {scene} ({where})")
            if len(set(degrees)) == 1 and degrees[0] in fixed:
                same.append(f"{scene} `{fixed[degrees[0]]}`")
        if parts:
            rule, holdout = _auto_rule(done[done.run_id.isin(auto[0].run_ids)])
            lines.append("- `auto`" + (f" ({rule})" if rule else "") + " ended at SH degree " + ", ".join(parts) + "."
                         + (f" Also changed: {holdout}" + (f", so its difference from the row of the degree it ended at"
                            f" ({', '.join(same)}) is the holdout's cost, not a degree's" if same else "") + "."
                            if holdout else ""))
    return lines, claims


#: Floats per Gaussian besides its colour: position 3, log-scales 3, rotation quaternion 4, opacity 1.
GEOMETRY_FLOATS = 3 + 3 + 4 + 1
#: Bytes per stored parameter (float32, as trained and as a 3DGS PLY stores them).
PARAM_BYTES = 4


def floats_per_gaussian(sh_degree: int) -> int:
    """Parameters of one Gaussian at SH degree ``d``: 3 + 3 + 4 + 1 + 3 (d + 1)² (14 at 0, 59 at 3)."""
    return GEOMETRY_FLOATS + 3 * (int(sh_degree) + 1) ** 2


def model_bytes(runs: pd.DataFrame) -> pd.Series:
    """The bytes of each run's trained model (`KindReport.model_bytes`): its final Gaussians times
    `floats_per_gaussian` at the SH degree it ended at (``metric.sh_degree``) times `PARAM_BYTES`
    (float32); NaN where either is not recorded."""
    if not {"metric.num_gaussians", "metric.sh_degree"} <= set(runs.columns):
        return pd.Series([math.nan] * len(runs), index=runs.index, dtype="float64")
    n = pd.to_numeric(runs["metric.num_gaussians"], errors="coerce")
    d = pd.to_numeric(runs["metric.sh_degree"], errors="coerce")
    floats = d.map(lambda v: floats_per_gaussian(int(v)) if pd.notna(v) else math.nan)
    return (n * floats * PARAM_BYTES).astype("float64")


def model_size_note(table: AxisRows, runs: pd.DataFrame, scenes: list[str]) -> tuple[list[str], list[Claim]]:
    """The model size of each row beside its Gaussian count: parameters (`floats_per_gaussian` at the
    SH degree each run ended at, ``metric.sh_degree``, times its Gaussians) and megabytes (float32),
    mean over seeds, and each row's paired ratio to the reference row (the one-at-a-time base, else
    the first), the geometric mean over seeds as the findings' ratios are. The SH degree sets the
    per-Gaussian count, so a Gaussian-count ratio alone understates what an SH setting costs."""
    from splatbench.metrics.stats import paired_ratio

    done = done_runs(runs)
    if done.empty or not {"metric.num_gaussians", "metric.sh_degree"} <= set(done.columns) or not table.rows:
        return [], []
    ref = next((r for r in table.rows if getattr(r, "is_base", False)), table.rows[0])
    parts, claims = [], []
    for scene in scenes:
        per_row = {}
        for row in table.rows:
            sel = done[(done.scene == scene) & done.run_id.isin(row.run_ids)]
            n = pd.to_numeric(sel["metric.num_gaussians"], errors="coerce")
            d = pd.to_numeric(sel["metric.sh_degree"], errors="coerce")
            params: dict[int, list[float]] = {}
            for seed, g, deg in zip(sel.seed, n, d):
                if pd.notna(g) and pd.notna(deg):
                    params.setdefault(int(seed), []).append(float(g) * floats_per_gaussian(int(deg)))
            if params:
                per_row[row.label] = {k: sum(v) / len(v) for k, v in params.items()}
        if not per_row:
            continue
        cells = []
        for label, seeds in per_row.items():
            mean = sum(seeds.values()) / len(seeds)
            text = f"`{label}` {mean / 1e6:.2f} M parameters, {mean * PARAM_BYTES / 1e6:.1f} MB"
            if label != ref.label and ref.label in per_row:
                ratio = paired_ratio(per_row[ref.label], seeds)
                if ratio.n and math.isfinite(ratio.estimate):
                    text += f" (×{ratio.estimate:.3f} `{ref.label}`'s)"
                    claims.append(Claim("model size", scene, label, "parameters", "ratio", ratio.estimate,
                                        f"×{ratio.estimate:.3f}", ref.label, ratio.low, ratio.high, ratio.n))
            cells.append(text)
        parts.append(f"{scene}: " + "; ".join(cells))
    if not parts:
        return [], []
    return [f"- Model size (float32 parameters per Gaussian 3 + 3 + 4 + 1 + 3·(d + 1)²: {floats_per_gaussian(0)} at SH "
            f"degree 0, {floats_per_gaussian(3)} at 3, d the degree each run ended at; times its Gaussians, mean over "
            f"seeds; ratios paired over seeds): " + " / ".join(parts) + "."], claims


#: The window of the test SSIM (`splatbench.metrics.image.ssim_metric`: 11 taps, σ 1.5).
METRIC_SSIM_WINDOW = 11


def ssim_trained_note(table: AxisRows, runs: pd.DataFrame, scenes: list[str]) -> tuple[list[str], list[Claim]]:
    """Where the loss trains on SSIM (``loss.ssim_lambda > 0``: (1 − λ) L1 + λ D-SSIM), the test SSIM the
    findings compare is the trained quantity (the same SSIM where ``loss.ssim_window`` is the metric's 11
    taps): a difference in it is partly the optimiser doing what it was asked, not an independent
    measure of quality. Names the rows that train on it and the weights."""
    done = done_runs(runs)
    if done.empty or "config.loss.ssim_lambda" not in done.columns:
        return [], []
    lam = pd.to_numeric(done["config.loss.ssim_lambda"], errors="coerce")
    if not (lam > 0).any():
        return [], []
    windows = {int(w) for w in pd.to_numeric(done.get("config.loss.ssim_window", pd.Series([], dtype=float)),
                                              errors="coerce").dropna()}
    same = windows == {METRIC_SSIM_WINDOW}
    which = "the same SSIM (its 11-tap Gaussian window)" if same else         f"an SSIM of window {' / '.join(map(str, sorted(windows))) or 'unrecorded'} (the metric's is 11)"
    rows = []
    for row in table.rows:
        sel = lam[done.run_id.isin(row.run_ids)]
        values = sorted({float(v) for v in sel.dropna()})
        if values and max(values) > 0:
            rows.append((row.label, values))
    ran = [r for r in table.rows if done.run_id.isin(r.run_ids).any()]  # not a row without runs (an extra cell's)
    if len(rows) == len(ran) and len({tuple(v) for _, v in rows}) == 1:
        where = f"in every row (loss.ssim_lambda = {' / '.join(f'{v:g}' for v in rows[0][1])})"
    else:
        where = "in " + ", ".join(f"`{label}` (loss.ssim_lambda = {' / '.join(f'{v:g}' for v in vs)})" for label, vs in rows)
    return [f"- SSIM: the loss, (1 − λ) L1 + λ D-SSIM, trains on {which} {where}: the test SSIM compared above is "
            f"the quantity those runs optimised, so a difference in it is partly the trained objective, not an "
            f"independent measure of quality (test PSNR and LPIPS are not trained on)."], []


#: Strategies whose opacity resets gate size pruning and fire only inside the refine window
#: (`splatbench.strategies.default.DefaultStrategy` and its subclasses).
_RESETTING = ("default", "absgrad", "budget")


def schedule_confound_note(table: AxisRows, runs: pd.DataFrame, scenes: list[str]) -> tuple[list[str], list[Claim]]:
    """What a densification-schedule setting changes besides itself, read from the
    runs' configs (so it holds for grids run before the counts were recorded):
    ``reset_every = 0`` also turns off size pruning (DefaultStrategy prunes by size only after
    the first reset), and ``refine_stop`` also changes the number of opacity resets (they fire
    only inside the refine window)."""
    done = done_runs(runs)
    col = f"config.{table.axis}" if not table.axis.startswith("config.") else table.axis
    if "config.strategy.name" not in done.columns or col not in done.columns:
        return [], []
    resetting = done[done["config.strategy.name"].isin(_RESETTING)]
    lines = []
    if table.axis == "strategy.reset_every":
        zero = [r for r in table.rows if decode(r.value) == 0 and resetting.run_id.isin(r.run_ids).any()]
        for r in zero:
            lines.append(f"- `{r.label}` (no opacity resets) also turns off size pruning: the default strategy prunes "
                         f"Gaussians larger than `max_world_size` × the scene extent only after its first opacity "
                         f"reset (splatbench/strategies/default.py), so this cell changes two things, not one.")
    if table.axis == "strategy.refine_stop" and len(resetting):
        lines.append("- Opacity resets fire only inside the refine window (as in graphdeco), so `refine_stop` also "
                     "changes how many resets a run makes (`metric.opacity_resets` where recorded).")
    return lines, []


def memory_note(runs: pd.DataFrame) -> list[str]:
    """Why a table of runs recorded before ``run_peak_rss_mb`` shows no memory column: their
    ``peak_rss_mb`` is their worker process's lifetime peak, which carries the peaks of the runs
    that worker ran before (a spawn pool reuses its workers), so it is no per-cell cost."""
    done = done_runs(runs)
    own = "metric.run_peak_rss_mb" in done.columns and pd.to_numeric(done["metric.run_peak_rss_mb"],
                                                                       errors="coerce").notna().any()
    if own or "metric.peak_rss_mb" not in done.columns or done.empty:
        return []
    return ["- No peak-memory column: these runs recorded their worker process's lifetime peak RSS "
            "(`metric.peak_rss_mb`), and a worker runs several runs in turn, so a run carries the peaks of the runs "
            "it followed (not a cost of its cell). Runs since record their own (`metric.run_peak_rss_mb`, the "
            "high-water mark reset as each run starts), shown as `peak RSS (MB)`."]


def lpips_conventions(runs: pd.DataFrame) -> list[tuple[str, bool]]:
    """The LPIPS conventions ``(net, scale_inputs)`` the done runs of ``runs`` recorded (``lpips_net``,
    ``lpips_scale_inputs``), sorted; [] for a table without them or runs that computed none."""
    if "metric.lpips_net" not in runs.columns:
        return []
    done = done_runs(runs)
    done = done[done["metric.lpips_net"].fillna("").astype(bool)]
    return sorted({(str(r["metric.lpips_net"]), bool(r["metric.lpips_scale_inputs"])) for _, r in done.iterrows()})


def lpips_note(runs: pd.DataFrame) -> list[str]:
    """Which LPIPS the report's column is (net and input convention), from the
    done runs' ``lpips_net`` / ``lpips_scale_inputs``; none for a table without them."""
    from splatbench.metrics.perceptual import convention  # late: the reports start without torch

    kinds = lpips_conventions(runs)
    if len(kinds) == 1:
        return [f"- The `LPIPS` column is {convention(*kinds[0])}."]
    return [f"- The `LPIPS` column mixes {len(kinds)} conventions (compare within one only): "
            + "; ".join(convention(*k) for k in kinds) + "."] if kinds else []


# --------------------------------------------------------------------------- outlier test views
#: How far (dB) a test view must fall below the median of the same view over its cell's other seeds to be
#: flagged (`view_outliers`). Far above a healthy run's seed-to-seed spread of one view, measured on real
#: records (each saved final model evaluated again, tools/backfill_view_psnr.py; the gap is a view's PSNR
#: below the median of the same view in the cell's other seeds): 192 views of the 24 quick_protocol runs that
#: stayed healthy (guitar teacher at 43-46 dB, textured Mitsuba scene at 29 dB, 3 seeds, 8 views) gap at most
#: 1.5 dB (SD 0.34 dB on guitar, 0.08 dB on textured); the real capture fox (sh_degree, 9 views, 2 seeds per
#: cell) at most 4.5 dB, on its hardest view (view 7 at 23-28 dB), its other views at most 0.7 dB. And below
#: the drops of the floaters seen: 18.3 and 24.8 dB in guitar seed 1's two 7K runs, 15-25 dB at its
#: checkpoints (docs/history/2026-12-07-divergent-seed.md). 10 dB is more than twice the largest healthy gap
#: and 5 dB under the smallest floater drop. A smaller floater can cost a view less (guitar's 7K no_resets
#: seed 2 has view 7 at 46.7 dB against 51.7 / 52.8 in the other seeds, 5.6 dB, its mean 0.1 dB lower) and
#: goes unflagged: at 52 dB that is 1.5e-5 more mean square error, and 5.6 dB is near fox's healthy 4.5 dB.
#: A run's own worst view against its median is no test: maryrose's view 8 sits 10-12 dB below its run's
#: median view in every run (a hard view, not a floater).
OUTLIER_VIEW_DB = 10.0
#: Where the mechanism is explained.
FLOATER_DOC = "docs/history/2026-12-07-divergent-seed.md"


@dataclass(frozen=True)
class OutlierRun:
    """A run with test views far below the same views in its cell's other seeds (`view_outliers`).

    views: (view index in test-split order, its PSNR, the median of the same view over the cell's
    other runs that recorded it), each more than `OUTLIER_VIEW_DB` below that median; cell_mean /
    without: the mean test PSNR over the cell's done runs with this run and without it (NaN when
    it is the cell's only run with a test PSNR)."""

    run_id: str
    scene: str
    cell: str
    seed: int
    views: tuple[tuple[int, float, float], ...]
    cell_mean: float
    without: float


@dataclass(frozen=True)
class ViewCheck:
    """`view_outliers`' answer: the flagged runs; how many runs were compared with their cell's
    other seeds (``checked``); how many could not be: ``unrecorded`` (no ``curves.test_view_psnr``:
    finished before runs recorded it) and ``alone`` (no other run of its cell recorded as many views)."""

    outliers: tuple[OutlierRun, ...]
    checked: int
    unrecorded: int
    alone: int


def _view_psnrs(raw: Any) -> list[float] | None:
    """A run's ``curves.test_view_psnr`` (the curves' JSON text), or None where not recorded."""
    try:
        c = json.loads(raw) if isinstance(raw, str) else {}
    except ValueError:
        return None
    views = c.get("test_view_psnr") if isinstance(c, dict) else None
    if not isinstance(views, list) or not views or not all(isinstance(v, (int, float)) for v in views):
        return None
    return [float(v) for v in views]


def view_outliers(table: pd.DataFrame, threshold: float = OUTLIER_VIEW_DB) -> ViewCheck:
    """Each done run's test views (``curves.test_view_psnr``) against the same views of the other
    runs of its scene and cell (the same ``axis.*`` values and ``config.protocol``: the other
    seeds): a run is flagged for every view more than ``threshold`` dB below the median of that
    view over the others (a floater in front of that camera: `FLOATER_DOC`)."""
    done = done_runs(table)
    axes = [c for c in done.columns if c.startswith("axis.")]
    keys = [*axes, *(["config.protocol"] if "config.protocol" in done.columns else [])]
    cells: dict[tuple, list[tuple[Any, list[float] | None]]] = {}
    for _, row in done.iterrows():
        key = (str(row.scene), *(cell_value(row[c]) for c in keys))
        cells.setdefault(key, []).append((row, _view_psnrs(row.get("curves"))))
    outliers, checked, unrecorded, alone = [], 0, 0, 0
    for (scene, *values), runs in cells.items():
        label = ", ".join(f"{a[5:]}={_g(v)}" for a, v in zip(axes, values)) or "the base"
        psnrs = pd.to_numeric(pd.Series([r["metric.test_psnr"] if "metric.test_psnr" in r else None
                                         for r, _ in runs]), errors="coerce")
        for k, (row, views) in enumerate(runs):
            if views is None:
                unrecorded += 1
                continue
            others = [v for j, (_, v) in enumerate(runs) if j != k and v is not None and len(v) == len(views)]
            if not others:
                alone += 1
                continue
            checked += 1
            median = np.median(np.array(others), axis=0)
            low = [(i, p, float(m)) for i, (p, m) in enumerate(zip(views, median))
                   if math.isfinite(p) and math.isfinite(m) and m - p > threshold]
            if low:
                rest = psnrs.drop(index=k).dropna()
                outliers.append(OutlierRun(str(row.run_id), scene, label, int(row.seed), tuple(low),
                                           float(psnrs.dropna().mean()) if psnrs.notna().any() else math.nan,
                                           float(rest.mean()) if len(rest) else math.nan))
    return ViewCheck(tuple(outliers), checked, unrecorded, alone)


def outlier_view_lines(table: pd.DataFrame) -> list[str]:
    """`view_outliers` in words: one line per flagged run (its views, how far below, what its cell's
    mean is with and without it) and one of what was checked; [] where no done run recorded its
    views (runs from before `curves.test_view_psnr`: nothing to say but that, which a report of
    such runs does not repeat)."""
    return _outlier_lines(view_outliers(table))


def check_schedule_note(table: pd.DataFrame) -> RunNotes:
    """Where the check's runs differ from graphdeco's train.py (docs/training.md, "Evaluation order"), as the
    grid's Protocol lines say it of the grid's: a refinement at their last step before its evaluation, the
    opacity reset graphdeco adds on white at its refine start; nothing where neither applies."""
    done = done_runs(table)
    if done.empty:
        return RunNotes()
    late = refined_at_end(done)
    said = [f"{late} of {len(done)} refined at their last step, right before its evaluation"] if late else []
    said += [white] if (white := _white_reset(done)) else []
    if not said:
        return RunNotes()
    return RunNotes(("- **The check's runs against graphdeco's train.py**: " + "; ".join(said) + ".",))


def outlier_view_note(table: pd.DataFrame) -> RunNotes:
    """The check's runs' `outlier_view_lines`, with how many runs they flag (`KindReport.check_notes`)."""
    found = view_outliers(table)
    return RunNotes(tuple(_outlier_lines(found)), len(found.outliers))


def _outlier_lines(found: ViewCheck) -> list[str]:
    """`outlier_view_lines` of what `view_outliers` found."""
    if not found.checked and not found.alone:
        return []
    lines = []
    for o in found.outliers:
        views = "; ".join(f"test view {i} at {p:.2f} dB, {m - p:.1f} dB below the same view in the cell's other "
                          f"seeds (their median {m:.2f} dB)" for i, p, m in o.views)
        moved = (f"; its cell's mean test PSNR is {o.cell_mean:.2f} dB with this run, {o.without:.2f} dB over the "
                 f"other seeds alone ({o.cell_mean - o.without:+.2f} dB)"
                 if math.isfinite(o.cell_mean) and math.isfinite(o.without) else "")
        lines.append(f"- **Outlier test view**: {o.scene}, `{o.cell}`, seed {o.seed} (`{o.run_id}`): {views}: "
                     f"likely a floater in front of that camera ({FLOATER_DOC}){moved}.")
    missed = []
    if found.unrecorded:
        missed.append(f"{found.unrecorded} without a per-view record (finished before runs recorded "
                      f"`curves.test_view_psnr`)")
    if found.alone:
        missed.append(f"{found.alone} without another seed of its cell to compare with")
    lines.append(f"- Each run's test views against the same views in its cell's other seeds (flagged: more than "
                 f"{OUTLIER_VIEW_DB:g} dB below their median): {found.checked} run{'' if found.checked == 1 else 's'} "
                 f"checked, {len(found.outliers)} flagged"
                 + (f"; {found.unrecorded + found.alone} could not be: {', '.join(missed)}" if missed else "") + ".")
    return lines


def hardest_view_lines(table: pd.DataFrame, min_effect: float = 0.1) -> list[str]:
    """Per scene, the test view that is the lowest in the most runs (a view low in *every* run -- a hard
    view, or a target the model cannot match, such as a mask that cuts away what the model renders --
    is not an outlier of one seed, so `view_outliers` cannot see it): how often it is the lowest, its
    PSNR and its gap below each run's median view, and how much each cell's mean test PSNR would rise
    without it (a rise the same in every cell leaves the comparisons as they are; a spread of rises
    bounds how much that one view moves them). Only scenes where leaving it out would move some cell's
    mean by ``min_effect`` dB or more (the train kind's test-PSNR minimum effect, `MIN_EFFECT`); []
    where no run recorded its views."""
    done = done_runs(table)
    axes = [c for c in done.columns if c.startswith("axis.")]
    lines = []
    for scene, rows in done.groupby("scene", sort=False):
        runs = [(tuple(cell_value(r[c]) for c in axes), v) for _, r in rows.iterrows()
                if (v := _view_psnrs(r.get("curves"))) is not None]
        if not runs or len({len(v) for _, v in runs}) != 1 or len(runs[0][1]) < 2:
            continue
        worst = [int(np.argmin(v)) for _, v in runs]
        view = max(set(worst), key=worst.count)
        psnr = [v[view] for _, v in runs]
        gap = [float(np.median(v)) - v[view] for _, v in runs]
        rise: dict[tuple, list[float]] = {}
        for cell, v in runs:
            rise.setdefault(cell, []).append(float(np.mean(np.delete(np.array(v), view)) - np.mean(v)))
        cell_rise = [float(np.mean(r)) for r in rise.values()]
        if max(cell_rise) < min_effect:  # a view that moves no cell's mean by the minimum effect is not worth a line
            continue
        lines.append(f"- {scene}: test view {view}, the lowest in {worst.count(view)} of {len(runs)} runs, "
                     f"{min(psnr):.1f}–{max(psnr):.1f} dB, {min(gap):.1f}–{max(gap):.1f} dB below its run's median "
                     f"view; without it each cell's mean test PSNR would rise by {min(cell_rise):.2f}–"
                     f"{max(cell_rise):.2f} dB, so it moves a mean difference between two cells by at most "
                     f"{max(cell_rise) - min(cell_rise):.2f} dB (the spread of those rises).")
    if not lines:
        return []
    return [f"- **Hardest test view** per scene where it moves a cell's mean by {min_effect:g} dB or more (a view "
            f"low in every run is a property of the scene or its target, not of a seed):", *("  " + x for x in lines)]


def outlier_view_finding(runs: pd.DataFrame, min_effect: Mapping[str, float] | None = None) -> Finding | None:
    """The grid's runs' `outlier_view_lines` as a run finding (`KindReport.run_findings`), its own
    section "Appendix: Outlier test views"; None where no run recorded its views."""
    lines = outlier_view_lines(runs)
    hardest = hardest_view_lines(runs, **({"min_effect": min_effect["test_psnr"]}
                                          if min_effect and "test_psnr" in min_effect else {}))
    return Finding("outlier test views", [*lines, *hardest], []) if lines else None


__all__ = ["OUTLIER_VIEW_DB", "FLOATER_DOC", "OutlierRun", "ViewCheck", "view_outliers", "outlier_view_lines",
           "outlier_view_note", "check_schedule_note", "outlier_view_finding", "hardest_view_lines",
           "DEFAULT_PROTOCOL", "SMOKE_TEST", "smoke_test_line", "model_bytes", "protocol_lines", "model_size_note", "floats_per_gaussian", "ssim_trained_note", "seed_varies", "scene_kinds", "auto_sh_degree_note", "how_read",
           "schedule_confound_note", "lpips_conventions", "lpips_note", "memory_note"]
