"""Per-photo masks: files that say which pixels of a photo may colour the mesh.

A mask is an image of the photo's size (PNG, JPEG or TIFF; grey, colour, with or without
alpha, 1 to 16 bits). By default a pixel whose value is nonzero in any channel is **kept** and a
zero pixel is **masked out** (never used): the convention of AliceVision / Meshroom (``mask(pix)
== 0`` is masked, ``main_prepareDenseScene.cpp``), of OpenMVS (``ImportIgnoreMask``: the ignore
label, 0 with ``--ignore-mask-label 0``, is masked, ``libs/MVS/DepthMap.cpp``) and of COLMAP. The
other convention (nonzero = masked out, white on the occluder) is ``mask_invert=True``
(``--mask-invert``). A mask is registered to its photo as stored: a distorted photo's mask is
undistorted with it, nearest neighbour (:meth:`~o3d_seqcc.scene.View.load_mask`).

:func:`attach_masks` finds a folder's mask of every view (``load_scene(masks=DIR)``,
``--masks DIR``), by name, the first that exists of, for each suffix of :data:`MASK_SUFFIXES`
(any case): the format's own names (Meshroom's ``<viewId>``), ``<image stem>``, ``<view
name>``, ``<image file name>`` (COLMAP's ``img.jpg.png``), then OpenMVS's ``<image
stem>.mask.png``.
"""

from __future__ import annotations

import io
import logging
import os
from dataclasses import replace
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from ..errors import InputError, warn
from .images import image_header
from .raster_checks import read_bounded
from .regular_files import open_regular

__all__ = ["MASK_SUFFIXES", "attach_masks", "check_mask_file", "find_mask", "mask_array", "mask_candidates",
           "mask_distorted", "read_mask", "view_mask"]

logger = logging.getLogger(__name__)

#: the file suffixes a mask is looked for with, in this order (any case)
MASK_SUFFIXES = (".png", ".jpg", ".jpeg", ".tif", ".tiff")


def _size_error(path: Path, view: str, w: int, h: int, shape: tuple[int, int]) -> InputError:
    return InputError(f"mask {path} of view {view!r} is {w}x{h} but the photo is {shape[1]}x{shape[0]}; give a mask "
                      "of the photo's size (pixel for pixel: nonzero = kept, 0 = masked out)")


def check_mask_file(path: str | os.PathLike, *, shape: tuple[int, int], view: str) -> None:
    """Check a mask file from its header, without decoding it: a readable image of ``shape`` ((height, width)).

    Raises
    ------
    InputError
        Missing, not a regular file, unreadable, over the pixel budget, truncated, or of another
        size than the photo; the message names the mask file, the view and the expected size.
    """
    path = Path(path)
    try:
        with open_regular(path, "mask") as f:
            w, h, _ = image_header(path, f, os.fstat(f.fileno()).st_size, what="mask")
    except InputError as e:
        raise InputError(f"view {view!r}: {e}") from None
    if (h, w) != tuple(shape):
        raise _size_error(path, view, w, h, shape)


def read_mask(path: str | os.PathLike, *, shape: tuple[int, int], view: str) -> np.ndarray:
    """Read a mask file: (H, W) bool, True where any channel of the pixel is nonzero.

    Raises
    ------
    InputError
        As :func:`check_mask_file`, or a file OpenCV cannot decode.
    """
    import cv2

    path = Path(path)
    try:
        data = read_bounded(path, "mask")
        w, h, _ = image_header(path, io.BytesIO(data), len(data), what="mask", full=True)
    except InputError as e:
        raise InputError(f"view {view!r}: {e}") from None
    if (h, w) != tuple(shape):
        raise _size_error(path, view, w, h, shape)
    m = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED | cv2.IMREAD_ANYDEPTH)
    if m is None:
        raise InputError(f"view {view!r}: cannot read mask {path}: not an image OpenCV can decode (save it as PNG)")
    if m.shape[:2] != tuple(shape):
        raise _size_error(path, view, m.shape[1], m.shape[0], shape)
    return m != 0 if m.ndim == 2 else np.any(m != 0, axis=2)


def mask_candidates(name: str, image: Path | None, extra: Sequence[str] = ()) -> list[str]:
    """The file names a view's mask may have in a masks folder, in the order they are tried (module docstring)."""
    stems = [*extra]
    if image is not None:
        stems.append(image.stem)
    stems.append(name)
    if image is not None:
        stems.append(image.name)
    out = list(dict.fromkeys(f"{s}{ext}" for s in stems for ext in MASK_SUFFIXES))
    if image is not None:
        out.append(f"{image.stem}.mask.png")
    return out


def find_mask(folder: Path, names: Sequence[str], listing: Mapping[str, str] | None = None) -> Path | None:
    """The first of ``names`` in ``folder`` (compared without case), or None; ``listing`` maps the folder's file
    names in lower case to themselves (one listing for many views)."""
    if listing is None:
        listing = _listing(folder)
    for n in names:
        hit = listing.get(n.lower())
        if hit is not None:
            return folder / hit
    return None


def _listing(folder: Path) -> dict[str, str]:
    try:
        entries = sorted(e.name for e in os.scandir(folder) if e.is_file())
    except OSError as e:
        raise InputError(f"masks folder {folder}: cannot list it ({e.strerror})") from None
    out: dict[str, str] = {}
    for n in entries:
        out.setdefault(n.lower(), n)
    return out


def attach_masks(views: Sequence, folder: str | os.PathLike | None, *, invert: bool = False,
                 extra: Mapping[str, Sequence[str]] | None = None) -> tuple:
    """The views with the masks of ``folder`` (those it has a mask for; the others keep their own, if any).

    Parameters
    ----------
    views : sequence of View
    folder : path-like or None
        The masks folder (module docstring: the names tried); None attaches nothing (``invert``
        still applies).
    invert : bool, default False
        Nonzero = masked out, for the masks of ``folder`` and those the views already name.
    extra : mapping of str to sequence of str, optional
        View name -> the format's own mask stems, tried first (Meshroom's view id).

    Raises
    ------
    InputError
        ``folder`` is not a folder, or holds a mask for none of the views (the message names the
        names looked for).

    Warns
    -----
    O3dSeqccWarning
        Some views have no mask in ``folder`` (they are used whole), named.
    """
    views = tuple(views)
    if folder is not None:
        folder = Path(folder)
        if not folder.is_dir():
            raise InputError(f"masks {folder} is not a folder; give the folder that holds the masks (--masks DIR)")
        listing = _listing(folder)
        out, without = [], []
        for v in views:
            found = find_mask(folder, mask_candidates(v.name, v.image, (extra or {}).get(v.name, ())), listing)
            if found is None:
                out.append(v)
                without.append(v.name)
                continue
            dist = v.distortion if v.distortion is None or v.distortion.masks is None else replace(v.distortion,
                                                                                                    masks=None)
            out.append(replace(v, mask=found, mask_map=None, distortion=dist))
        if len(without) == len(views):
            v = views[0]
            tried = ", ".join(mask_candidates(v.name, v.image, (extra or {}).get(v.name, ()))[:6])
            raise InputError(f"masks {folder}: no mask for any of the {len(views)} views (for view {v.name!r} looked "
                             f"for {tried}, ...); give the folder of the masks, named after the photos")
        if without:
            shown = ", ".join(repr(n) for n in without[:8]) + (" ..." if len(without) > 8 else "")
            warn(f"masks {folder}: no mask for {len(without)} of {len(views)} views ({shown}): they are used whole")
        views = tuple(out)
        logger.info("masks %s: %d of %d views masked", folder, len(views) - len(without), len(views))
    if invert:
        views = tuple(replace(v, mask_invert=True) if v.has_mask else v for v in views)
    return views


def mask_array(mask, shape: tuple[int, int], where: str) -> np.ndarray:
    """A mask given in memory as a read-only (H, W) bool array (True = nonzero), checked against ``shape``.

    Raises
    ------
    InputError
        Not of the photo's size, or not bool / numbers; the message starts with ``where``.
    """
    m = np.asarray(mask)
    m = m[..., 0] if m.ndim == 3 and m.shape[2] == 1 else m
    if m.shape != tuple(shape) or not (m.dtype == bool or np.issubdtype(m.dtype, np.number)):
        raise InputError(f"{where}: the mask must be {tuple(shape)} (the photo's size, {shape[1]}x{shape[0]}), bool "
                         f"or numbers, got shape {m.shape} {m.dtype}")
    out = np.array(m != 0, copy=True)
    out.setflags(write=False)
    return out


def mask_distorted(view) -> bool:
    """A view's mask is registered to its distorted photo (its distortion's ``masks``, default its ``images``):
    :func:`view_mask` undistorts it."""
    d = view.distortion
    return d is not None and not d.is_zero and bool(d.images if d.masks is None else d.masks)


def view_mask(view) -> np.ndarray | None:
    """A view's mask (:meth:`~o3d_seqcc.scene.View.load_mask`): (H, W) bool, True where the photo's pixels count,
    False where they are masked out (``mask_invert`` applied; undistorted, nearest neighbour, when
    :func:`mask_distorted`); None without one.

    Raises
    ------
    InputError
        The mask file is missing, unreadable or of another size than the photo (naming the file,
        the view and the expected size).
    """
    if view.mask_map is not None:
        nonzero = view.mask_map
    elif view.mask is None:
        return None
    else:
        nonzero = read_mask(view.mask, shape=(view.height, view.width), view=view.name)
    keep = ~nonzero if view.mask_invert else np.array(nonzero)
    if mask_distorted(view):
        keep = view.distortion.undistort(keep.view(np.uint8), view.intrinsic, nearest=True) != 0
    return keep
