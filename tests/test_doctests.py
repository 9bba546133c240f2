"""The Examples sections of the public functions' docstrings run as doctests (issue 38).

Every module of the package whose source holds a ``>>>`` example is imported and its examples run, one test per
docstring; an example that no longer gives what it shows fails here.
"""

from __future__ import annotations

import doctest
import importlib
import tempfile
from pathlib import Path

import pytest

PKG = Path(__file__).resolve().parents[1] / "o3d_seqcc"
FLAGS = doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE


def _modules() -> list[str]:
    out = []
    for p in sorted(PKG.rglob("*.py")):
        if ">>> " in p.read_text(encoding="utf-8"):
            rel = p.relative_to(PKG.parent).with_suffix("")
            out.append(".".join(rel.parts[:-1] if rel.name == "__init__" else rel.parts))
    return out


def _doctests() -> list:
    tests = []
    for name in _modules():
        tests += [t for t in doctest.DocTestFinder(exclude_empty=True).find(importlib.import_module(name))
                  if t.examples and t.name.startswith(name)]  # defined here, not imported
    return sorted(tests, key=lambda t: t.name)


DOCTESTS = _doctests()


def test_the_public_functions_have_examples():
    names = {t.name.rsplit(".", 1)[-1] for t in DOCTESTS}
    assert len(names) >= 19 and {"load_scene", "compute_visibility", "correct", "bake_texture", "run"} <= names


@pytest.mark.parametrize("test", DOCTESTS, ids=[t.name.removeprefix("o3d_seqcc.") for t in DOCTESTS])
def test_example(test, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))  # the examples' tempfile.mkdtemp() folders go here
    runner = doctest.DocTestRunner(optionflags=FLAGS)
    runner.run(test)
    assert runner.failures == 0, f"{test.name}: {runner.failures} of {runner.tries} examples failed (output above)"
