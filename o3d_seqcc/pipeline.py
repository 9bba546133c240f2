"""The whole job as library calls, with the command line's defaults (mvs-texturing's ``texrecon``).

- :func:`run`: visibility -> mappings -> colour correction -> view selection -> atlas -> seam
  metric, one visibility computation serving both the correction and the texturing;
- :func:`texture`: the texturing half alone, on the scene's (or given) images;
- :func:`correct_scene`: the correction half alone, with the report the ``correct`` command writes.

Each returns a result whose ``save(out)`` writes exactly what the matching command writes
(``o3d-seqcc run`` / ``texture`` / ``correct`` call these functions and ``save``), so a Python
user and the command line get byte-identical files for the same scene and options::

    import o3d_seqcc as sc
    res = sc.pipeline.run("scene.json", reference="auto")          # defaults = the CLI's
    res.save("out/")                                               # mesh.glb, mesh.obj, report.json ...
    res.textured.to_open3d()                                       # an Open3D textured mesh

The work runs as tasks (:mod:`o3d_seqcc._shared.parallel`): visibility per view, mappings + joint
histogram + CMF fit per graph edge, image encoding per view, on local threads or, with
``client=`` (a ``dask.distributed.Client``), on a Dask cluster; lookup-table composition,
view selection, the atlas and the export run here. Images are read when a stage needs them
(:class:`~o3d_seqcc.imaging.sequences.SceneImages`), never all at once.
"""

from __future__ import annotations

import logging
import os
import time
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Iterable, Sequence

import numpy as np

from ._shared.arguments import check_images_argument
from .correction import CorrectionResult, correct
from .errors import InputError
from .io.export import DEFAULT_FORMATS, check_export_options, parse_formats
from .imaging.sequences import scene_photos
from .io.load import as_scene
from .mappings.compute import Mappings, compute_mappings
from .geometry.meshops import face_adjacency
from .evaluation.table2 import before_after
from ._shared.parallel import LocalExecutor, carried, current as current_executor, use as use_executor
from ._shared.progress import stage as _stage
from .visibility.refine import coverage
from .run_folder.parts import scene_paths
from .run_folder.write import correction_page_inputs, run_page_inputs, save_correction, save_run
from .report.inputs import PageInputs
from .report.background import BackgroundReport
from .report.schema import correction_section, document
from .scene import Scene, resolve_view
from .settings import CORRECTION_ONLY, TEXTURE_ONLY, CorrectionSettings, RunSettings
from .evaluation.seams import SeamReport, seam_metric
from .texturing import TexturedMesh, TextureSettings, bake_texture, select_views, selection_stats
from .visibility.compute import Visibility, compute_visibility

__all__ = ["CorrectionRun", "RunResult", "check_export_options", "correct_scene", "parse_formats", "run", "texture"]

logger = logging.getLogger(__name__)

def _import_in_background(*modules: str) -> None:
    """Import slow third-party modules in a daemon thread while this one works (scikit-learn: ~1 s)."""
    import importlib, threading  # noqa: E401

    def load() -> None:
        for m in modules:
            try:
                importlib.import_module(m)
            except Exception:  # the real import, later, reports it
                return

    threading.Thread(target=load, name="o3d_seqcc-imports", daemon=True).start()


@dataclass(frozen=True, eq=False)
class RunResult:
    """What :func:`run` and :func:`texture` produce.

    Attributes
    ----------
    scene : Scene
    images : sequence of (H, W, 3) arrays
        The images the mesh was textured with (corrected by :func:`run`); lazy (an
        :class:`~o3d_seqcc.imaging.sequences.ImageSequence`: each access reads and corrects the view's
        image) unless a list was given.
    visibility : Visibility
    selection : (F,) int64
        View per face, -1 = seen by no view.
    selection_stats : dict
        Faces, unseen faces, image transitions, views used (:func:`~o3d_seqcc.texturing.selection_stats`).
    textured : TexturedMesh
        The textured mesh (``textured.to_open3d()`` for Open3D).
    settings : TextureSettings
    correction : CorrectionResult or None
        None for :func:`texture`.
    mappings : Mappings or None
    seams : SeamReport or None
        Seam metric of ``textured`` (None with ``seams=False``).
    seams_original : SeamReport or None
        Seam metric of the same texturing with the uncorrected images (``compare_original``).
    timings : dict
        Seconds per stage.
    command : str
        ``"run"`` or ``"texture"`` (the report's ``command``).
    source : str
        The scene argument as given (the report's ``scene``; empty for a Scene object).
    images_from : str
        ``"scene"`` (the scene's files), ``"corrected"`` (:func:`run`) or ``"given"``.
    originals : list of (H, W, 3) arrays or None
        The images before correction (:func:`run`; None for :func:`texture`).
    run_settings : RunSettings or None
        Every option the run used (``settings`` is its ``texture``).
    """

    scene: Scene
    images: list
    visibility: Visibility
    selection: np.ndarray
    selection_stats: dict
    textured: TexturedMesh
    settings: TextureSettings
    correction: CorrectionResult | None = None
    mappings: Mappings | None = None
    _seams: Any = field(default=None, repr=False)  # a SeamReport, or a future of it (run's thread: see seams)
    seams_original: SeamReport | None = None
    timings: dict = field(default_factory=dict)
    command: str = "run"
    source: str = ""
    images_from: str = "scene"
    originals: list | None = None
    run_settings: RunSettings | None = None
    #: Table 2 and the report's figures started on a background thread by :func:`run` (:class:`~o3d_seqcc.report.background.BackgroundReport`),
    #: used by :meth:`save`
    _background: Any = field(default=None, repr=False, compare=False)

    @property
    def seams(self) -> SeamReport | None:
        """Seam metric of ``textured`` (None with ``seams=False``); measured beside what follows :func:`run`
        (:meth:`save`): the first read waits for it."""
        return self._seams.result() if isinstance(self._seams, Future) else self._seams

    def __getstate__(self) -> dict:
        """Pickled with the seam metric waited for and without :func:`run`'s background thread (:meth:`save`
        computes what it would have given)."""
        return {**self.__dict__, "_seams": self.seams, "_background": None}

    def report(self, files: dict[str, str] | None = None, *, picture_view: str | None = None,
               export: dict[str, Any] | None = None, metrics: dict | None = None,
               selection_seams: dict | None = None) -> dict[str, Any]:
        """The ``report.json`` content (JSON types; the keys of :mod:`o3d_seqcc.report.schema`, as every command's).

        ``export``: the export options :meth:`save` used; ``metrics``: Table 2 (:func:`~o3d_seqcc.evaluation.table2.before_after`);
        ``selection_seams``: ``{"photos", "corrected"}`` -> :class:`~o3d_seqcc.evaluation.seams.SelectionSeams`.
        """
        s = self.settings
        names = self.scene.names
        c = None if self.correction is None else correction_section(
            self.correction, names, None if self.mappings is None else self.mappings.mode)
        return document(
            self.command, scene=self.source, **scene_paths(self.scene), images=self.images_from, views=list(names),
            correction=c, metrics=metrics, texture_settings=asdict(s),
            selection={"method": s.selection, "seed": s.seed, **self.selection_stats,
                       **({"picture_view": picture_view} if picture_view else {})},
            atlas={k: v for k, v in self.textured.stats.items() if not k.startswith("time_")}, export=export,
            seams=None if self.seams is None else self.seams.to_dict(), files=files,
            seams_original_images=None if self.seams_original is None else self.seams_original.to_dict(),
            selection_seams=None if selection_seams is None else {k: v.summary() for k, v in selection_seams.items()},
            visibility_stats=self.visibility.stats, timings_s=self.timings)

    def save(
        self,
        out: str | os.PathLike,
        *,
        overwrite: bool = False,
        formats: str | Iterable[str] = DEFAULT_FORMATS,
        save_images: bool = False,
        selection_view: str | int | None = None,
        unlit: bool = False,
        up_axis: str = "auto",
        texture_format: str = "png",
        jpeg_quality: int = 90,
        report: bool = True,
    ) -> dict[str, str]:
        """Write the textured mesh, the selection, ``report.json`` and ``report.html`` as the folder ``out``, all at once.

        Parameters
        ----------
        out : path-like
            Output folder, written as a whole (:func:`o3d_seqcc.io.output.output_folder`: staged,
            then swapped in); it may not hold any input of the scene.
        overwrite : bool, default False
            Replace an earlier output of o3d_seqcc in ``out`` (never a folder with other files).
        formats : str or iterable, default ("glb", "obj")
            Export formats among ``glb``, ``obj``, ``ply``.
        save_images : bool, default False
            Also write the images used (the corrected ones for :func:`run`) to ``out/images/``.
        selection_view : str or int, optional
            View from which ``selection.png`` (the selection coloured by image) is rendered;
            default the view seeing the most faces; ``"none"`` skips the picture.
        unlit : bool, default False
            GLB material with ``KHR_materials_unlit``.
        up_axis : {"auto", "y", "z", "none"}, default "auto"
            Up axis of the GLB, OBJ and PLY (glTF is Y-up): the scene's up direction, estimated
            from its cameras, is rotated onto it and the rotation baked into the vertices
            (:func:`o3d_seqcc.geometry.orientation.up_axis_transform`, recorded in the report's
            ``export``); ``"none"`` keeps the scene's frame. ``"auto"``: ``"y"`` for a new atlas,
            ``"none"`` for a bake into the mesh's own UVs (``uv="keep"``: the mesh comes back as it
            was given, its positions too). The MeshLab layer always keeps the scene's frame (the
            project's rasters must match it).
        texture_format : {"png", "jpg", "webp"}, default "png"
            Texture images of the GLB and OBJ (WebP in the GLB through ``EXT_texture_webp``).
        jpeg_quality : int, default 90
            JPEG / WebP quality (1-100).
        report : bool, default True
            Also write ``report.html`` (:mod:`o3d_seqcc.report`: the paper's figures for this run)
            and, after a correction, Table 2 in ``report.json`` (``metrics``: every mapping up to
            :data:`~o3d_seqcc.report.METRICS_ALL_UP_TO`, else a sample: ``metrics_sample``).

        Returns
        -------
        dict
            Kind -> written path (also in the report's ``files``).

        Raises
        ------
        InputError
            Unknown format, up axis or texture format, a quality outside 1..100 (before anything
            is written).
        """
        return save_run(self, out, overwrite=overwrite, formats=formats, save_images=save_images,
                        selection_view=selection_view, unlit=unlit, up_axis=up_axis, texture_format=texture_format,
                        jpeg_quality=jpeg_quality, report=report)

    def page_inputs(self, *, report: dict | None = None) -> PageInputs:
        """What this result's report page is drawn from (:func:`o3d_seqcc.report.html_report`); ``report``: the
        report.json content to show, default :meth:`report`'s."""
        return run_page_inputs(self, report)


def own_uv_layout(scene: Scene, s: TextureSettings) -> tuple[Any, np.ndarray] | None:
    """With ``uv="keep"``: the scene's mesh as read and its corner UVs, checked (before any heavy work); else None."""
    if s.uv != "keep":
        return None
    from .io.mesh_files import read_corner_uv
    from .texturing.own_uv import check_corner_uv

    mesh = scene.load_mesh()
    if isinstance(scene.mesh, (str, os.PathLike)):
        uv, where = read_corner_uv(scene.mesh, mesh.vertices, mesh.faces), f"mesh {scene.mesh}"
    else:
        uv, where = mesh.corner_uv, "the mesh"
        if uv is None:
            raise InputError("uv='keep': the mesh in memory has no texture coordinates (Mesh.corner_uv; an Open3D "
                             "mesh's triangle_uvs); give one with UVs or drop uv='keep' for a new atlas")
    return mesh, check_corner_uv(uv, len(mesh.faces), where=where)


def _bake(vis, images, labels, s: TextureSettings, adjacency, own) -> TexturedMesh:
    """The atlas bake, or with ``own`` (:func:`own_uv_layout`) the bake into the mesh's own UVs."""
    if own is None:
        return bake_texture(vis.mesh, images, vis, labels, settings=s, adjacency=adjacency)
    from .texturing.own_uv import bake_own_uv

    return bake_own_uv(vis.mesh, images, vis, labels, input_mesh=own[0], corner_uv=own[1], parent=vis.parent_faces,
                       settings=s, adjacency=adjacency)


def _texture_stage(scene, images, vis, s: TextureSettings, timings: dict, *, want_seams: bool,
                   selected: Any = None, own: Any = None):
    mesh = vis.mesh
    with _stage("selection", timings):
        adjacency = face_adjacency(mesh.faces, mesh.vertices)
        opts = {"adjacency": adjacency, "smoothness": s.smoothness} if s.selection == "mrf" else {}
        labels = select_views(vis, method=s.selection, seed=s.seed, images=images, data_term=s.data_term,
                              outlier_removal=s.outlier_removal, **opts)
    if selected is not None:  # the report's background thread measures the selection seams while the bake works
        selected(mesh, labels, scene.views)
    with _stage("bake", timings):
        tm = _bake(vis, images, labels, s, adjacency, own)
    return (labels, {**selection_stats(labels, adjacency, len(scene.views)), **coverage(vis, labels)}, tm,
            _seams_beside(tm, timings) if want_seams else None)


def _seams_beside(tm: TexturedMesh, timings: dict) -> Any:
    """The seam metric of ``tm`` (``timings["seams"]``): with local threads, a future of it computed on a thread of
    its own, beside what the caller does next (``save``'s files: the metric's numpy leaves a core idle)."""
    ex = current_executor()
    if not isinstance(ex, LocalExecutor) or ex.threads() < 2:
        with _stage("seams", timings):
            return seam_metric(tm)

    def measure() -> SeamReport:
        t = time.perf_counter()
        try:
            return seam_metric(tm)
        finally:
            timings["seams"] = time.perf_counter() - t

    pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="o3d_seqcc-seams")
    future = pool.submit(carried(measure))
    pool.shutdown(wait=False)  # the thread ends after its task (the interpreter's exit waits for it)
    return future


def texture(
    scene: Scene | str | os.PathLike,
    *,
    images: Sequence[np.ndarray] | None = None,
    mesh: str | os.PathLike | None = None,
    scene_options: dict[str, Any] | None = None,
    settings: RunSettings | TextureSettings | None = None,
    client: Any = None,
    **options: Any,
) -> RunResult:
    """Texture the mesh from the scene's images (or ``images``): selection, atlas, seam metric.

    Parameters
    ----------
    scene : Scene or path
        A scene, or any path :func:`~o3d_seqcc.load_scene` reads.
    images : list of (H, W, 3) arrays, optional
        One per view, instead of the scene's files (e.g. corrected images).
    mesh : path-like, optional
        Mesh to use instead of the scene's.
    scene_options : dict, optional
        When ``scene`` is a path: keyword options of :func:`~o3d_seqcc.load_scene`, as the
        command line's scene flags (``{"skip_missing": True}`` for ``--skip-missing-images``,
        ``allow_unseen``, ``masks``, ``image_dir``, ...).
    settings : RunSettings or TextureSettings, optional
        Default :class:`~o3d_seqcc.settings.RunSettings` (the command line's defaults); a
        TextureSettings replaces its ``texture``. The correction's settings are not used.
    client : dask.distributed.Client, optional
        Run the per-view tasks on its cluster (:mod:`o3d_seqcc._shared.parallel`); default local threads.
    **options
        Options changed from ``settings``, by their flat names (:meth:`RunSettings.replace
        <o3d_seqcc.settings.RunSettings.replace>`): fields of
        :class:`~o3d_seqcc.texturing.TextureSettings` (``selection="largest-area"``,
        ``atlas_size=4096``, ...) and :class:`~o3d_seqcc.visibility.settings.VisibilitySettings`
        (``split_faces``, ``max_angle``, ...), ``seams``.

    Returns
    -------
    RunResult
    """
    source = str(scene) if not isinstance(scene, Scene) else ""
    timings: dict[str, float] = {}
    t_all = time.perf_counter()
    rs = RunSettings.resolve(settings, options, where="texture", exclude=CORRECTION_ONLY)
    s = rs.texture
    sc = as_scene(scene, mesh, scene_options)
    if images is None:
        imgs = scene_photos(sc.views)  # read when the bake needs them, kept while they fit
    else:
        imgs = check_images_argument(images, sc.views)
    own = own_uv_layout(sc, s)
    with use_executor(client):
        with _stage("visibility", timings):
            vis = compute_visibility(sc, settings=rs.visibility)
        labels, stats, tm, sm = _texture_stage(sc, imgs, vis, s, timings, want_seams=rs.seams, own=own)
    timings["total"] = time.perf_counter() - t_all
    return RunResult(scene=sc, images=imgs, visibility=vis, selection=labels, selection_stats=stats, textured=tm,
                     settings=s, _seams=sm, timings=timings, command="texture", source=source,
                     images_from="scene" if images is None else "given", run_settings=rs)


def run(
    scene: Scene | str | os.PathLike,
    *,
    mesh: str | os.PathLike | None = None,
    scene_options: dict[str, Any] | None = None,
    settings: RunSettings | TextureSettings | None = None,
    client: Any = None,
    **options: Any,
) -> RunResult:
    """Colour-correct every view toward a reference, then texture the mesh with the corrected images.

    Parameters
    ----------
    scene : Scene or path
        A scene, or any path :func:`~o3d_seqcc.load_scene` reads.
    mesh : path-like, optional
        Mesh to use instead of the scene's.
    scene_options : dict, optional
        When ``scene`` is a path: keyword options of :func:`~o3d_seqcc.load_scene`, as the
        command line's scene flags (``{"skip_missing": True}`` for ``--skip-missing-images``,
        ``allow_unseen``, ``masks``, ``image_dir``, ...).
    settings : RunSettings, optional
        Every option of the run; default :class:`~o3d_seqcc.settings.RunSettings` (the command
        line's defaults, documented there and in its stage classes). A
        :class:`~o3d_seqcc.texturing.TextureSettings` (or another stage's settings) replaces that
        stage only.
    client : dask.distributed.Client, optional
        Run the per-view and per-edge tasks on its cluster (:mod:`o3d_seqcc._shared.parallel`; the
        scene's files must be readable at the same paths on every worker); default local
        threads (``joblib.parallel_config``). The outputs are identical either way.
    **options
        Options changed from ``settings``, by their flat names (:meth:`RunSettings.replace
        <o3d_seqcc.settings.RunSettings.replace>`; None: the settings' value):
        :class:`~o3d_seqcc.correction.settings.CorrectionSettings` (``reference``, ``method``,
        ``t_npm``, ``mappings``, ...), :class:`~o3d_seqcc.visibility.settings.VisibilitySettings`
        (``split_faces``, ``max_angle``, ...), :class:`~o3d_seqcc.texturing.TextureSettings`
        (``selection``, ``atlas_size``, ...; ``seed`` seeds the correction too) and the run's
        own ``seams``, ``compare_original``.

    Returns
    -------
    RunResult

    Raises
    ------
    InputError
        Unknown method, reference, mapping mode or texture option value, checked before any
        heavy work; bad scenes.
    UnknownSettingError
        An option name no settings object has (a ``TypeError``; the message lists the valid ones).

    Examples
    --------
    >>> import tempfile, o3d_seqcc as sc
    >>> room = sc.make_synthetic_scene(tempfile.mkdtemp() + '/room', n_views=3, width=96, height=72, seed=1,
    ...                                seen_only=True)
    >>> res = sc.pipeline.run(room.scene, t_npm=10, atlas_size=512)
    >>> files = res.save(room.root.parent / 'out', formats='glb')  # staged, then swapped in
    >>> sorted(k for k in files if k in ('glb', 'report_html', 'meshlab_project'))
    ['glb', 'meshlab_project', 'report_html']
    """
    source = str(scene) if not isinstance(scene, Scene) else ""
    timings: dict[str, float] = {}
    t_all = time.perf_counter()
    rs = RunSettings.resolve(settings, options, where="run", exclude=("metrics",))
    s, cs = rs.texture, rs.correction
    sc = as_scene(scene, mesh, scene_options)
    if cs.reference != "auto":
        resolve_view(sc.names, cs.reference)
    own = own_uv_layout(sc, s)
    originals = scene_photos(sc.views)  # read when a task first needs them, kept while they fit
    if cs.method != "seqcc-global":  # its default start is numpy only: no CMF fit, no scikit-learn (2 s of imports)
        _import_in_background("sklearn.svm", "sklearn.isotonic")  # the colour mapping fits need them
    with use_executor(client):
        with _stage("visibility", timings):
            vis = compute_visibility(sc, settings=rs.visibility)
        with _stage("mappings", timings):
            maps = compute_mappings(sc, visibility=vis, mappings=cs.mappings)
        with _stage("correction", timings):
            res = correct(sc, mappings=maps, images=originals, settings=cs)
        # the report's Table 2 needs the correction alone: on a spare thread while the texturing runs (local only:
        # a Dask client may be closed before save())
        bg = BackgroundReport(originals, res, maps) if isinstance(current_executor(), LocalExecutor) else None
        try:
            labels, stats, tm, sm = _texture_stage(sc, res.images, vis, s, timings, want_seams=rs.seams,
                                                   selected=None if bg is None else bg.selected, own=own)
            sm0 = None
            if rs.compare_original:
                with _stage("compare_original", timings):
                    # the same settings pack the same charts (they do not depend on the images) into the same atlas
                    sm0 = seam_metric(_bake(vis, originals, labels, s, None, own))
        except BaseException:
            if bg is not None:
                bg.close()
            raise
    timings["total"] = time.perf_counter() - t_all
    return RunResult(scene=sc, images=res.images, visibility=vis, selection=labels, selection_stats=stats, textured=tm,
                     settings=s, correction=res, mappings=maps, _seams=sm, seams_original=sm0, timings=timings,
                     command="run", source=source, images_from="corrected", originals=originals, run_settings=rs,
                     _background=bg)


@dataclass(frozen=True, eq=False)
class CorrectionRun:
    """What :func:`correct_scene` produces: the correction, its inputs and its report.

    Attributes
    ----------
    scene : Scene
    result : CorrectionResult
        Corrected images (``result.images``), transforms, reference, paths.
    mappings : Mappings
    originals : list of (H, W, 3) arrays
    report : dict
        The ``report.json`` content (:mod:`o3d_seqcc.report.schema`, as ``run``'s): under
        ``correction`` the graph edges, paths, unreachable views and per-view lookup tables;
        ``metrics``, the per-pair metrics before / after with the contrast ratios (None with
        ``metrics=False``); ``timings_s``.
    """

    scene: Scene
    result: CorrectionResult
    mappings: Mappings
    originals: list
    report: dict

    def save(self, out: str | os.PathLike, *, overwrite: bool = False, report: bool = True) -> Path:
        """Write ``out/images/<view>.png``, ``out/scene.json`` (pointing at them), ``out/report.json``
        and ``out/report.html`` (unless ``report=False``; :mod:`o3d_seqcc.report`).

        The folder is written as a whole (:func:`o3d_seqcc.io.output.output_folder`: staged, then
        swapped in; it may not hold any input of the scene); ``overwrite`` replaces an earlier
        output of o3d_seqcc there. Returns ``out``.
        """
        return save_correction(self, out, overwrite=overwrite, report=report)

    def page_inputs(self, *, report: dict | None = None) -> PageInputs:
        """What this correction's report page is drawn from; ``report``: default :attr:`report`."""
        return correction_page_inputs(self, report)


def correct_scene(
    scene: Scene | str | os.PathLike,
    *,
    mesh: str | os.PathLike | None = None,
    scene_options: dict[str, Any] | None = None,
    settings: RunSettings | CorrectionSettings | None = None,
    client: Any = None,
    **options: Any,
) -> CorrectionRun:
    """Colour-correct every view of a scene (the ``correct`` command), with its report.

    Parameters
    ----------
    scene : Scene or path
    mesh : path-like, optional
    scene_options : dict, optional
        When ``scene`` is a path: keyword options of :func:`~o3d_seqcc.load_scene`, as the
        command line's scene flags (``{"skip_missing": True}`` for ``--skip-missing-images``,
        ``allow_unseen``, ``masks``, ``image_dir``, ...).
    settings : RunSettings or CorrectionSettings, optional
        Default :class:`~o3d_seqcc.settings.RunSettings` (the command line's defaults); a
        CorrectionSettings replaces its ``correction``. The texture's settings are not used.
    client : dask.distributed.Client, optional
        Run the per-view and per-edge tasks on its cluster (:mod:`o3d_seqcc._shared.parallel`).
    **options
        Options changed from ``settings``, by their flat names (as :func:`run`): fields of
        :class:`~o3d_seqcc.correction.settings.CorrectionSettings` (``reference``, ``method``,
        ``t_npm``, ``mappings``, ``seed``, ``graph_weight``, ...) and
        :class:`~o3d_seqcc.visibility.settings.VisibilitySettings` (``split_faces``, ...), and
        ``metrics`` (:attr:`RunSettings.metrics <o3d_seqcc.settings.RunSettings.metrics>`:
        per-pair PSNR / CIEDE2000 before and after in the report, the slowest part).

    Returns
    -------
    CorrectionRun
    """
    rs = RunSettings.resolve(settings, options, where="correct_scene", exclude=TEXTURE_ONLY)
    cs = rs.correction
    reference, mappings = cs.reference, cs.mappings
    metrics = rs.metrics
    sc = as_scene(scene, mesh, scene_options)
    if reference != "auto":
        resolve_view(sc.names, reference)
    t = time.perf_counter()
    with use_executor(client):
        with _stage("mappings"):
            maps = compute_mappings(sc, mappings=mappings, settings=rs.visibility)
        t_map = time.perf_counter() - t
        originals = [v.load_image() for v in sc.views]
        with _stage("correction"):
            res = correct(sc, mappings=maps, images=originals, settings=cs)
    res.timings["mappings"] = t_map
    t = time.perf_counter()
    table2 = None
    if metrics:
        with _stage("metrics"):
            table2 = before_after(originals, res.images, maps, res.paths, per_pair=True)
    t_metrics = time.perf_counter() - t
    report = document("correct", scene=str(scene) if not isinstance(scene, Scene) else "", **scene_paths(sc),
                      images="scene", views=list(sc.names),
                      correction=correction_section(res, sc.names, mappings, lookup_tables=True), metrics=table2,
                      visibility_stats=getattr(getattr(maps, "visibility", None), "stats", None),
                      timings_s={"mappings": t_map, "correction": res.timings.get("total", 0.0), "metrics": t_metrics})
    return CorrectionRun(scene=sc, result=res, mappings=maps, originals=originals, report=report)
