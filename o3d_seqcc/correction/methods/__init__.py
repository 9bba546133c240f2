"""The correction methods (Table 1 and beyond), one module per published method or family, and their table.

- :mod:`~o3d_seqcc.correction.methods.seqcc`: ``seqcc`` (the paper's), ``seqcc-joint``;
- :mod:`~o3d_seqcc.correction.methods.seqcc_global`: ``seqcc-global`` (the default);
- :mod:`~o3d_seqcc.correction.methods.edge_summaries`, :mod:`~o3d_seqcc.correction.methods.joint_curves`:
  its parts (every edge as matched quantiles; per-view curves over all edges);
- :mod:`~o3d_seqcc.correction.methods.pairwise`: ``none``, ``reinhard``, ``root-polynomial``, ``vandermonde``;
- :mod:`~o3d_seqcc.correction.methods.global_methods`: ``gain-compensation``, ``histogram-matching``.

:data:`METHODS` is written out below (name -> function): no method module registers itself when
imported. Users add theirs with :func:`register_method`.
"""

from __future__ import annotations

from typing import Callable

from ..._shared.registry import Registry
from .global_methods import gain_compensation, histogram_matching
from .pairwise import _method_none, _method_reinhard, _method_root_polynomial, _method_vandermonde
from .seqcc import _method_seqcc, _method_seqcc_joint
from .seqcc_global import method_seqcc_global

__all__ = ["METHODS", "available_methods", "register_method"]

#: name -> ``fn(ctx, **options) -> list[Transform]``; an entry's ``needs_graph`` (:meth:`Registry.info`, default
#: True) makes :func:`~o3d_seqcc.correction.correct` insist on a usable graph (an edge, a reference with one)
METHODS: Registry[Callable] = Registry("correction method", {
    "none": _method_none,
    "vandermonde": _method_vandermonde,
    "reinhard": _method_reinhard,
    "root-polynomial": _method_root_polynomial,
    "seqcc": _method_seqcc,
    "seqcc-joint": _method_seqcc_joint,
    "seqcc-global": method_seqcc_global,
    "gain-compensation": gain_compensation,
    "histogram-matching": histogram_matching,
}, info={"none": {"needs_graph": False}})


def register_method(name: str, *, needs_graph: bool = True) -> Callable[[Callable], Callable]:
    """Decorator registering a correction method ``fn(ctx, **options) -> list[Transform]`` under ``name``.

    Parameters
    ----------
    name : str
        Name used with ``correct(..., method=name)``.
    needs_graph : bool, default True
        When True, :func:`~o3d_seqcc.correction.correct` insists on a usable graph (at least one
        edge, a reference with an edge) and raises :class:`~o3d_seqcc.errors.InputError` otherwise.
    """
    return METHODS.register(name, needs_graph=bool(needs_graph))


def available_methods() -> list[str]:
    """Sorted names of the registered correction methods.

    Examples
    --------
    >>> import o3d_seqcc as sc
    >>> 'seqcc' in sc.available_methods() and sc.DEFAULT_METHOD in sc.available_methods()
    True
    """
    return METHODS.names()
