"""The Khronos glTF-Validator (npm package ``gltf-validator``), run with Node.js on a GLB file.

Not a dependency of the library: :func:`find_validator` says whether it is installed (``./dev.sh``
installs it into ``.cache/node``; ``GLTF_VALIDATOR_DIR`` names another folder holding
``node_modules/gltf-validator``), :func:`validate_glb` runs it.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import tempfile
from pathlib import Path

from ..errors import InputError

__all__ = ["find_validator", "validate_glb"]

_SCRIPT = """
const fs = require('fs');
const validator = require(process.argv[3] + '/node_modules/gltf-validator');
validator.validateBytes(new Uint8Array(fs.readFileSync(process.argv[2])), {maxIssues: 100}).then(
  (r) => console.log(JSON.stringify(r.issues)),
  (e) => { console.error(String(e)); process.exit(3); });
"""


def find_validator() -> tuple[str, Path] | None:
    """``(node executable, folder holding node_modules/gltf-validator)``, or None when either is missing.

    Looks in ``$GLTF_VALIDATOR_DIR``, the repository's ``.cache/node`` (``./dev.sh``), and npm's
    global root.
    """
    node = shutil.which("node")
    if node is None:
        return None
    cands = [os.environ.get("GLTF_VALIDATOR_DIR"), str(Path(__file__).resolve().parents[2] / ".cache" / "node")]
    npm = shutil.which("npm")
    if npm:
        try:
            root = subprocess.run([npm, "root", "-g"], capture_output=True, text=True, timeout=30).stdout.strip()
        except (subprocess.SubprocessError, OSError):
            root = ""
        if root:
            cands.append(str(Path(root).parent))
    for c in cands:
        if c and (Path(c) / "node_modules" / "gltf-validator" / "package.json").is_file():
            return node, Path(c).resolve()
    return None


def validate_glb(path: str | os.PathLike) -> dict:
    """The validator's issues for a GLB: ``numErrors``, ``numWarnings``, ``numInfos``, ``messages``.

    Raises
    ------
    InputError
        The validator is not installed (the message says how to install it), or it failed.
    """
    found = find_validator()
    if found is None:
        raise InputError("the Khronos glTF validator is not installed: `npm install --prefix DIR gltf-validator` and "
                         "set GLTF_VALIDATOR_DIR=DIR (./dev.sh setup does it)")
    node, vdir = found
    with tempfile.TemporaryDirectory() as tmp:
        script = Path(tmp) / "validate.js"
        script.write_text(_SCRIPT)
        r = subprocess.run([node, str(script), str(Path(path).resolve()), str(vdir)], capture_output=True, text=True,
                           timeout=300)
    if r.returncode != 0:
        raise InputError(f"the glTF validator failed on {path}: {r.stderr.strip()[:500]}")
    return json.loads(r.stdout)
