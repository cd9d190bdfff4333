"""A ``train`` run's config read as the kind reads it: its keys split into the scene, the scene's
``data`` keys and the `TrainConfig` fields (`split`), the `TrainConfig` they make (`train_config`),
and what that config schedules: the strategy's refinements and opacity resets (`planned`,
`opacity_reset_steps`) and the steps between SH band raises (`sh_steps`).

The kind (`splatbench.experiments.train_kind`) validates, resolves and runs configs through
`split` and `train_config`; its report hooks (`splatbench.experiments.train_report`) and the
reports read a finished run's recorded config (`splatbench.experiments.configs.run_config`)
through the same functions, so a schedule a report names is the one the run made, never a copy
of its rule. The kind imports its report hooks, so what both read lives here, below both.
"""

from __future__ import annotations

import dataclasses
from typing import Any

from splatbench.errors import InputError
from splatbench.guards import check_image_size, check_keys
from splatbench.train.config import DataConfig, TrainConfig, nest  # the kind's Config (loads torch: every use of the kind validates)

#: TrainConfig fields the kind owns (machine-specific paths; never in a config).
OWNED_FIELDS = ("dataset", "out")
#: The ``data`` table: how the scene is rendered into a dataset.
DATA_FIELDS = ("resolution", "views", "spp", "test_spp")
#: ``data`` keys of a dataset folder and of a teacher scene.
FOLDER_FIELDS = ("path",)
TEACHER_FIELDS = ("model", "views", "resolution", "up")


def split(config: dict[str, Any]) -> tuple[str, dict[str, Any], dict[str, Any]]:
    """(scene, the scene's ``data`` keys, the TrainConfig fields) of a nested run config: the
    ``data`` table holds both the scene's keys (`DATA_FIELDS`, `FOLDER_FIELDS`, `TEACHER_FIELDS`)
    and `DataConfig`'s (how the dataset is read: ``downscale``, ``masks``, ...), which go to the
    TrainConfig. Dotted keys (``"sh.degree"``) are read into their tables (`nest`). One-line
    `InputError` naming the field for anything unknown."""
    config = nest(config)
    for key in config:
        if key in OWNED_FIELDS:
            what = "the rendered scene" if key == "dataset" else "the run's folder"
            raise InputError(f"{key}: set by the train kind ({what}); choose the scene with 'scenes' and its "
                             f"rendering with data.resolution / data.views / data.spp / data.test_spp")
    check_keys(config, (*(f.name for f in dataclasses.fields(TrainConfig)), "scene"))
    scene = config.get("scene")
    if not isinstance(scene, str) or not scene:
        raise InputError(f"scene: expected a scene name, got {scene!r}")
    table = config.get("data", {})
    if not isinstance(table, dict):
        raise InputError(f"data: expected a table of {', '.join(DATA_FIELDS)}, got {table!r}")
    read_keys = tuple(f.name for f in dataclasses.fields(DataConfig))
    check_keys(table, (*DATA_FIELDS, *FOLDER_FIELDS, *TEACHER_FIELDS, *read_keys), prefix="data.")
    kind = scene_type(table)
    allowed = {"catalog": DATA_FIELDS, "folder": FOLDER_FIELDS, "teacher": TEACHER_FIELDS}[kind]
    data = {k: v for k, v in table.items() if k in allowed and k not in read_keys}  # other types' keys: module doc
    for key, value in data.items():
        if key in ("path", "model", "up"):
            continue
        if value is not None and (not isinstance(value, int) or isinstance(value, bool) or value < 1):
            raise InputError(f"data.{key}: expected an int >= 1, got {value!r}")
    if data.get("resolution") is not None:  # the width; checked as a square image (the rigs are square)
        check_image_size(data["resolution"], data["resolution"], field="data.resolution", memory=False)
    if data.get("views") is not None and data["views"] < 2:
        raise InputError(f"data.views: expected at least 2 views (one is held out), got {data['views']}")
    train = {k: v for k, v in config.items() if k not in ("scene", "data")}
    reading = {k: v for k, v in table.items() if k in read_keys and (kind == "folder" or k != "downscale")}
    if reading:
        train["data"] = reading
    return scene, data, train


def scene_type(data: dict[str, Any]) -> str:
    """"folder" (``data.path``), "teacher" (``data.model``) or "catalog"."""
    return "folder" if "path" in data else "teacher" if "model" in data else "catalog"


def train_config(train: dict[str, Any]) -> TrainConfig:
    """The TrainConfig of a run config's TrainConfig fields (`split`'s third part)."""
    return TrainConfig.from_dict(dict(train), source="")  # the grid's messages name where the value came from


# --------------------------------------------------------------------------- what a config schedules
def planned(config: dict[str, Any]) -> dict[str, float]:
    """The refinements and opacity resets a run's resolved config schedules (its strategy's
    ``planned_counts``, scaled as the run scales it): what a report names for runs that did
    not record their counts; {} for a config that no longer validates."""
    from splatbench.strategies import planned_counts

    scheduled = _scheduled_strategy(config)
    if scheduled is None:
        return {}
    counts = planned_counts(*scheduled)
    return {"opacity_resets": counts.opacity_resets, "refinements": counts.refinements}


def _recorded_config(config: dict[str, Any]) -> TrainConfig | None:
    """The TrainConfig of a run's resolved config; None for one that no longer validates (what a
    report reads of runs made under older code: `planned`, `opacity_reset_steps`, `sh_steps`)."""
    try:
        return train_config(split(config)[2])
    except InputError:
        return None


def _scheduled_strategy(config: dict[str, Any]) -> tuple[Any, int] | None:
    """(The strategy a run's resolved config makes, scaled as the run scales it; its iterations);
    None for a config that no longer validates (`planned`, `opacity_reset_steps`)."""
    cfg = _recorded_config(config)
    if cfg is None:
        return None
    try:
        return cfg.make_strategy(), cfg.iterations
    except InputError:
        return None


def opacity_reset_steps(config: dict[str, Any]) -> tuple[int, ...]:
    """The completed-iteration counts at which a run's resolved config resets opacities (its strategy
    as the run scales it: every ``reset_every`` iterations while ``it < refine_stop``, the count
    ``planned_counts`` makes); the training step logged at such a count is the first after the reset.
    () for a strategy without resets, or a config that no longer validates (`SettlingCurves.resets`)."""
    scheduled = _scheduled_strategy(config)
    if scheduled is None:
        return ()
    strategy, iterations = scheduled
    steps = getattr(strategy, "reset_steps", None)  # `DefaultStrategy.reset_steps` (and its subclasses')
    return tuple(steps(iterations)) if steps is not None else ()


def sh_steps(config: dict[str, Any]) -> int | None:
    """The steps between SH band raises that a run's resolved config makes (`TrainConfig.sh_steps`:
    ``sh.interval`` scaled by `splatbench.train.schedule.scale_step` over the protocol's schedule
    length, 30,000 under a graphdeco protocol, which so keeps its steps as written); None for a
    config that no longer validates (`splatbench.experiments.train_report.sh_interval_steps`)."""
    cfg = _recorded_config(config)
    return None if cfg is None else cfg.sh_steps


__all__ = ["OWNED_FIELDS", "DATA_FIELDS", "FOLDER_FIELDS", "TEACHER_FIELDS", "split", "scene_type", "train_config",
           "planned", "opacity_reset_steps", "sh_steps"]
