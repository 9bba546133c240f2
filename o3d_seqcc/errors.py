"""Exceptions raised by o3d_seqcc."""

from __future__ import annotations

__all__ = ["InputError"]


class InputError(ValueError):
    """Bad user input: a missing or malformed file, an inconsistent scene, an invalid option.

    The message always names the offending file or view and says how to fix it.
    """
