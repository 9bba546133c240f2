"""The options of :func:`~o3d_seqcc.correction.correct`, where their defaults live.

:func:`~o3d_seqcc.correction.correct`, :func:`o3d_seqcc.pipeline.run` / ``correct_scene``
(through :class:`~o3d_seqcc.settings.RunSettings`), :func:`o3d_seqcc.correct_images`, the
pymeshlab filters, the MeshLab plugin and the ``run`` / ``correct`` commands all read them from
:class:`CorrectionSettings`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._shared.options import SettingsBase, check_choice, check_types
from ..errors import InputError
from ..imaging.arrays import INTERPOLATIONS
from ..mappings.compute import DEFAULT_MODE, MODES
from .base import DEFAULT_METHOD
from .graph import WEIGHTS, check_t_npm
from .methods import METHODS

__all__ = ["CorrectionSettings"]


@dataclass(frozen=True)
class CorrectionSettings(SettingsBase):
    """Options of the colour correction: reference, method, graph and mappings (paper 3.3-3.7).

    Attributes
    ----------
    reference : str or int, default "auto"
        Reference view (name or index), or ``"auto"``: the view with the smallest total path cost
        in the colour-correction graph (:func:`o3d_seqcc.correction.graph.choose_reference`).
    method : str, default :data:`~o3d_seqcc.correction.DEFAULT_METHOD` ("seqcc-global")
        Colour-correction method, a name of :data:`o3d_seqcc.correction.METHODS` ("seqcc" is the
        paper's; "seqcc-global" refines it jointly over every graph edge).
    t_npm : "auto" or int >= 1, default "auto"
        Minimum pair count for a graph edge (:func:`o3d_seqcc.correction.graph.resolve_t_npm`):
        with surface mappings pixels of shared surface (``"auto"``: 1 % of the median photo's
        pixels), with vertex and dense mappings vertex mappings (``"auto"``: the paper's 400).
    mappings : {"surface", "vertices", "dense"}, default :data:`~o3d_seqcc.mappings.DEFAULT_MODE` ("surface")
        Pairwise mapping mode (:func:`o3d_seqcc.mappings.compute_mappings`): ``"surface"``, the
        shared faces' vertices and points inside the large ones at the photos' resolution, pairs
        counted in pixels of shared surface; ``"vertices"``, the paper's face vertices, counted;
        ``"dense"``, vertices and interior points, counted.
    seed : int, default 0
        Seed of any randomness in the correction method (runs are deterministic for a seed).
    interpolation : {"bilinear", "nearest"}, default "bilinear"
        Colour sampling at the mappings.
    graph_weight : {"paper", "log"}, default "paper"
        Edge weight formula of the colour-correction graph: ``1 - n / total`` (the paper's) or
        ``log(total / n)`` (prefers strong edges).
    method_options : dict, default {}
        Options of the method (e.g. seqcc: ``cmf="csvr"``, ``cmf_options={...}``, ``bits``);
        names the method does not take raise ``TypeError`` listing the ones it does.
    """

    _label = "correction setting"

    reference: str | int = "auto"
    method: str = DEFAULT_METHOD
    t_npm: int | str = "auto"
    mappings: str = DEFAULT_MODE
    seed: int = 0
    interpolation: str = "bilinear"
    graph_weight: str = "paper"
    method_options: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        METHODS.check(self.method)
        check_t_npm(self.t_npm)
        check_choice("mappings mode", self.mappings, MODES, flag="--mappings")
        check_choice("interpolation", self.interpolation, INTERPOLATIONS)
        check_choice("graph_weight", self.graph_weight, WEIGHTS, flag="--graph-weight")
        ref = self.reference
        if isinstance(ref, (bool, np.bool_)) or not isinstance(ref, (str, int, np.integer)):
            raise InputError(f"reference must be a view name, a view index or 'auto', got {ref!r:.60}")
        check_types(self)
        if not isinstance(self.method_options, dict):
            raise InputError(f"method_options must be a dict of the method's options, got "
                             f"{type(self.method_options).__name__}")
        object.__setattr__(self, "method_options", dict(self.method_options))
        METHODS.check_options(self.method, self.method_options)

    def to_dict(self) -> dict[str, Any]:
        out = super().to_dict()
        out["method_options"] = dict(self.method_options)
        return out
