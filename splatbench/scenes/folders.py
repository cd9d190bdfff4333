"""Where a rendered dataset goes, and what a render into an existing folder replaces.

One naming scheme for every dataset folder, used by ``splatbench scenes render``
(`default_out`) and by the experiment runner (``experiments.train_kind.dataset_folder``)::

    dataset_name("glossy", 128, 64, 64)          -> "glossy-128-v64-s64"
    dataset_name("glossy", 128, 64, 64, 2048)    -> "glossy-128-v64-s64-t2048"

`default_out` keeps the short ``data/scenes/<name>-<W>`` for a render at the rig's own
views, split and samples (what the docs and earlier versions use), and uses
`dataset_name` as soon as one of them differs -- so renders with different settings
never share a folder, and a CLI render lands where an experiment with the same
settings looks for it.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

# `plan` below is a `splatbench.scenes.render.RenderPlan` (not imported: render imports this module)


def dataset_name(scene: str, resolution: int | str, views: int, spp: int, test_spp: int | None = None) -> str:
    """``<scene>-<resolution>-v<views>-s<spp>``, plus ``-t<test_spp>`` when it is set and
    differs from ``spp``. ``resolution``: the width, or ``"WxH"``."""
    name = f"{scene}-{resolution}-v{views}-s{spp}"
    return name if test_spp in (None, spp) else f"{name}-t{test_spp}"


def _resolution_token(plan: Any) -> str:
    w, h = plan.resolution
    return str(w) if w == h else f"{w}x{h}"


def at_rig_defaults(plan: Any) -> bool:
    """True when ``plan`` renders the rig's own views, test split and samples per pixel
    (any resolution): a ``--views`` or ``--spp`` equal to the rig's is no difference."""
    rig = plan.scene.rig
    return (len(plan.cameras) == rig.views and list(plan.test) == rig.test_indices()
            and plan.spp == rig.spp and plan.test_spp is None)


def default_out(plan: Any) -> Path:
    """``data/scenes/<name>-<W>`` (``-<W>x<H>`` when not square) at the rig's views, split
    and spp, else ``data/scenes/`` + `dataset_name`; relative to the current folder."""
    token = _resolution_token(plan)
    name = (f"{plan.scene.name}-{token}" if at_rig_defaults(plan)
            else dataset_name(plan.scene.name, token, len(plan.cameras), plan.spp, plan.test_spp))
    return Path("data") / "scenes" / name


def describe_replaced(out: Path, old: dict[str, Any], new: dict[str, Any]) -> str:
    """One line saying what the dataset in ``out`` (its manifest ``old``) held that the
    render of ``new`` (the manifest-to-be: `RenderPlan.inputs` plus ``hash``) replaces."""
    old_settings, new_settings = dict(old.get("settings") or {}), dict(new["settings"])
    for settings in (old_settings, new_settings):  # test_spp absent: the test views had spp
        settings.setdefault("test_spp", settings.get("spp"))
    changes = []
    if old.get("scene") != new["scene"]:
        changes.append(f"scene {old.get('scene')} -> {new['scene']}")
    for key in ("resolution", "views", "test", "spp", "test_spp", "seed", "points"):
        if key == "test" and old_settings.get("views") != new_settings.get("views"):
            continue  # a different view count has a different split anyway
        if old_settings.get(key) != new_settings.get(key):
            changes.append(f"{key} {_show(key, old_settings.get(key))} -> {_show(key, new_settings.get(key))}")
    old_files, new_files = old.get("files") or {}, new["files"]
    if not changes and old_files != new_files:
        changed = sorted(f for f in set(old_files) | set(new_files) if old_files.get(f) != new_files.get(f))
        changes.append(f"scene files changed: {', '.join(changed)}")
    if not changes and old.get("renderer") != new["renderer"]:
        changes.append("renderer version changed")
    if not changes:
        return f"replaced {out}, which held the same render (--force)"
    return f"replaced {out}, which held a different render: {'; '.join(changes)}"


def _show(key: str, value: Any) -> str:
    if key == "resolution" and isinstance(value, list) and len(value) == 2:
        return f"{value[0]}x{value[1]}"
    return str(value)
