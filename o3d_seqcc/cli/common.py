"""Options shared by several commands; their defaults come from the library, never from here."""

from __future__ import annotations

import argparse
from dataclasses import fields
from pathlib import Path
from typing import Any

from ..correction import available_methods
from ..errors import InputError
from ..io.export import EXPORT_UP_AXES, FORMATS, TEXTURE_FORMATS
from ..io.load import load_scene
from ..io.output import check_output, check_output_file
from ..mappings.compute import MODES
from ..scene import DEPTH_SCALE_RANGE
from ..settings import CorrectionSettings, RunSettings, VisibilitySettings
from ..texturing import SELECTION_METHODS, TextureSettings
from ..texturing.settings import DATA_TERMS, FALLBACKS, OUTLIER_REMOVALS, OVERFLOWS, UV_MODES
from .console import add_progress_argument, progress_from_args
from .parser import library_default

__all__ = [
    "add_atlas_arguments",
    "add_correction_arguments",
    "add_export_arguments",
    "add_progress_argument",
    "add_scene_arguments",
    "add_split_argument",
    "add_t_npm_argument",
    "add_texture_arguments",
    "library_default",
    "prepare_out_dir",
    "print_report_path",
    "print_run_summary",
    "progress_from_args",
    "run_options_from_args",
    "save_options_from_args",
    "scene_from_args",
    "scene_options_from_args",
    "texture_settings_from_args",
]

_DEFAULTS = TextureSettings()
#: the defaults of the correction, visibility and run options (the flags' defaults are these fields')
_CORRECTION, _VISIBILITY, _RUN = CorrectionSettings(), VisibilitySettings(), RunSettings()


def add_scene_arguments(p: argparse.ArgumentParser) -> None:
    """The scene argument and the loader options every command shares."""
    from ..io.load import AXES, EXTRINSIC_CONVENTIONS
    from ..visibility.camera_checks import MIN_AREA_SEEN

    p.add_argument("scene", help="scene.json (or its folder), a MeshLab .mlp, Meshroom cameras.sfm, an Open3D RGB-D "
                   "folder, a COLMAP model folder (text or binary), or an OpenMVS scene.mvs")
    p.add_argument("--mesh", help="mesh file (required for RGB-D folders, COLMAP and Meshroom; overrides the others')")
    p.add_argument("--image-dir", help="folder of the images (COLMAP, Meshroom, OpenMVS), instead of where the scene "
                   "file says")
    p.add_argument("--depth-dir", help="folder of depth maps named after the views, for scenes without depth (MeshLab "
                   "projects, COLMAP, Meshroom): turns the depth-consistency filter on")
    depth_scale = library_default(load_scene)["depth_scale"]
    p.add_argument("--depth-scale", type=float, default=depth_scale,
                   help=f"depth units per metre of the --depth-dir maps (default {depth_scale:g}: millimetres)")
    p.add_argument("--extrinsic", choices=EXTRINSIC_CONVENTIONS, default=None,
                   help="what the scene's pose matrices map (scene.json, COLMAP, RGB-D folders), when not the format's "
                   "own (scene.json and COLMAP world-to-camera, key.log camera-to-world); default: the format's, "
                   "checked against the mesh")
    p.add_argument("--axes", choices=AXES, default=None,
                   help="the scene's camera axes: opencv (y down, looking down +z; every format's own) or opengl (y up, "
                   "looking down -z); default opencv, checked against the mesh")
    p.add_argument("--intrinsic", metavar="FILE",
                   help="RGB-D folders: the colour camera's intrinsic, Open3D's PinholeCameraIntrinsic JSON (default "
                   "PrimeSense, for 640x480 images only)")
    p.add_argument("--masks", metavar="DIR",
                   help="folder of per-photo masks (PNG/JPG/TIF of the photo's size, named after the image or the view: "
                   "<stem>.png, ...; Meshroom's <viewId>.png, OpenMVS's <stem>.mask.png): nonzero = keep, 0 = masked "
                   "out; masked pixels colour nothing (visibility, mappings, view selection, bake)")
    p.add_argument("--mask-invert", action="store_true",
                   help="the masks' other convention: nonzero = masked out (for --masks and the masks the scene names)")
    p.add_argument("--no-camera-check", dest="camera_check", action="store_false",
                   help="skip the check of the cameras against the mesh (camera-to-world, OpenGL axes, other units)")
    p.add_argument("--skip-missing-images", dest="skip_missing", action="store_true",
                   help="go on without the photos that are missing or unreadable (one warning names them; report.json "
                   "lists them under scene_options.skipped_images); by default they are an error listing them all")
    p.add_argument("--allow-unseen", dest="allow_unseen", action="store_true",
                   help=f"go on (with a warning) when the cameras see less than {100 * MIN_AREA_SEEN:g}%% of the mesh; "
                   "by default an error (a mesh from another scene, other units or camera conventions)")


def scene_options_from_args(args: argparse.Namespace) -> dict[str, Any]:
    """The keyword options of :func:`~o3d_seqcc.load_scene` given on the command line (validated)."""
    lo, hi = DEPTH_SCALE_RANGE
    if not lo <= args.depth_scale <= hi:  # NaN, inf and denormals too
        raise InputError(f"--depth-scale must be between {lo:g} and {hi:g} depth units per metre (1000: millimetres, "
                         f"1: metres), got {args.depth_scale!r}")
    return {"mesh": args.mesh, "image_dir": args.image_dir, "depth_dir": args.depth_dir,
            "depth_scale": args.depth_scale, "extrinsic": args.extrinsic, "axes": args.axes,
            "intrinsic": args.intrinsic, "check_cameras": args.camera_check, "masks": args.masks,
            "mask_invert": args.mask_invert, "skip_missing": args.skip_missing,
            "allow_unseen": args.allow_unseen}


def scene_from_args(args: argparse.Namespace):
    """The scene named on the command line (validated, cameras checked)."""
    return load_scene(args.scene, **scene_options_from_args(args))


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


def add_texture_arguments(p: argparse.ArgumentParser, *, outputs: bool = True) -> None:
    """Options of :class:`~o3d_seqcc.texturing.TextureSettings`, of the export, and (``outputs``) of the
    output folder (``texture`` and ``run``; ``demo`` without the output-folder options)."""
    d = _DEFAULTS
    if outputs:
        p.add_argument("--out", required=True, help="output folder (refused if it exists, unless --overwrite)")
        p.add_argument("--overwrite", action="store_true", help="write into an existing output folder")
        from ..pipeline import RunResult

        formats = ",".join(library_default(RunResult.save)["formats"])
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

    d = library_default(RunResult.save)
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


def prepare_out_dir(args: argparse.Namespace, scene) -> Path:
    """Check ``--out`` against the scene's inputs before any work (:func:`o3d_seqcc.io.output.check_output`)."""
    check_output(args.out, overwrite=args.overwrite, inputs=scene.input_paths())
    return Path(args.out)


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


def refuse_input_overwrite(path: str | Path, inputs: Any, option: str) -> None:
    """Check an output file path before any work (:func:`o3d_seqcc.io.output.check_output_file`): never one
    of the inputs (links resolved), a folder, a FIFO or device, or a file of an o3d-seqcc output folder.

    Raises
    ------
    InputError
        The message names ``option`` and what ``path`` is.
    """
    check_output_file(path, option=option, inputs=inputs)


def print_run_summary(res, out: Path) -> None:
    """Print what a :class:`~o3d_seqcc.pipeline.RunResult` did (correction, texturing, seams, timings)."""
    names, s, tm = res.scene.names, res.selection_stats, res.textured
    if res.correction is not None:
        c = res.correction
        print(f"corrected {len(names)} views with {c.method} toward {names[c.reference]} ({len(c.unreachable)} unreachable)")
    st = tm.stats
    pages = f"{tm.pages} pages of " if tm.pages > 1 else ""
    mem = st.get("texture_memory") or {}
    if s.get("split_input_faces"):
        split = (f"textured {s['input_faces']} faces ({s['split_input_faces']} split into parts: {s['faces']} out; "
                 f"{s['unseen_input_faces']} unseen, {s['partly_seen_input_faces']} partly: "
                 f"{100 * s['unseen_area']:.1f}% of the surface, ")
    else:
        split = (f"textured {s['faces']} faces ({s['unseen_faces']} unseen: {100 * s.get('unseen_area', 0.0):.1f}% of "
                 "the surface, ")
    print(split + f"{s['transitions']} image transitions, "
          f"{st['charts']} charts, atlas {pages}{tm.page_shape[1]}x{tm.page_shape[0]} at "
          f"{st.get('texels_per_pixel', 1.0):.2f} texels/pixel, {100 * st.get('coverage', 0.0):.0f}% covered) in "
          f"{res.timings['total']:.2f} s -> {out}")
    if mem:
        print(f"texture memory: {mem['gpu_bytes'] / 2**20:.1f} MiB on the GPU (RGBA8 with mipmaps, "
              f"{len(mem['pages'])} page(s))")
    if res.seams is not None:
        print(f"seams: mean {res.seams.mean:.2f}, p99 {res.seams.p99:.2f}, >5: {res.seams.frac_above_5:.3f}")
    print("timings (s): " + ", ".join(f"{k} {v:.2f}" for k, v in res.timings.items()))
    print_report_path(out)


def print_report_path(out: Path) -> None:
    """Print the path of the HTML report of an output folder (the last line of run, texture, correct)."""
    report = Path(out) / "report.html"
    if report.is_file():
        print(f"report: {report}")
