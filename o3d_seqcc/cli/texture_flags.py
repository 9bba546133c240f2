"""The texture, atlas and export flags (``texture``, ``run``, ``demo``), and the settings a command's flags
make: :class:`~o3d_seqcc.settings.RunSettings`, the export options, the checked texture job."""

from __future__ import annotations

import argparse
from dataclasses import fields
from pathlib import Path
from typing import Any

from ..io.export import EXPORT_UP_AXES, FORMATS, TEXTURE_FORMATS
from ..settings import RunSettings
from ..texturing import SELECTION_METHODS, TextureSettings
from ..texturing.settings import DATA_TERMS, FALLBACKS, OUTLIER_REMOVALS, OVERFLOWS, UV_MODES
from ..settings import keyword_defaults
from .scene_flags import prepare_out_dir, scene_from_args

_DEFAULTS = TextureSettings()
#: the defaults of the run options (``--no-seams``' is this field's)
_RUN = RunSettings()


def add_texture_arguments(p: argparse.ArgumentParser, *, outputs: bool = True) -> None:
    """Options of :class:`~o3d_seqcc.texturing.TextureSettings`, of the export, and (``outputs``) of the
    output folder (``texture`` and ``run``; ``demo`` without the output-folder options)."""
    d = _DEFAULTS
    if outputs:
        p.add_argument("--out", required=True, help="output folder (refused if it exists, unless --overwrite)")
        p.add_argument("--overwrite", action="store_true", help="write into an existing output folder")
        from ..pipeline import RunResult

        formats = ",".join(keyword_defaults(RunResult.save)["formats"])
        p.add_argument("--format", default=formats, help=f"comma-separated export formats among {', '.join(FORMATS)} "
                       f"(default {formats})")
    p.add_argument("--selection", default=d.selection, choices=sorted(SELECTION_METHODS),
                   help="per-face image selection: mrf (default: largest areas with few image transitions), "
                   "largest-area or random (the paper's two)")
    p.add_argument("--smoothness", type=float, default=d.smoothness,
                   help=f"mrf: Potts weight per interior edge (default {d.smoothness:g})")
    p.add_argument("--seed", type=int, default=d.seed,
                   help=f"seed of random selection / mrf order, and of the correction (default {d.seed})")
    p.add_argument("--data-term", default=d.data_term, choices=DATA_TERMS,
                   help=f"mrf: what makes a photo good for a face (default {d.data_term}: its gradient magnitude "
                   "integrated over the face's projection, large and sharp; area: the projected area alone)")
    p.add_argument("--outlier-removal", default=d.outlier_removal, choices=OUTLIER_REMOVALS,
                   help=f"per face, drop the photos whose colour of it is far from the others' (passers-by, cars the "
                   f"mesh lacks; default {d.outlier_removal}: far from the median of its photos; gauss-clamping / "
                   "gauss-damping: texrecon's Gaussian test)")
    add_atlas_arguments(p)
    p.add_argument("--no-leveling", dest="leveling", action="store_false",
                   help="skip global seam leveling (per-chart low-frequency colour offsets that cancel the colour "
                   "steps at chart seams; on by default)")
    p.add_argument("--leveling-smoothness", type=float, default=d.leveling_smoothness,
                   help=f"seam leveling: smoothness of the offsets inside charts (default {d.leveling_smoothness})")
    p.add_argument("--no-local-leveling", dest="local_leveling", action="store_false",
                   help="skip local seam leveling (the colour steps left along chart borders are blended away in a "
                   "strip of --local-band texels; on by default)")
    p.add_argument("--local-band", type=int, default=d.local_band,
                   help=f"local seam leveling: width of the blended strip in texels (default {d.local_band})")
    p.add_argument("--fallback", choices=FALLBACKS, default=d.fallback,
                   help="colour of faces seen by no view: smooth (default: vertex colours of the seen faces around, "
                   "interpolated) or flat (one colour per face)")
    p.add_argument("--selection-view", default=None,
                   help="view (name or index) from which OUT/selection.png is rendered (default: the view that sees "
                   "the most faces); 'none' to skip the picture")
    add_export_arguments(p)
    if outputs:
        p.add_argument("--no-seams", dest="seams", action="store_false", default=_RUN.seams,
                       help="skip the seam metric in report.json")


def add_atlas_arguments(p: argparse.ArgumentParser) -> None:
    """The atlas budget and layout options of :class:`~o3d_seqcc.texturing.TextureSettings` (``texture``, ``run``, ``demo``)."""
    d = _DEFAULTS
    p.add_argument("--uv", choices=UV_MODES, default=d.uv,
                   help="atlas (default): a new texture atlas of the charts; keep: bake into the mesh's own texture "
                   "coordinates (OBJ vt, PLY s/t, GLB TEXCOORD_0), the output keeping its topology and UVs")
    p.add_argument("--atlas-size", default=d.atlas_size, metavar="auto|N",
                   help=f"atlas side (default {d.atlas_size}: sized to the charts at the photos' resolution, pages of "
                   "up to 8192^2); N: the largest side in texels, a budget: the page is the smallest that holds the "
                   "charts at --texels-per-pixel within N x N")
    p.add_argument("--texels-per-pixel", default=d.texels_per_pixel, metavar="auto|T",
                   help="texel density, atlas texels per photo pixel (default auto: the photos' resolution, 1, each "
                   "texel a copy of a photo pixel; lowered only by an --atlas-size budget)")
    p.add_argument("--atlas-overflow", dest="overflow", choices=OVERFLOWS, default=d.overflow,
                   help="when the charts do not fit an --atlas-size budget at that density: scale the density down (default, "
                   "a warning gives the factor) or write several atlas pages (one material each)")
    p.add_argument("--power-of-two", dest="power_of_two", action=argparse.BooleanOptionalAction,
                   default=d.power_of_two,
                   help="square pages whose side is a power of two, for engines that want one (default: one page cut "
                   "to the charts, its sides multiples of 4 for block compression)")
    p.add_argument("--shrink-to-fit", type=float, default=d.shrink_to_fit, metavar="F",
                   help="with --power-of-two: accept a texel density up to this share lower (e.g. 0.05) to keep the "
                   "charts on the power of two below the one they need; reported in report.json (density_scale) and "
                   "warned (default 0: never)")
    p.add_argument("--padding", type=int, default=d.padding,
                   help=f"texels of gutter (the photo around the chart) between charts, mip-safe to level 2 at the "
                   f"default {d.padding}")
    p.add_argument("--small-charts", type=int, default=d.small_charts, metavar="N",
                   help=f"charts of at most N texels on their longer side share one block with --small-padding gutters "
                   f"(default {d.small_charts}; 0: every chart with --padding)")
    p.add_argument("--small-padding", type=int, default=d.small_padding,
                   help=f"texels of gutter between the small charts of that block (default {d.small_padding})")
    p.add_argument("--pack-effort", choices=("fast", "best"), default=d.pack_effort,
                   help="xatlas's placement search (default fast) or every candidate position (best: about 10 %% more "
                   "coverage on a fine mesh, the packing about 5x slower)")
    p.add_argument("--merge-charts", type=int, default=d.merge_charts,
                   help=f"charts of at most this many faces join a neighbouring chart's parametrisation where its view "
                   f"sees them (default {d.merge_charts}; 0: off)")


def add_export_arguments(p: argparse.ArgumentParser) -> None:
    """Up axis, texture format and quality, unlit material (defaults: :meth:`o3d_seqcc.pipeline.RunResult.save`'s)."""
    from ..pipeline import RunResult

    d = keyword_defaults(RunResult.save)
    p.add_argument("--up-axis", choices=EXPORT_UP_AXES, default=d["up_axis"],
                   help=f"up axis of the GLB/OBJ/PLY (default {d['up_axis']}: y, as glTF is Y-up, for a new atlas; "
                   "none with --uv keep): the scene's up direction, estimated from the cameras, is rotated onto it "
                   "(recorded in report.json; the MeshLab project keeps the scene's frame); none keeps the scene's "
                   "frame")
    p.add_argument("--texture-format", choices=tuple(TEXTURE_FORMATS), default=d["texture_format"],
                   help=f"texture images (default {d['texture_format']}; webp in the GLB needs EXT_texture_webp)")
    p.add_argument("--jpeg-quality", type=int, default=d["jpeg_quality"],
                   help=f"JPEG / WebP quality 1-100 (default {d['jpeg_quality']})")
    p.add_argument("--unlit", action="store_true", help="GLB material with KHR_materials_unlit")


def save_options_from_args(args: argparse.Namespace) -> dict[str, Any]:
    """The export options of :meth:`~o3d_seqcc.pipeline.RunResult.save` from the parsed arguments (validated)."""
    from ..pipeline import check_export_options

    check_export_options(up_axis=args.up_axis, texture_format=args.texture_format, jpeg_quality=args.jpeg_quality)
    return {"up_axis": args.up_axis, "texture_format": args.texture_format, "jpeg_quality": args.jpeg_quality,
            "unlit": args.unlit}


def texture_settings_from_args(args: argparse.Namespace) -> TextureSettings:
    """:class:`~o3d_seqcc.texturing.TextureSettings` from the parsed texture options."""
    return TextureSettings(**{f.name: getattr(args, f.name) for f in fields(TextureSettings) if hasattr(args, f.name)})


def run_options_from_args(args: argparse.Namespace, *, texture: bool = True) -> RunSettings:
    """:class:`~o3d_seqcc.settings.RunSettings` from the parsed options: every flag whose destination is a
    settings field (``--method`` -> ``correction.method``, ``--no-split-faces`` -> ``visibility.split_faces``,
    ``--no-seams`` -> ``seams``, ...); the texture options only with ``texture``."""
    names = [n for n in RunSettings.routes() if hasattr(args, n) and (texture or RunSettings.routes()[n] != ("texture",))]
    rs = RunSettings().replace(**{n: getattr(args, n) for n in names if n != "seed"})
    if hasattr(args, "seed"):  # run: the selection's seed seeds the correction too; correct: the correction's
        rs = rs.replace(seed=args.seed) if texture else rs.replace(correction=rs.correction.replace(seed=args.seed))
    return rs.replace(texture=texture_settings_from_args(args)) if texture else rs


def texture_job_from_args(args: argparse.Namespace) -> tuple[RunSettings, dict[str, Any], Any, Path]:
    """What ``run`` and ``texture`` check before any work: export formats and options, the run's
    settings, the scene, and ``--out`` against the scene's inputs.

    Returns
    -------
    (RunSettings, dict, Scene, Path)
        The settings, the keyword options of :meth:`~o3d_seqcc.pipeline.RunResult.save`, the
        loaded scene and the output folder.
    """
    from ..pipeline import parse_formats

    parse_formats(args.format)
    settings = run_options_from_args(args)
    save_options = save_options_from_args(args)
    scene = scene_from_args(args)
    return settings, save_options, scene, prepare_out_dir(args, scene)
