"""Photos a scene names that cannot be read: found all at once, listed in one error.

Every scene reader and :meth:`Scene.validate <o3d_seqcc.scene.Scene.validate>` checks each photo's
header with :func:`check_photo` and keeps going past the ones that are missing or unreadable
(missing, not a regular file, permission denied, truncated, not an image, grey-scale, alpha
channel, over the pixel budget), collecting them as :class:`MissingImage`. At the end
:func:`missing_images` makes the one :class:`~o3d_seqcc.errors.MissingImagesError` that lists
them all: view names, paths, the file and line that name them where the format has lines, and a
near namesake beside a missing file (:func:`near_miss`). The error carries the scene without
them, which ``load_scene(skip_missing=True)`` (``--skip-missing-images``) goes on with.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

from ..errors import InputError, MissingImagesError
from .images import check_image_file

__all__ = ["MissingImage", "check_photo", "missing_images", "near_miss"]

#: what the messages say to go on without the photos
SKIP_HINT = "skip_missing=True in load_scene (--skip-missing-images)"


@dataclass(frozen=True)
class MissingImage:
    """A photo of a scene that cannot be read.

    Attributes
    ----------
    view : str
        The view's name.
    path : pathlib.Path
        The image file looked for.
    problem : str
        What is wrong (the file layer's message, with a near namesake's name for a missing file).
    where : str
        The file and line that name the photo (``"list.txt: line 3"``), or ``""``.
    """

    view: str
    path: Path
    problem: str
    where: str = ""

    def line(self) -> str:
        """One line of the error's list."""
        return f"view {self.view!r}: " + (f"{self.where}: " if self.where else "") + self.problem


def near_miss(path: Path) -> str:
    """``"; found NAME beside it: did you mean it?"`` for a missing file with a near namesake, else ``""``.

    A near namesake is a file in the same folder whose name differs only in case or in the
    extension (``img00.jpg`` for ``img00.png``, as COLMAP models written before a conversion
    name them); a missing folder is said as such.
    """
    folder = Path(path).parent
    if not folder.is_dir():
        return f"; the folder {folder} does not exist"
    name, stem = Path(path).name.lower(), Path(path).stem.lower()
    try:
        entries = [e for e in os.scandir(folder) if e.is_file()]
    except OSError:
        return ""
    same = [e.name for e in entries if e.name.lower() == name]
    other = sorted(e.name for e in entries if Path(e.name).stem.lower() == stem and e.name.lower() != name)
    found = same or other
    if not found:
        return ""
    return f"; found {found[0]} beside it: did you mean it?"


def check_photo(view: str, path: str | os.PathLike, *, where: str = "") -> tuple[int, int] | MissingImage:
    """The size of a photo from its header (:func:`~o3d_seqcc.io.images.check_image_file`), or what is wrong with it.

    Parameters
    ----------
    view : str
        The view's name (for the list).
    path : path-like
        The image file.
    where : str, default ""
        The file and line naming it, for the list.

    Returns
    -------
    (width, height) or MissingImage
    """
    p = Path(path)
    try:
        w, h, _mode = check_image_file(p)
    except InputError as e:
        try:
            hint = near_miss(p) if not p.is_file() else ""
        except (OSError, ValueError):  # a name too long for the file system
            hint = ""
        return MissingImage(view, p, f"{e}{hint}", where)
    return w, h


def missing_images(missing: list[MissingImage] | tuple[MissingImage, ...], *, total: int, where: str = "",
                   hint: str = "", scene: object = None) -> MissingImagesError:
    """The error listing every photo of ``missing`` (to raise).

    Parameters
    ----------
    missing : sequence of MissingImage
        At least one.
    total : int
        Photos the scene names, the missing ones included.
    where : str, default ""
        The scene file or folder, first in the message.
    hint : str, default ""
        The format's own way to find the photos (``"pass image_dir= (--image-dir DIR) if the images are
        elsewhere"``), said before the skip option.
    scene : Scene, optional
        The scene without the missing views (None when none is left: then skipping cannot help, and the
        message says so).
    """
    n = len(missing)
    head = f"{where}: " if where else ""
    fix = "; ".join(x for x in ("fix their paths", hint) if x)
    if scene is None:
        text = (f"{head}none of the {total} photos can be read:\n" + "".join(f"  {m.line()}\n" for m in missing)
                + f"{fix} (without photos there is nothing to colour the mesh with)")
    else:
        text = (f"{head}{n} of {total} photos are missing or unreadable:\n"
                + "".join(f"  {m.line()}\n" for m in missing)
                + f"{fix}, or pass {SKIP_HINT} to go on without {'it' if n == 1 else f'these {n} photos'}")
    return MissingImagesError(text, missing=tuple(missing), scene=scene, total=total, where=where)
