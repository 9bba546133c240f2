"""Our two jobs as MeshLab filters, called the way pymeshlab calls its own.

pymeshlab cannot add filters to MeshLab, so the filters take the ``pymeshlab.MeshSet`` as their
first argument instead of being its methods::

    import pymeshlab
    import meshlab_filters

    ms = pymeshlab.MeshSet()
    ms.load_project("/data/room/project.mlp")                # a mesh layer + registered rasters
    meshlab_filters.print_filter_parameter_list("seqcc_color_correct_rasters")
    meshlab_filters.apply(ms, "seqcc_color_correct_rasters", reference="auto", savedir="corrected")
    meshlab_filters.apply(ms, "seqcc_texture_from_rasters", colorcorrection=False, savedir="textured")
    ms.save_project("/data/room/corrected/room.mlp")           # absolute path: see meshset.py

========================================  ==============================================================
filter                                    what it does to the MeshSet
========================================  ==============================================================
``seqcc_color_correct_rasters``           colour-corrects every raster toward a reference
                                          (``o3d-seqcc correct``); the MeshSet then holds the corrected
                                          rasters (and its mesh layers, unchanged)
``seqcc_texture_from_rasters``            textures the current mesh from the rasters, colour-corrected
                                          first by default (``o3d-seqcc run``; ``colorcorrection=False``:
                                          ``o3d-seqcc texture``); the textured mesh is added as a new
                                          layer and becomes the current mesh
========================================  ==============================================================

Parameter names follow pymeshlab's (lower case, no underscores: ``tnpm`` is the library's
``t_npm``, ``atlassize`` is ``TextureSettings.atlas_size``); their defaults are read from the
library's settings objects (:class:`~o3d_seqcc.correction.settings.CorrectionSettings`,
:class:`~o3d_seqcc.texturing.TextureSettings`, :class:`~o3d_seqcc.settings.RunSettings`), which
are the command line's, and their descriptions from the settings' docstrings. Enum parameters take the value's name or, as in
pymeshlab, its index. Unknown filter names raise :class:`~o3d_seqcc.errors.InputError` listing
the valid ones; unknown parameters raise ``TypeError`` listing the filter's parameters; bad values
raise ``InputError`` naming the parameter and what it accepts.
"""

from __future__ import annotations

import functools
import inspect
import logging
import re
import sys
from dataclasses import dataclass
from typing import Any, Callable, TextIO

import numpy as np

from o3d_seqcc._shared.registry import Registry, UnknownNameError
from o3d_seqcc.errors import InputError, require

__all__ = ["FilterParameter", "MeshLabFilter", "apply", "filter_list", "filter_parameter_text",
           "get_filter", "print_filter_parameter_list"]

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class FilterParameter:
    """One parameter of a filter, as pymeshlab documents its own.

    Attributes
    ----------
    name : str
        pymeshlab-style name (``tnpm``).
    type : type
        ``bool``, ``int``, ``float`` or ``str``.
    default : Any
        The library's default.
    label : str
        Short label (MeshLab's dialog label).
    description : str
        One paragraph, from the library's docstring.
    values : tuple of str
        Possible values of an enum parameter (empty otherwise).
    keyword : str
        The library keyword the value is passed as (``t_npm``).
    """

    name: str
    type: type
    default: Any
    label: str
    description: str
    values: tuple[str, ...] = ()
    keyword: str = ""

    def signature(self) -> str:
        """``name : type = default`` as ``pymeshlab.print_filter_parameter_list`` prints it."""
        text = f"{self.name} : {self.type.__name__} = {self.default!r}"
        if self.values:
            text += f" (or int = {self.values.index(self.default)})"
        return text

    def convert(self, value: Any, filter_name: str) -> Any:
        """``value`` checked and converted to the parameter's type (enum index -> name)."""
        where = f"{filter_name}: parameter {self.name!r}"
        if self.values:
            if isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_)):
                if not 0 <= int(value) < len(self.values):
                    raise InputError(f"{where}: enum index {value} out of range 0..{len(self.values) - 1}; "
                                     f"possible values: {', '.join(map(repr, self.values))}")
                return self.values[int(value)]
            if value not in self.values:
                raise InputError(f"{where}: {value!r} is not a possible value; use one of "
                                 f"{', '.join(map(repr, self.values))} (or its index)")
            return str(value)
        if self.type is bool:
            if not isinstance(value, (bool, np.bool_)):
                raise InputError(f"{where} must be True or False, got {value!r}")
            return bool(value)
        if self.type is int:
            if isinstance(value, str) and value == "auto" and self.default == "auto":  # a derived default (t_npm)
                return value
            if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
                alt = " or 'auto'" if self.default == "auto" else ""
                raise InputError(f"{where} must be an int{alt}, got {value!r}")
            return int(value)
        if self.type is float:
            if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
                raise InputError(f"{where} must be a float, got {value!r}")
            return float(value)
        if not isinstance(value, str):
            raise InputError(f"{where} must be a str, got {value!r}")
        return value


@dataclass(frozen=True)
class MeshLabFilter:
    """A filter: pymeshlab-style name, MeshLab-style title, description, parameters, implementation.

    Attributes
    ----------
    name : str
        Name given to :func:`apply` (``seqcc_color_correct_rasters``).
    meshlab_name : str
        Title as MeshLab's menus would show it.
    description : str
    parameters : tuple of FilterParameter
    run : callable
        ``run(ms, **{p.keyword: value})`` -> dict of outputs.
    """

    name: str
    meshlab_name: str
    description: str
    parameters: tuple[FilterParameter, ...]
    run: Callable[..., dict]

    def parameter(self, name: str) -> FilterParameter:
        """The parameter called ``name`` (KeyError if none)."""
        return {p.name: p for p in self.parameters}[name]


# ---- descriptions and defaults, read from the library -----------------------------------------------------------

_ROLE = re.compile(r":[a-z]+:`~?([^`]+)`")


def _doc_entries(obj: Any, section: str) -> dict[str, str]:
    """``name -> description`` of a numpydoc section (``Parameters`` / ``Attributes``) of ``obj``'s docstring.

    Sphinx roles and literal quotes are stripped (``:func:`~a.b``` -> ``a.b``, ````x```` -> ``x``);
    an entry naming several parameters (``a, b : int``) gives each the same text.
    """
    lines = (inspect.getdoc(obj) or "").splitlines()
    out: dict[str, str] = {}
    try:
        start = next(i for i in range(len(lines) - 1)
                     if lines[i].strip() == section and set(lines[i + 1].strip()) == {"-"}) + 2
    except StopIteration:
        return out
    names: list[str] = []
    for i in range(start, len(lines)):
        line = lines[i]
        if i + 1 < len(lines) and line.strip() and set(lines[i + 1].strip()) == {"-"}:
            break  # next section
        if line and not line[0].isspace():
            names = [n.strip().lstrip("*") for n in line.split(":")[0].split(",")]
            for n in names:
                out[n] = ""
        elif line.strip():
            for n in names:
                out[n] = (out[n] + " " + line.strip()).strip()
    return {k: _ROLE.sub(r"\1", v).replace("``", "") for k, v in out.items()}


def _param(keyword: str, label: str, defaults: dict[str, Any], docs: dict[str, str], *,
           name: str | None = None, values: tuple[str, ...] = (), kind: type | None = None) -> FilterParameter:
    default = defaults[keyword]
    desc = docs.get(keyword, "")
    if not desc:
        raise RuntimeError(f"no description of {keyword!r} in the library's docstrings")  # caught by the tests
    return FilterParameter(name=name or keyword.replace("_", ""), type=kind or type(default), default=default,
                           label=label, description=desc, values=tuple(values), keyword=keyword)


def _correction_parameters(cc_defaults: dict, cc_docs: dict) -> list[FilterParameter]:
    from o3d_seqcc.correction import available_methods
    from o3d_seqcc.mappings.compute import MODES

    return [
        _param("reference", "Reference raster", cc_defaults, cc_docs, kind=str),
        _param("method", "Correction method", cc_defaults, cc_docs, values=tuple(available_methods())),
        _param("t_npm", "Minimum overlap per graph edge", cc_defaults, cc_docs, kind=int),  # or "auto"
        _param("mappings", "Pairwise mappings", cc_defaults, cc_docs, values=tuple(MODES)),
    ]


def _output_parameters(default_dir: str, save_defaults: dict, save_docs: dict, what: str) -> list[FilterParameter]:
    savedir = FilterParameter(
        name="savedir", type=str, default=default_dir, label="Output folder", keyword="savedir",
        description=f"Folder written as a whole ({what}, report.json, project.mlp); a relative path is relative to "
                    "the current working directory, as MeshLab's texture file names are. Refused if it exists, "
                    "unless overwrite.")
    return [savedir, _param("overwrite", "Overwrite", save_defaults, save_docs)]


@functools.cache
def _registry() -> Registry[MeshLabFilter]:
    from o3d_seqcc import pipeline
    from o3d_seqcc.correction.graph import WEIGHTS
    from o3d_seqcc.settings import CorrectionSettings, RunSettings, keyword_defaults  # the command line's defaults too
    from o3d_seqcc.texturing import SELECTION_METHODS, TextureSettings
    from o3d_seqcc.texturing.settings import DATA_TERMS, FALLBACKS, OUTLIER_REMOVALS, OVERFLOWS, UV_MODES

    from . import meshset

    # every default from the settings objects (the command line's), every description from their docstrings
    run_defaults, run_docs = RunSettings.defaults(), _doc_entries(RunSettings, "Attributes")
    cc_defaults, cc_docs = CorrectionSettings.defaults(), _doc_entries(CorrectionSettings, "Attributes")
    save_defaults = {**keyword_defaults(pipeline.CorrectionRun.save), **keyword_defaults(pipeline.RunResult.save)}
    save_docs = _doc_entries(pipeline.RunResult.save, "Parameters")
    ts_defaults = TextureSettings.defaults()
    ts_docs = _doc_entries(TextureSettings, "Attributes")
    enums = {"selection": tuple(sorted(SELECTION_METHODS)), "overflow": tuple(OVERFLOWS), "fallback": tuple(FALLBACKS),
             "data_term": tuple(DATA_TERMS), "outlier_removal": tuple(OUTLIER_REMOVALS), "uv": tuple(UV_MODES),
             "pack_effort": ("fast", "best")}
    labels = {
        "selection": "View selection", "smoothness": "Selection smoothness", "seed": "Random seed",
        "atlas_size": "Largest atlas size", "padding": "Chart gutter", "texels_per_pixel": "Texels per pixel",
        "overflow": "When the atlas is full", "power_of_two": "Power-of-two atlas",
        "shrink_to_fit": "Density drop to keep a power of two", "merge_charts": "Merge tiny charts",
        "small_charts": "Small charts (texels)", "small_padding": "Small charts' gutter",
        "pack_effort": "Packing effort",
        "fill_background": "Fill the background", "leveling": "Global seam leveling",
        "leveling_smoothness": "Seam leveling smoothness", "local_leveling": "Local seam leveling",
        "local_band": "Local leveling band", "fallback": "Colour of unseen faces",
        "data_term": "Selection data term", "outlier_removal": "Photometric outlier removal",
        "uv": "Texture coordinates",
    }
    if set(labels) != set(ts_defaults):
        raise RuntimeError(f"label the TextureSettings fields {sorted(set(ts_defaults) ^ set(labels))}")

    correct = MeshLabFilter(
        name="seqcc_color_correct_rasters",
        meshlab_name="Sequential pairwise colour correction of the rasters",
        description="Colour-corrects every raster toward a reference raster along the best chain of overlapping "
                    "rasters (Dal'Col et al., Sensors 2023), using the current mesh to find which pixels see the "
                    "same surface point. The corrected rasters replace the MeshSet's rasters; the mesh layers are "
                    "kept. The same job as o3d-seqcc correct.",
        parameters=tuple([
            *_correction_parameters(cc_defaults, cc_docs),
            _param("graph_weight", "Graph edge weight", cc_defaults, cc_docs, values=tuple(WEIGHTS)),
            _param("seed", "Random seed", cc_defaults, cc_docs),
            _param("metrics", "Report metrics", run_defaults, run_docs),
            *_output_parameters("seqcc_corrected", save_defaults, save_docs,
                                "images/<raster>.png, the mesh layers in layers/"),
        ]),
        run=meshset.color_correct_rasters,
    )
    texture = MeshLabFilter(
        name="seqcc_texture_from_rasters",
        meshlab_name="Texture from registered rasters, colour-corrected (seqcc)",
        description="Textures the current mesh from the rasters: one raster per face (with few raster changes), "
                    "a texture atlas at the rasters' own resolution, seam leveling; the rasters are colour-"
                    "corrected first unless colorcorrection is off. The textured mesh is added as a new layer "
                    "and becomes the current mesh; the rasters are not changed. The same job as o3d-seqcc run "
                    "(o3d-seqcc texture without colour correction).",
        parameters=tuple([
            FilterParameter(name="colorcorrection", type=bool, default=True, label="Colour correction",
                            keyword="colorcorrection",
                            description="Colour-correct the rasters toward the reference first (o3d-seqcc run), "
                                        "or texture with the rasters as they are (o3d-seqcc texture)."),
            *_correction_parameters(cc_defaults, cc_docs),
            # atlas_size: an int budget or "auto" (sized to the charts), as t_npm
            *(_param(k, labels[k], ts_defaults, ts_docs, values=enums.get(k, ()), kind=int if k == "atlas_size" else None)
              for k in ts_defaults),
            _param("seams", "Seam metric", run_defaults, run_docs),
            FilterParameter(name="formats", type=str, default=",".join(pipeline.DEFAULT_FORMATS),
                            label="Export formats", description=save_docs["formats"], keyword="formats"),
            _param("save_images", "Save the images used", save_defaults, save_docs),
            *_output_parameters("seqcc_textured", save_defaults, save_docs,
                                "mesh_meshlab.ply with its texture, the export formats"),
        ]),
        run=meshset.texture_from_rasters,
    )
    return Registry("MeshLab filter", {"seqcc_color_correct_rasters": correct, "seqcc_texture_from_rasters": texture})


# ---- public functions ---------------------------------------------------------------------------------------------


def filter_list() -> list[str]:
    """Names of the filters :func:`apply` knows."""
    return sorted(_registry())


def get_filter(filter_name: str) -> MeshLabFilter:
    """The filter called ``filter_name``; an unknown name raises InputError listing the valid ones."""
    try:
        return _registry()[filter_name]
    except UnknownNameError as e:
        raise InputError(f"{e} (MeshLab's own filters are methods of the MeshSet: ms.apply_filter(name, ...))") from None


def filter_parameter_text(filter_name: str) -> str:
    """What :func:`print_filter_parameter_list` prints, as a string."""
    f = get_filter(filter_name)
    out = [f"{f.name} filter ('{f.meshlab_name}') - list of parameter names:"]
    for p in f.parameters:
        out.append(f"\t{p.signature()}")
        if p.values:
            out.append("\t\tPossible enum values: " + ", ".join(f"{i}. {v!r}" for i, v in enumerate(p.values)))
        out.append(f"\t\t{p.label}: {p.description}")
    return "\n".join(out) + "\n"


def print_filter_parameter_list(filter_name: str, *, file: TextIO | None = None) -> None:
    """Print the parameters of a filter with their types, defaults and descriptions, like pymeshlab's.

    Printing is this function's contract (as ``pymeshlab.print_filter_parameter_list``'s); the
    text is :func:`filter_parameter_text`.

    Parameters
    ----------
    filter_name : str
        ``"seqcc_color_correct_rasters"`` or ``"seqcc_texture_from_rasters"``.
    file : text stream, optional
        Where to print; default ``sys.stdout``.

    Raises
    ------
    InputError
        Unknown filter name (the message lists the valid ones).
    """
    print(filter_parameter_text(filter_name), end="", file=file if file is not None else sys.stdout)


def apply(ms: Any, filter_name: str, **parameters: Any) -> dict[str, Any]:
    """Apply one of our filters to a ``pymeshlab.MeshSet``, as ``ms.apply_filter(name, **parameters)`` would.

    Parameters
    ----------
    ms : pymeshlab.MeshSet
        Holds a project: at least one triangle mesh (the current one is used) and registered rasters
        (``ms.load_project("project.mlp")``). Changed in place (see the filter's description).
    filter_name : str
        See :func:`filter_list`.
    **parameters
        The filter's parameters by their pymeshlab-style names (:func:`print_filter_parameter_list`);
        those not given take the library's defaults.

    Returns
    -------
    dict
        The filter's outputs (written files, chosen reference, ...), as ``apply_filter``'s dict.

    Raises
    ------
    InputError
        Unknown filter, bad parameter value, a MeshSet without mesh or rasters, bad scenes.
    TypeError
        Unknown parameter name (the message lists the filter's parameters).
    """
    f = get_filter(filter_name)
    pymeshlab = require("pymeshlab", extra="meshlab", what="meshlab_filters.apply (pymeshlab's MeshSet)")

    if not isinstance(ms, pymeshlab.MeshSet):
        raise InputError(f"{filter_name}: ms must be a pymeshlab.MeshSet holding a project "
                         f"(ms = pymeshlab.MeshSet(); ms.load_project(...)), got {type(ms).__name__}")
    known = {p.name: p for p in f.parameters}
    bad = sorted(set(parameters) - set(known))
    if bad:
        raise TypeError(f"{filter_name}: unknown parameter(s) {bad}; valid: {', '.join(known)}")
    kwargs = {p.keyword: p.convert(parameters[p.name], filter_name) if p.name in parameters else p.default
              for p in f.parameters}
    logger.info("%s: %s", filter_name, ", ".join(f"{k}={v!r}" for k, v in kwargs.items()))
    return f.run(ms, **kwargs)
