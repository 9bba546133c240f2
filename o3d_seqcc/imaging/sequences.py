"""Images read when a task needs them and released after: lazy, picklable image sequences.

The pipeline never holds every photo in memory at once. Its stages see a *sequence* of images
(``images[v]`` is view ``v``'s image) whose items are produced on access:

- :class:`SceneImages`: ``views[v].load_image()`` (a file read, or the view's in-memory
  pixels); pickles as the views alone, so a Dask worker reads the files itself;
- :class:`FloatImages`: another sequence's images as float64 in [0, 1]
  (:func:`~o3d_seqcc.imaging.arrays.img_as_float`), with a least-recently-used cache of at most
  ``cache_bytes`` (default :data:`CACHE_BYTES`, the environment variable
  ``O3D_SEQCC_IMAGE_CACHE_MB`` overrides it): what the correction methods sample colours from.

Both give exactly the arrays an eager list would hold; only the moment of reading changes.
"""

from __future__ import annotations

import os
import threading
from collections import OrderedDict
from collections.abc import Sequence
from typing import Any, Callable

import numpy as np

from .arrays import img_as_float

__all__ = ["CACHE_BYTES", "CachedImages", "FloatImages", "ImageSequence", "LRUCache", "SceneImages", "default_cache_bytes",
           "image_dtypes", "scene_photos"]

#: default byte budget of the float image cache (512 MiB; ``O3D_SEQCC_IMAGE_CACHE_MB`` overrides it)
CACHE_BYTES = 512 * 2**20


def default_cache_bytes() -> int:
    """The float image cache budget: ``O3D_SEQCC_IMAGE_CACHE_MB`` (MiB) when set, else :data:`CACHE_BYTES`."""
    env = os.environ.get("O3D_SEQCC_IMAGE_CACHE_MB", "").strip()
    return int(float(env) * 2**20) if env else CACHE_BYTES


def _nbytes(value: Any) -> int:
    if isinstance(value, (tuple, list)):
        return sum(_nbytes(v) for v in value)
    return int(getattr(value, "nbytes", 0))


class LRUCache:
    """Thread-safe least-recently-used cache bounded by the total bytes of its values (arrays or
    tuples of arrays). Pickles empty (a copy sent to a Dask worker starts with no items).

    Parameters
    ----------
    budget : int
        Bytes; 0 caches nothing.
    """

    def __init__(self, budget: int) -> None:
        self.budget = int(budget)
        self._items: OrderedDict[Any, Any] = OrderedDict()
        self._bytes = 0
        self._lock = threading.Lock()
        self._making: dict[Any, threading.Event] = {}

    def get(self, key: Any, make: Callable[[], Any] | None = None) -> Any:
        """The cached value, else ``make()`` (stored when it fits), else None without ``make``.

        Threads asking for a key another thread is making wait for that value instead of making
        it again (a photo is decoded once when two report sections want it at the same time).
        """
        with self._lock:
            hit = self._items.get(key)
            if hit is not None:
                self._items.move_to_end(key)
                return hit
            if make is None:
                return None
            busy = self._making.get(key)
            if busy is None:
                self._making[key] = threading.Event()
        if busy is not None:
            busy.wait()
            with self._lock:
                hit = self._items.get(key)
            return hit if hit is not None else make()  # it did not fit, or its maker failed
        try:
            value = make()
            self[key] = value
            return value
        finally:
            with self._lock:
                self._making.pop(key).set()

    def __setitem__(self, key: Any, value: Any) -> None:
        size = _nbytes(value)
        if self.budget <= 0 or size > self.budget:
            return
        with self._lock:
            if key in self._items:
                return
            self._items[key] = value
            self._bytes += size
            while self._bytes > self.budget and self._items:
                _, old = self._items.popitem(last=False)
                self._bytes -= _nbytes(old)

    def __contains__(self, key: Any) -> bool:
        with self._lock:
            return key in self._items

    def __len__(self) -> int:
        return len(self._items)

    def __getstate__(self) -> dict:
        return {"budget": self.budget}

    def __setstate__(self, state: dict) -> None:
        self.__init__(state["budget"])


class ImageSequence(Sequence):
    """Read-only sequence of (H, W, 3) images produced on access (subclasses define ``_load``)."""

    def __len__(self) -> int:  # pragma: no cover - abstract
        raise NotImplementedError

    def _load(self, i: int) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    def __getitem__(self, i):
        if isinstance(i, slice):
            return [self[k] for k in range(*i.indices(len(self)))]
        n = len(self)
        k = int(i)
        if k < 0:
            k += n
        if not 0 <= k < n:
            raise IndexError(f"image index {i} out of range for {n} images")
        return self._load(k)

    def dtypes(self) -> list[np.dtype]:
        """The dtype of every image (subclasses avoid decoding when they can)."""
        return [np.asarray(self[i]).dtype for i in range(len(self))]

    def __repr__(self) -> str:
        return f"<{type(self).__name__}: {len(self)} images>"


class SceneImages(ImageSequence):
    """The views' images, read from their files on every access (no cache).

    Parameters
    ----------
    views : sequence of View
    """

    def __init__(self, views: Sequence) -> None:
        self.views = tuple(views)

    def __len__(self) -> int:
        return len(self.views)

    def _load(self, i: int) -> np.ndarray:
        return self.views[i].load_image()

    def dtypes(self) -> list[np.dtype]:
        """uint8 / uint16 per view, from the file headers (PNG, JPEG) or the in-memory pixels."""
        from ..io.images import image_dtype

        return [np.asarray(v.pixels).dtype if v.pixels is not None else image_dtype(v.image) for v in self.views]


class FloatImages(ImageSequence):
    """Another sequence's images as float64 in [0, 1], converted on access and LRU-cached.

    Parameters
    ----------
    images : sequence of (H, W, 3) uint8 / uint16 / float arrays
    cache_bytes : int, optional
        Budget of the cache (default :data:`CACHE_BYTES` or ``O3D_SEQCC_IMAGE_CACHE_MB``).
    """

    def __init__(self, images: Sequence, cache_bytes: int | None = None) -> None:
        self.images = images
        self.cache_bytes = default_cache_bytes() if cache_bytes is None else int(cache_bytes)
        self._cache = LRUCache(self.cache_bytes)

    def __len__(self) -> int:
        return len(self.images)

    def _load(self, i: int) -> np.ndarray:
        return self._cache.get(i, lambda: img_as_float(self.images[i]))

    def dtypes(self) -> list[np.dtype]:
        return [np.dtype(np.float64)] * len(self)



class CachedImages(ImageSequence):
    """Another sequence's images through a least-recently-used cache, which several sequences may share.

    For a consumer that reads the same images several times (the report: thumbnails, joint
    histograms, renders, the viewer's textures): each image is produced once while it fits.

    Parameters
    ----------
    images : sequence of (H, W, 3) arrays
    cache : LRUCache
    key : str
        Distinguishes this sequence's entries from the others' in a shared cache.
    """

    def __init__(self, images: Sequence, cache: LRUCache, key: str) -> None:
        self.images, self.cache, self.key = images, cache, key

    def __len__(self) -> int:
        return len(self.images)

    def _load(self, i: int) -> np.ndarray:
        return self.cache.get((self.key, i), lambda: self.images[i])

    def dtypes(self) -> list[np.dtype]:
        return image_dtypes(self.images)


def scene_photos(views: Sequence, cache_bytes: int | None = None) -> CachedImages:
    """The views' photos as a run reads them: decoded on first access, kept while they fit.

    A run reads every photo in several stages (colour samples, the selection's data costs,
    the bake, the report); decoding a 6 MP PNG takes 0.3-0.5 s, keeping it 18 MB. The photos
    (uint8 / uint16, as decoded) stay in one least-recently-used cache of ``cache_bytes``
    (default :func:`default_cache_bytes`: 512 MiB or ``O3D_SEQCC_IMAGE_CACHE_MB``); beyond it
    the least recently used are read again. Pickles as the views (a Dask worker reads the files
    itself, its copy of the cache empty).
    """
    budget = default_cache_bytes() if cache_bytes is None else int(cache_bytes)
    return CachedImages(SceneImages(views), LRUCache(budget), "photos")


def image_dtypes(images: Sequence) -> list[np.dtype]:
    """The dtype of every image of a list or an :class:`ImageSequence` (headers only for files)."""
    if isinstance(images, ImageSequence):
        return images.dtypes()
    return [np.asarray(im).dtype for im in images]
