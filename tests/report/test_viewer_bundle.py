"""The report's viewer bundle is what viewer/build.sh makes from viewer/package-lock.json (npm ci + esbuild)."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

VIEWER = Path(__file__).resolve().parents[2] / "viewer"


@pytest.mark.skipif(shutil.which("npm") is None, reason="npm is not installed (./dev.sh setup installs it)")
def test_the_shipped_bundle_is_what_the_build_script_produces():
    r = subprocess.run(["bash", str(VIEWER / "build.sh"), "--check"], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "viewer.min.js is what viewer/build.sh produces" in r.stdout


def test_the_lock_pins_the_viewers_packages():
    import json

    lock = json.loads((VIEWER / "package-lock.json").read_text())
    pkg = json.loads((VIEWER / "package.json").read_text())
    for name, version in pkg["devDependencies"].items():
        assert lock["packages"][f"node_modules/{name}"]["version"] == version  # exact versions, no ranges
        assert lock["packages"][f"node_modules/{name}"]["integrity"].startswith("sha512-")
