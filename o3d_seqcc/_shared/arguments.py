"""Checks of the library's own arguments: a wrong type or value is an InputError naming the argument.

The entry points (:mod:`o3d_seqcc.pipeline`, :mod:`o3d_seqcc.open3d_api`) call these (and
:func:`o3d_seqcc.scene.check_scene_argument`) before any
work, so that ``pipeline.run(123)`` says "scene must be a Scene or the path of a scene, got 123
(int)" instead of a ``TypeError`` from deep inside ``pathlib``.
"""

from __future__ import annotations

import os
from typing import Any, Sequence

import numpy as np

from ..errors import InputError

__all__ = ["check_images_argument", "check_type", "shown"]


def shown(value: Any) -> str:
    """``value`` for a message: its repr (cut at 60 characters) and its type."""
    text = repr(value)
    return f"{text[:60] + '...' if len(text) > 60 else text} ({type(value).__name__})"


def check_type(name: str, value: Any, kind: type | tuple, *, optional: bool = True) -> None:
    """Raise InputError unless ``value`` is a ``kind`` (or None when ``optional``)."""
    if value is None and optional or isinstance(value, kind):
        return
    names = " or ".join(k.__name__ for k in (kind if isinstance(kind, tuple) else (kind,)))
    raise InputError(f"{name} must be a {names}{' or None' if optional else ''}, got {shown(value)}")


def check_images_argument(images: Any, views: Sequence) -> list:
    """``images``: one (H, W, 3) uint8 / uint16 RGB image per view, of the view's size; returns them as a list."""
    if isinstance(images, (str, bytes, os.PathLike)) or not hasattr(images, "__len__"):
        raise InputError(f"images must be a list of (H, W, 3) images, one per view, got {shown(images)}")
    imgs = list(images)
    if len(imgs) != len(views):
        raise InputError(f"images: {len(imgs)} given for {len(views)} views; give one per view")
    for i, (im, v) in enumerate(zip(imgs, views)):
        a = np.asarray(im) if isinstance(im, np.ndarray) or hasattr(im, "__array__") else None
        if a is None or a.shape != (v.height, v.width, 3) or a.dtype not in (np.uint8, np.uint16):
            got = shown(im) if a is None else f"{a.shape} {a.dtype}"
            raise InputError(f"images[{i}] must be a ({v.height}, {v.width}, 3) uint8 / uint16 RGB image (view "
                             f"{v.name!r}), got {got}")
    return imgs
