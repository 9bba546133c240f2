"""Time ``o3d_seqcc.correction.correct`` on fountain (16k-face mesh, 33 views), end to end.

Prints the best-of-``--repeat`` wall time of the default method (``seqcc-global``) and of the
paper's ``seqcc`` (mappings computed inside ``correct``), their stages, and the ratio to a peer
run in the same process (``method="none"``: same image loading, mappings and graph, no
fitting), so the cost of the fitting itself stands out on a noisy shared machine.

    .venv/bin/python benchmarks/correct_timing.py [--repeat 3] [--mappings vertices|dense]
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))  # this checkout's package, not whichever one is installed
FOUNTAIN = REPO.parent / "shared" / "datasets" / "fountain_small"
METHODS = ("none", "seqcc", "seqcc-global")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--mappings", choices=("vertices", "dense"), default="vertices")
    args = ap.parse_args()
    if not (FOUNTAIN / "scene" / "key.log").is_file():
        print(f"fountain data not found at {FOUNTAIN}; nothing to time")
        return 0
    warnings.simplefilter("ignore")
    t0 = time.perf_counter()
    import sklearn.isotonic  # noqa: F401  (imports are not what we time)
    import sklearn.svm  # noqa: F401

    from o3d_seqcc import load_scene
    from o3d_seqcc.correction import correct

    print(f"imports {time.perf_counter() - t0:.2f} s")
    scene = load_scene(FOUNTAIN, mesh="scene/mesh_decimated_uv_blender.ply")
    best: dict[str, float] = {}
    stages: dict[str, dict] = {}
    for _ in range(args.repeat):
        for method in METHODS:
            t = time.perf_counter()
            res = correct(scene, reference="auto", method=method, mappings=args.mappings)
            dt = time.perf_counter() - t
            if dt < best.get(method, float("inf")):
                best[method] = dt
                stages[method] = {k: round(v, 3) for k, v in res.timings.items()}
    for method in METHODS[1:]:
        print(f"correct(method={method!r}, mappings={args.mappings!r}) end to end: best of {args.repeat} {best[method]:.2f} s")
        print(f"  stages: {stages[method]}")
        print(f"  ratio to the peer method='none' ({best['none']:.2f} s): {best[method] / best['none']:.2f}")
    print("target: <= 3 s end to end (issues 4 and 12)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
