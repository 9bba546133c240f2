"""The public API: every name in __all__ resolves, unknown names fail, registries reject unknowns."""

from __future__ import annotations

import importlib

import pytest

import o3d_seqcc


def test_every_public_name_resolves():
    for name in o3d_seqcc.__all__:
        assert getattr(o3d_seqcc, name) is not None, name


def test_unknown_attribute():
    with pytest.raises(AttributeError, match="no attribute 'nope'"):
        o3d_seqcc.nope  # noqa: B018


def test_lazy_names_are_the_module_objects():
    assert o3d_seqcc.correct is importlib.import_module("o3d_seqcc.correction").correct
    assert o3d_seqcc.compute_mappings is importlib.import_module("o3d_seqcc.mappings").compute_mappings
    tex = importlib.import_module("o3d_seqcc.texturing")
    assert tex.bake_texture is importlib.import_module("o3d_seqcc.texturing.atlas").bake_texture
    assert set(tex.__all__) <= set(dir(tex)) and all(getattr(tex, n) is not None for n in tex.__all__)


def test_correction_registry_lists_the_papers_table_1():
    names = set(o3d_seqcc.available_methods())
    assert {"none", "reinhard", "root-polynomial", "vandermonde", "gain-compensation", "histogram-matching", "seqcc"} <= names


def test_cli_lists_every_command():
    from o3d_seqcc.cli import COMMANDS, build_parser

    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    assert set(COMMANDS) == set(sub.choices)
    assert {"info", "demo", "synthetic", "mappings", "correct", "evaluate", "texture", "run", "seams"} <= set(COMMANDS)
