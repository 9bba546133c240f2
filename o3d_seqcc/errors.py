"""Exceptions raised by o3d_seqcc."""

from __future__ import annotations

import importlib
import importlib.util
import warnings
from types import ModuleType

__all__ = ["InputError", "O3dSeqccWarning", "require", "warn"]


class InputError(ValueError):
    """Bad user input: a missing or malformed file, an inconsistent scene, an invalid option.

    The message always names the offending file or view and says how to fix it.
    """


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
