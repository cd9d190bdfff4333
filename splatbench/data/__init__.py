"""Datasets and bundled data.

``load_dataset(path, *, layout="auto", test_every=8, images_dir="images", background=(0, 0, 0), downscale=1, masks=True)``
reads a COLMAP, Blender (NeRF synthetic / nerfstudio / instant-ngp) or LLFF (``poses_bounds.npy``,
``llff.py``) dataset folder, with object masks as alphas in every layout (``masks.py``), undistorting
images whose cameras have lens distortion (``undistort.py``, pycolmap), into a typed
`Dataset` of `Split` s (see ``dataset.py``); ``colmap_folder(path)`` is where a folder's COLMAP
model is (``sparse/0/`` or ``sparse/``; None: none). ``check_dataset(path, ...)`` makes the same
checks from file names and image headers alone (a dry run's; `DatasetCheck`: layout, view counts,
the served image size). The folder also holds package data:
``garden_sfm.npz`` (see ``NOTICE.md``).
"""

from splatbench.data.dataset import (LAYOUTS, PINHOLE_MODELS, Dataset, DatasetCheck, PointCloud, Split, check_dataset,
                                     colmap_folder, load_dataset)

__all__ = ["Dataset", "DatasetCheck", "Split", "PointCloud", "load_dataset", "check_dataset", "LAYOUTS",
           "PINHOLE_MODELS", "colmap_folder"]
