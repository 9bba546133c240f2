"""Exceptions raised by o3d_seqcc."""

from __future__ import annotations

import warnings

__all__ = ["InputError", "O3dSeqccWarning", "warn"]


class InputError(ValueError):
    """Bad user input: a missing or malformed file, an inconsistent scene, an invalid option.

    The message always names the offending file or view and says how to fix it.
    """


class O3dSeqccWarning(UserWarning):
    """A result that works but is worse than it could be (views left uncorrected, depth that disagrees, ...)."""


def warn(message: str, *, stacklevel: int = 3) -> None:
    """Emit an :class:`O3dSeqccWarning` once (the command line routes warnings to its log, so it is shown once)."""
    warnings.warn(message, O3dSeqccWarning, stacklevel=stacklevel)
