"""Mitsuba scene catalog and multi-view dataset rendering.

These are catalog scenes, the ground truth that datasets are rendered from (one of the five
kinds of "scene": docs/architecture.md).

Catalog (``catalog.py``, no Mitsuba import)::

    find_scenes(extra=()) -> dict[str, SceneSpec]     every scene folder found
    get_scene(name_or_folder, extra=()) -> SceneSpec   one scene (a path when the name has a '/')
    SceneSpec(name, folder, rig: RigSpec)              .scene_file, .rig_file, .files()
    RigSpec.cameras(views=None, resolution=None) -> list[Camera];  .test_indices(views=None)

Rendering (``render.py``, Mitsuba variant ``llvm_ad_rgb``)::

    render_dataset(scene, out=None, *, resolution=None, views=None, spp=None, test_spp=None, force=False)
        -> RenderedDataset(path, cached, seconds, train, test, hash, replaced)

Folders (``folders.py``)::

    default_out(plan) -> data/scenes/<name>-<W> at the rig's views and spp, else data/scenes/<dataset_name>
    dataset_name(scene, resolution, views, spp, test_spp=None) -> "<scene>-<W>-v<views>-s<spp>[-t<test_spp>]"
    load_mitsuba_scene(scene) -> mi.Scene              .shapes() for surface sampling
    render_rgb(mi_scene, camera, *, spp, seed=0) -> [H, W, 3] linear RGB
    render_depth(mi_scene, camera) -> [H, W] camera z (0 = no hit)

Surface sampling (``surface.py``, the one implementation; `splatbench.gaussians_from_points.from_surface`
uses it)::

    sample_surface(mi_scene, n, *, seed=0, albedo=False)
        -> SurfacePoints(xyz, normals, shape_index, shape_ids, albedo)

Load a rendered dataset with `splatbench.data.load_dataset`.
"""

from splatbench.scenes.catalog import (RIG_KINDS, RigSpec, SceneSpec, builtin_scenes_dir, find_scenes, get_scene,
                                       load_scene_spec, parse_resolution, scene_dirs)
from splatbench.scenes.folders import dataset_name, default_out
from splatbench.scenes.render import (RenderedDataset, RenderPlan, linear_to_srgb, load_mitsuba_scene,
                                      plan_render, points_from_depth, read_manifest, render_dataset, render_depth,
                                      render_rgb, srgb_to_linear)
from splatbench.scenes.surface import SurfacePoints, sample_surface, shape_order_key

__all__ = ["RIG_KINDS", "RigSpec", "SceneSpec", "builtin_scenes_dir", "find_scenes", "get_scene", "load_scene_spec",
           "parse_resolution", "scene_dirs", "RenderedDataset", "RenderPlan", "SurfacePoints", "dataset_name",
           "default_out", "linear_to_srgb", "load_mitsuba_scene", "plan_render", "points_from_depth", "read_manifest",
           "render_dataset", "render_depth", "render_rgb", "sample_surface", "shape_order_key", "srgb_to_linear"]
