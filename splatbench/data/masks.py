"""A capture's object masks, in every layout: ``masks/`` or ``masks_N/`` beside its images.

One implementation for the COLMAP, Blender/instant-ngp and LLFF loaders (`load_dataset`):

* **Which folder** -- ``masks/`` (factor 1, the full-size photos) and ``masks_N/`` (the
  photos reduced by N, as ``images_N/``). The images read at factor F take ``masks_F/``,
  else the nearest finer mask folder (reduced by area averaging to the images' size);
  one `InputError` line when no folder serves F.
* **Which file** -- by the image's path inside its image folder without the suffix
  (``images_8/IMG_1.jpg`` <- ``masks_8/IMG_1.png``; a subfolder is kept:
  ``images/cam0/IMG_1.jpg`` <- ``masks/cam0/IMG_1.png``), with an optional ``_mask``
  suffix (NeRD's ``masks_8/IMG_9669_mask.png``) or named after the whole image name
  (COLMAP's ``masks/IMG_1.jpg.png``). An image with no mask, an image two files could be
  the mask of (``IMG_1.png`` and ``IMG_1_mask.png``), or one mask two images would share:
  one `InputError` line naming the files. A mask that no image takes: a note.
* **What it holds** -- read as grey (8-bit, 255 = the object, 0 = background; COLMAP's
  masks use the same values), the image's size, or a larger one of the same aspect
  (a finer folder), reduced by area. It becomes the view's alpha (multiplied into an
  RGBA photo's own alpha).

``data.masks=false`` ignores the folders, with a note; a distorted capture with masks is
refused in one line (the loader undistorts the photos, not their masks).
"""

from __future__ import annotations

import re
from collections.abc import Callable
from pathlib import Path

import numpy as np

from splatbench.errors import InputError

#: Mask files read (as for LLFF's images), any case.
MASK_SUFFIXES = (".png", ".jpg", ".jpeg")
_OFF = "or set data.masks=false to ignore the masks"


def folders(root: Path, base: str) -> dict[int, str]:
    """``{factor: folder}`` of ``root``'s ``base/`` (factor 1) and ``base_N/`` folders."""
    out = {1: base} if (root / base).is_dir() else {}
    for entry in root.iterdir():
        m = re.fullmatch(rf"{re.escape(base)}_(\d{{1,4}})", entry.name)
        if m and int(m.group(1)) >= 1 and entry.is_dir():
            out.setdefault(int(m.group(1)), entry.name)
    return dict(sorted(out.items()))


def folder_factor(folder: str) -> int:
    """N of an ``images_N`` folder name, 1 for any other (``images``, ``train``)."""
    m = re.fullmatch(r".+_(\d{1,4})", folder)
    return int(m.group(1)) if m and int(m.group(1)) >= 1 else 1


def image_key(rel: str) -> str:
    """The path of image ``rel`` (relative to the capture) inside its image folder."""
    parts = Path(rel).parts
    return Path(*parts[1:]).as_posix() if len(parts) > 1 else parts[0]


class Masks:
    """The mask folders of ``root`` and the matches made so far (module doc). ``use``:
    False ignores them (``note`` says so); ``note`` gets the lines a user should know."""

    def __init__(self, root: Path, use: bool, note: Callable[[str], None], *, headers_only: bool = False) -> None:
        self.root, self.note = root, note
        self.headers_only = headers_only  # `read` checks a mask's header and decodes nothing (a dry run)
        self.folders = folders(root, "masks")
        self.enabled = use and bool(self.folders)
        self._index: dict[str, dict[str, list[str]]] = {}  # folder -> key -> mask files (relative to the folder)
        self._taken: dict[str, str] = {}  # mask (relative to root) -> the image that took it
        if self.folders and not use:
            note(f"{', '.join(f + '/' for f in self.folders.values())}: masks ignored (data.masks=false); the "
                 f"photos are trained as they are")

    def refuse_distortion(self, rel: str, model: str) -> None:
        """One line: masks cannot accompany image ``rel`` of a distorted ``model`` camera."""
        raise InputError(f"{rel}: its {model} camera has lens distortion, which splatbench removes from the photos "
                         f"on load but not from {', '.join(f + '/' for f in self.folders.values())} (the masks would "
                         f"no longer fit): undistort photos and masks together first (COLMAP's image_undistorter), "
                         f"{_OFF}")

    def folder_for(self, factor: int, what: str) -> str:
        """The mask folder for images at ``factor``: ``masks_<factor>/``, else the nearest finer one."""
        if factor in self.folders:
            return self.folders[factor]
        finer = [m for m in self.folders if m < factor]
        if not finer:
            raise InputError(f"{what}: no mask folder serves it (mask folders "
                             f"{', '.join(f + '/' for f in self.folders.values())}: a folder of masks reduced by M "
                             f"serves images reduced by M or more); add masks_{factor}/ or masks/, {_OFF}")
        return self.folders[max(finer)]

    def _keys(self, folder: str) -> dict[str, list[str]]:
        if folder not in self._index:
            by_key: dict[str, list[str]] = {}
            base = self.root / folder
            for path in sorted(base.rglob("*")):
                if path.suffix.lower() not in MASK_SUFFIXES or not path.is_file():
                    continue
                name = path.relative_to(base).as_posix()
                stem = name[: -len(path.suffix)]
                for key in {stem} | ({stem[:-5]} if stem.endswith("_mask") else set()):
                    by_key.setdefault(key, []).append(name)
            self._index[folder] = by_key
        return self._index[folder]

    def file(self, folder: str, rel: str) -> str:
        """The mask file (relative to the capture) of image ``rel`` in ``folder``."""
        key = image_key(rel)
        by_key = self._keys(folder)
        stem = key[: -len(Path(key).suffix)] if Path(key).suffix else key
        found = sorted(set(by_key.get(stem, [])) | set(by_key.get(key, [])))
        if not found:
            raise InputError(f"{folder}/: no mask for {rel} (expected {folder}/{stem}.png or {folder}/{stem}_mask.png; "
                             f"every image needs its mask), {_OFF}")
        if len(found) > 1:
            raise InputError(f"{folder}/: {' and '.join(f'{folder}/{f}' for f in found)} could each be the mask of "
                             f"{rel}: keep one (delete or rename the others)")
        mrel = f"{folder}/{found[0]}"
        if self._taken.setdefault(mrel, rel) != rel:
            raise InputError(f"{mrel}: would be the mask of both {self._taken[mrel]} and {rel} (their names differ "
                             f"only in folder or suffix): give each image its own mask, named after it")
        return mrel

    def read(self, mrel: str, rel: str, size: tuple[int, int], exact: tuple[int, int] | None) -> np.ndarray:
        """Mask file ``mrel`` of image ``rel`` as uint8 [H, W] at ``size`` (W, H): as stored,
        or reduced by area from a larger one of the same aspect. ``exact`` (W, H): the size
        the file must have (a mask folder of the image folder's own factor). ``headers_only``:
        the header's size checked, zeros of ``size`` returned (read-only, no memory)."""
        from splatbench.safeio import image_header, read_image

        if self.headers_only:
            mask = None
            got = image_header(self.root / mrel, what=mrel)[:2]
        else:
            mask = read_image(self.root / mrel, what=mrel, mode="L")  # grey, 255 = the object
            got = (mask.shape[1], mask.shape[0])
        fix = f"resize or re-export it to its image's size, {_OFF}"
        if exact is not None and got != exact:
            raise InputError(f"{mrel}: mask size {got[0]}x{got[1]} differs from its image {rel} {exact[0]}x{exact[1]} "
                             f"({fix})")
        w, h = size
        if got != size and (got[0] < w or got[1] < h or abs(got[1] * w / got[0] - h) > 1):  # the same aspect, to a
            raise InputError(f"{mrel}: mask size {got[0]}x{got[1]} cannot be reduced to its image {rel}'s {w}x{h} "
                             f"(a mask is its image's size, or larger with the same aspect; {fix})")  # pixel's rounding
        if mask is None:
            return blank((h, w))
        return mask if got == size else area_resize(mask, w, h)

    def finish(self) -> str:
        """The mask folders used (``"masks_8"``; ``""`` when none), after noting the masks
        used and, in those folders, masks no image took."""
        used = sorted({m.split("/", 1)[0] for m in self._taken})
        for folder in used:
            taken = {m.split("/", 1)[1] for m in self._taken if m.startswith(folder + "/")}
            stray = sorted({f for files in self._keys(folder).values() for f in files} - taken)
            self.note(f"masks: {folder}/ ({len(taken)} object masks) become the views' alphas: the photos are "
                      f"composited over the run's background (data.masks=false ignores them)")
            if stray:
                self.note(f"{folder}/: {len(stray)} masks match no image and are ignored ({', '.join(stray[:3])}"
                          f"{', ...' if len(stray) > 3 else ''}): is an image missing, or is a mask misnamed?")
        return ", ".join(used)


def blank(shape: tuple[int, ...]) -> np.ndarray:
    """Read-only uint8 zeros of ``shape`` that take no memory (one element, broadcast): the
    pixels of an image or mask whose header alone was read (`splatbench.data.check_dataset`)."""
    return np.broadcast_to(np.zeros((), np.uint8), tuple(int(n) for n in shape))


def area_resize(image: np.ndarray, width: int, height: int) -> np.ndarray:
    """``image`` [H, W(, C)] uint8 reduced to ``height`` x ``width`` by area averaging: each
    output pixel the mean of the input area it covers, weighted by the overlap, for any
    ratio (OpenCV's INTER_AREA; PIL's BOX weighs whole pixels by their centres instead),
    rounded to uint8. (LLFF's photos and every layout's masks.)"""
    def weights(n_in: int, n_out: int) -> np.ndarray:  # [n_out, n_in], rows summing to 1
        edges = np.arange(n_out + 1) * (n_in / n_out)
        pixel = np.arange(n_in)[None, :]
        overlap = np.minimum(edges[1:, None], pixel + 1) - np.maximum(edges[:-1, None], pixel)
        return np.clip(overlap, 0, None) / (n_in / n_out)

    pixels = image.reshape(*image.shape[:2], -1).astype(np.float32)  # [H, W, C]; float32 means of 8-bit values: ~1e-5
    rows = (weights(image.shape[0], height).astype(np.float32) @ pixels.reshape(image.shape[0], -1))
    out = weights(image.shape[1], width).astype(np.float32) @ rows.reshape(height, image.shape[1], -1)
    return np.clip(np.rint(out), 0, 255).astype(np.uint8).reshape(height, width, *image.shape[2:])


def combine(alpha: np.ndarray | None, mask: np.ndarray) -> np.ndarray:
    """An RGBA photo's alpha [H, W] uint8 times its mask (both mark what is not the
    object), rounded; the mask alone for an RGB photo."""
    if alpha is None:
        return mask
    return ((alpha.astype(np.uint32) * mask + 127) // 255).astype(np.uint8)


__all__ = ["MASK_SUFFIXES", "Masks", "folders", "folder_factor", "image_key", "area_resize", "combine"]
