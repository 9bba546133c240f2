"""Exceptions raised by o3d_seqcc."""

from __future__ import annotations

import importlib
import importlib.util
import warnings
from types import ModuleType

__all__ = ["InputError", "MissingImagesError", "O3dSeqccWarning", "require", "warn"]


class InputError(ValueError):
    """Bad user input: a missing or malformed file, an inconsistent scene, an invalid option.

    The message always names the offending file or view and says how to fix it.
    """


class MissingImagesError(InputError):
    """Photos a scene names that are missing or unreadable, every one of them in one error.

    Built by :func:`o3d_seqcc.io.missing.missing_images`; ``load_scene(skip_missing=True)``
    (``--skip-missing-images``) goes on with :attr:`scene`.

    Attributes
    ----------
    missing : tuple of o3d_seqcc.io.missing.MissingImage
        View name, image path, what is wrong and (where known) the file and line naming it.
    scene : Scene or None
        The scene without those views (None when none would be left).
    total : int
        Photos the scene names, the missing ones included.
    where : str
        The scene file or folder.
    """

    def __init__(self, message: str, *, missing: tuple = (), scene: object = None, total: int = 0,
                 where: str = "") -> None:
        super().__init__(message)
        self.missing, self.scene, self.total, self.where = tuple(missing), scene, int(total), where

    def __reduce__(self):  # the attributes survive pickling (a worker process raising it)
        return (_rebuild_missing, (self.args[0], self.missing, self.scene, self.total, self.where))


def _rebuild_missing(message: str, missing: tuple, scene: object, total: int, where: str) -> MissingImagesError:
    return MissingImagesError(message, missing=missing, scene=scene, total=total, where=where)


class O3dSeqccWarning(UserWarning):
    """A result that works but is worse than it could be (views left uncorrected, depth that disagrees, ...)."""


def warn(message: str, *, stacklevel: int = 3) -> None:
    """Emit an :class:`O3dSeqccWarning` once (the command line routes warnings to its log, so it is shown once)."""
    warnings.warn(message, O3dSeqccWarning, stacklevel=stacklevel)


def require(module: str, *, extra: str, what: str) -> ModuleType:
    """Import an optional dependency, or raise :class:`InputError` naming the extra that installs it.

    Parameters
    ----------
    module : str
        The module to import (e.g. ``"distributed"``, ``"pymeshlab"``).
    extra : str
        The package extra that installs it (``pip install 'o3d-seqcc[EXTRA]'``).
    what : str
        What needs it, for the message ("--scheduler (a Dask cluster)").
    """
    top = module.split(".")[0]
    if importlib.util.find_spec(top) is None:
        raise InputError(f"{what} needs {top}, which is not installed: pip install 'o3d-seqcc[{extra}]' (or "
                         f"'o3d-seqcc[all]'; from a checkout, ./dev.sh setup installs every extra)")
    return importlib.import_module(module)
