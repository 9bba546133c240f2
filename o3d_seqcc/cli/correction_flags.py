"""The colour-correction flags (``correct``, ``run``, ``evaluate``): reference, method, ``--t-npm``, mapping
mode, face splitting; their defaults are the settings objects' fields."""

from __future__ import annotations

import argparse

from ..correction import available_methods
from ..mappings.compute import MODES
from ..settings import CorrectionSettings, VisibilitySettings

#: the defaults of the correction and visibility options (the flags' defaults are these fields')
_CORRECTION, _VISIBILITY = CorrectionSettings(), VisibilitySettings()


def add_correction_arguments(p: argparse.ArgumentParser) -> None:
    """Reference, method, t_npm and mapping mode (``correct`` and ``run``; defaults: :class:`CorrectionSettings`'s)."""
    d = _CORRECTION
    p.add_argument("--reference", default=d.reference,
                   help=f"reference view name (or index), or 'auto' (default {d.reference}: the view with the smallest "
                   "total path cost in the colour-correction graph)")
    p.add_argument("--method", default=d.method, choices=available_methods(), metavar="METHOD",
                   help=f"colour-correction method: {', '.join(available_methods())} (default {d.method}; "
                   "seqcc is the paper's)")
    add_t_npm_argument(p, d.t_npm)
    p.add_argument("--mappings", choices=MODES, default=d.mappings,
                   help=f"pairwise mappings (default {d.mappings}: the shared faces' vertices and points inside "
                   "the large ones at the photos' resolution, pairs counted in pixels of shared surface; vertices: "
                   "the paper's face vertices, counted; dense: vertices and interior points, counted)")


def add_split_argument(p: argparse.ArgumentParser) -> None:
    """``--no-split-faces`` (:attr:`VisibilitySettings.split_faces`, on by default)."""
    p.add_argument("--no-split-faces", dest="split_faces", action="store_false", default=_VISIBILITY.split_faces,
                   help="keep the mesh's faces as they are: by default a face no photo holds whole (clipped by the "
                   "image border, partly hidden, larger than a photo, or seen so deep its texture would slide) is "
                   "split into parts the photos that see them can texture")


def t_npm_value(text: str) -> int | str:
    """``--t-npm``'s value: ``"auto"`` or a positive integer (argparse type)."""
    if text.strip().lower() == "auto":
        return "auto"
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"give 'auto' or a positive integer, not {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"give 'auto' or a positive integer, not {text!r}")
    return value


def add_t_npm_argument(p: argparse.ArgumentParser, default: int | str | None = None, *, extra: str = "") -> None:
    """``--t-npm auto|N`` (:func:`o3d_seqcc.correction.graph.resolve_t_npm`), default :attr:`CorrectionSettings.t_npm`."""
    default = _CORRECTION.t_npm if default is None else default
    p.add_argument("--t-npm", type=t_npm_value, default=default, metavar="auto|N",
                   help=f"minimum pair count for a colour-correction graph edge (default {default}): pixels of "
                   "shared surface with --mappings surface (auto: 1%% of the median photo's pixels), vertex "
                   f"mappings with vertices / dense (auto: the paper's 400){extra}")
