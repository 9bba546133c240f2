"""The two filters of the native MeshLab plugin (``meshlab_filters/plugin/``), described from the library.

The C++ plugin does not retype any default or help text: at build time CMake runs
``python -m meshlab_filters.native header OUT.h``, which writes this module's
:func:`native_filters` as JSON inside a C++ header, and the plugin builds its MeshLab parameters
from it. Each parameter is one of the pymeshlab-style filters' (:mod:`meshlab_filters.filters`),
whose defaults and descriptions are read from the library's signatures and docstrings, so a
default changed in the library reaches MeshLab's dialog with the next ``./dev.sh setup`` (its
build stamp hashes this JSON).

=====================================================  ==========================================
MeshLab filter                                         child process
=====================================================  ==========================================
``Sequential colour correction of rasters (o3d_seqcc)`` ``o3d-seqcc correct PROJECT --out DIR``;
                                                       the rasters' images are replaced by the
                                                       corrected ``DIR/images/*.png``
``Seamless texture from rasters (o3d_seqcc)``          ``o3d-seqcc run PROJECT --out DIR``
                                                       (``texture`` without colour correction);
                                                       ``DIR/mesh_meshlab.ply`` becomes a new,
                                                       current layer
=====================================================  ==========================================

``PROJECT`` is the current mesh (placement matrix applied, binary PLY) and every raster, written
by the plugin to a temporary folder; the child runs with ``-v --progress-lines`` and its log and
progress go to MeshLab's log and progress bar (:func:`o3d_seqcc._shared.progress.progress_lines`).

Run ``python -m meshlab_filters.native json`` to see what the plugin is built with, and
``python -m meshlab_filters.native script "Seamless texture from rasters (o3d_seqcc)" tnpm=100``
for a complete filter script (:func:`filter_script`).
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .filters import FilterParameter, get_filter

__all__ = ["CORRECT_TITLE", "NATIVE_FILTERS", "TEXTURE_TITLE", "NativeFilter", "cli_arguments", "cpp_header",
           "filter_script", "native_filters"]

#: exact MeshLab filter names (filter scripts call them by name: a contract)
CORRECT_TITLE = "Sequential colour correction of rasters (o3d_seqcc)"
TEXTURE_TITLE = "Seamless texture from rasters (o3d_seqcc)"

_PAPER = ("<br><br>See: <i>L. Dal'Col, D. Coelho, T. Madeira, P. Dias, M. Oliveira</i>, <b>\"A Sequential Color "
          "Correction Approach for Texture Mapping of 3D Meshes\"</b>, Sensors 2023, 23(2), 607.")


@dataclass(frozen=True)
class NativeFilter:
    """One filter of the native plugin.

    Attributes
    ----------
    title : str
        MeshLab's filter name (menu entry, ``.mlx`` ``FilterName``).
    registry : str
        The pymeshlab-style filter of :mod:`meshlab_filters.filters` its parameters come from.
    command : str
        ``o3d-seqcc`` command run.
    parameters : tuple of str
        Registry parameter names shown in MeshLab's dialog, in order.
    switch : str
        A bool parameter that, when False, runs ``command_off`` instead (``""``: none).
    command_off : str
    info : str
        MeshLab's description (HTML), shown at the top of the dialog.
    savedir_help : str
        Tooltip of the output folder (resolved differently from the pymeshlab filters').
    """

    title: str
    registry: str
    command: str
    parameters: tuple[str, ...]
    info: str
    savedir_help: str
    switch: str = ""
    command_off: str = ""


NATIVE_FILTERS: tuple[NativeFilter, ...] = (
    NativeFilter(
        title=CORRECT_TITLE, registry="seqcc_color_correct_rasters", command="correct",
        parameters=("reference", "method", "tnpm", "savedir", "overwrite"),
        info="Colour-corrects every raster toward a reference raster along the best chain of overlapping rasters "
             "(sequential pairwise colour correction, refined jointly over every overlapping pair by default), "
             "using the current mesh to find the pixels that see the same surface point. Each raster's image is "
             "replaced by its corrected copy, written to the output folder (images/&lt;raster&gt;.png, with "
             "report.html, report.json, scene.json and project.mlp); cameras and meshes are not changed. Runs "
             "<tt>o3d-seqcc correct</tt> on the current mesh and the rasters." + _PAPER,
        savedir_help="Folder for the corrected images, report.html / report.json, scene.json and project.mlp, "
                     "written as a whole. A relative path is relative to the project's folder (or, without a "
                     "project, the current mesh's folder). Refused if it exists, unless Overwrite."),
    NativeFilter(
        title=TEXTURE_TITLE, registry="seqcc_texture_from_rasters", command="run", switch="colorcorrection",
        command_off="texture",
        parameters=("colorcorrection", "reference", "method", "tnpm", "selection", "atlassize", "texelsperpixel",
                    "savedir", "overwrite"),
        info="Textures the current mesh from the rasters: their colours are corrected toward a reference raster "
             "first (sequential pairwise colour correction), then each face takes one raster (a Markov random "
             "field: large projections, few seams), the charts are packed into an atlas at the rasters' own "
             "resolution and the seams are levelled. The textured mesh (mesh_meshlab.ply and its texture in the "
             "output folder, with report.html, mesh.glb and mesh.obj) is added as a new layer and becomes the "
             "current mesh; the source mesh's layer is hidden (the textured copy covers it) and the rasters are "
             "not changed. Runs <tt>o3d-seqcc run</tt> (<tt>o3d-seqcc texture</tt> "
             "without colour correction)." + _PAPER,
        savedir_help="Folder for the textured mesh (mesh_meshlab.ply + texture: the new layer's files, kept), "
                     "mesh.glb, mesh.obj, report.html / report.json and project.mlp, written as a whole. A relative "
                     "path is relative to the project's folder (or, without a project, the current mesh's folder). "
                     "Refused if it exists, unless Overwrite."),
)


def _subparser(command: str) -> argparse.ArgumentParser:
    from o3d_seqcc.cli import build_parser

    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))  # noqa: SLF001
    return sub.choices[command]


def _flag(p: FilterParameter) -> str:
    return "--out" if p.name == "savedir" else "--" + p.keyword.replace("_", "-")


def _kind(p: FilterParameter) -> str:
    if p.name == "reference":
        return "raster"  # an enum of "auto" and the document's rasters
    if p.values:
        return "enum"
    if p.type is int and p.default == "auto":  # a derived default (t_npm): "auto" or a number, typed as text
        return "string"
    return {bool: "bool", int: "int", float: "float"}.get(p.type, "string")


def _default_text(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    return str(value)


def native_filters() -> list[dict[str, Any]]:
    """The plugin's filters as plain data (what the C++ header holds).

    Returns
    -------
    list of dict
        Per filter: ``title``, ``python_name`` (pymeshlab's name of it: the registry's), ``info``,
        ``command``, ``switch``, ``command_off`` and
        ``parameters``: per parameter ``name`` (the pymeshlab-style name, MeshLab's parameter
        name), ``kind`` (``bool``, ``int``, ``float``, ``string``, ``enum``, ``raster``),
        ``label``, ``tooltip`` (the library's description), ``default`` (text), ``values`` (enum
        values), ``flag`` (the command-line option), ``commands`` (the commands that take it) and
        ``keyword`` (the library's name of it, as error messages give it).

    Raises
    ------
    RuntimeError
        A parameter whose option no command of the filter has (the CLI and the registry drifted).
    """
    out = []
    for nf in NATIVE_FILTERS:
        reg = get_filter(nf.registry)
        commands = [c for c in (nf.command, nf.command_off) if c]
        options = {c: {s for a in _subparser(c)._actions for s in a.option_strings} for c in commands}  # noqa: SLF001
        params = []
        for name in nf.parameters:
            p = reg.parameter(name)
            flag = "" if name == nf.switch else _flag(p)
            takes = [c for c in commands if flag in options[c]] if flag else []
            if flag and not takes:
                raise RuntimeError(f"{nf.title}: parameter {name!r}: no {flag} option in o3d-seqcc {' / '.join(commands)}")
            params.append({
                "name": p.name, "kind": _kind(p), "label": p.label,
                "tooltip": nf.savedir_help if name == "savedir" else p.description,
                "default": _default_text(p.default), "values": list(p.values), "flag": flag, "commands": takes,
                "keyword": p.keyword,
            })
        out.append({"title": nf.title, "python_name": nf.registry, "info": nf.info, "command": nf.command,
                    "switch": nf.switch, "command_off": nf.command_off, "parameters": params})
    return out


def cli_arguments(title: str, values: dict[str, Any] | None = None) -> list[str]:
    """The ``o3d-seqcc`` command and options the plugin runs for ``values`` (defaults for the rest).

    The same rule as the C++ plugin's (``filter_o3d_seqcc.cpp``: ``childArguments``), for tests and for
    running a filter's job by hand; the scene argument and ``-v --progress-lines`` are not included.
    ``raster`` parameters take the view name or index as text.
    """
    nf = next((f for f in native_filters() if f["title"] == title), None)
    if nf is None:
        raise KeyError(f"no native filter {title!r}; valid: {', '.join(f.title for f in NATIVE_FILTERS)}")
    values = dict(values or {})
    params = {p["name"]: p for p in nf["parameters"]}
    bad = sorted(set(values) - set(params))
    if bad:
        raise TypeError(f"{title}: unknown parameter(s) {bad}; valid: {', '.join(params)}")

    def value(p):
        v = values.get(p["name"], p["default"])
        return _default_text(v) if not isinstance(v, str) else v

    command = nf["command"]
    if nf["switch"] and value(params[nf["switch"]]) != "true":
        command = nf["command_off"]
    args = [command]
    for p in nf["parameters"]:
        if command not in p["commands"]:
            continue
        v = value(p)
        if p["kind"] == "bool":
            if v == "true":
                args.append(p["flag"])
        else:
            args += [p["flag"], v]
    return args


_RICH = {"bool": "RichBool", "int": "RichInt", "float": "RichFloat", "string": "RichString", "enum": "RichEnum",
         "raster": "RichEnum"}


def filter_script(*steps: tuple[str, dict[str, Any]]) -> str:
    """A MeshLab filter script (``.mlx``) that runs the plugin's filters in order.

    Every parameter is written, in the plugin's order, with its MeshLab type (MeshLab 2020.09's
    ``meshlabserver`` aborts on a script that leaves one out: an assertion in its script runner),
    as MeshLab's own *Save filter script* writes them.

    Parameters
    ----------
    *steps : (str, dict)
        ``(title, values)``: a filter of :data:`NATIVE_FILTERS` and its parameters by name (the
        rest take the library's defaults). Enums take a value or its index; ``reference`` takes
        ``"auto"`` or a raster index (0 = the document's first raster).

    Returns
    -------
    str
        The ``.mlx`` text (``meshlabserver -p project.mlp -s script.mlx -o out.ply -m wt``).
    """
    import xml.etree.ElementTree as ET

    table = {f["title"]: f for f in native_filters()}
    root = ET.Element("FilterScript")
    for title, values in steps:
        if title not in table:
            raise KeyError(f"no native filter {title!r}; valid: {', '.join(table)}")
        params = {p["name"]: p for p in table[title]["parameters"]}
        bad = sorted(set(values) - set(params))
        if bad:
            raise TypeError(f"{title}: unknown parameter(s) {bad}; valid: {', '.join(params)}")
        f = ET.SubElement(root, "filter", name=title)
        for p in table[title]["parameters"]:
            v = values.get(p["name"], p["default"])
            attrs = {"name": p["name"], "type": _RICH[p["kind"]], "description": p["label"], "tooltip": p["tooltip"]}
            if p["kind"] in ("enum", "raster"):
                options = p["values"] if p["kind"] == "enum" else ["auto"]
                if p["kind"] == "raster":
                    index = 0 if v == "auto" else int(v) + 1
                else:
                    index = int(v) if isinstance(v, int) and not isinstance(v, bool) else options.index(v)
                attrs.update(value=str(index), enum_cardinality=str(len(options)),
                             **{f"enum_val{i}": o for i, o in enumerate(options)})
            else:
                attrs["value"] = _default_text(v)
            ET.SubElement(f, "Param", attrs)
    ET.indent(root, space=" ")
    return "<!DOCTYPE FilterScript>\n" + ET.tostring(root, encoding="unicode") + "\n"


def cpp_header() -> str:
    """The C++ header the plugin is built with: :func:`native_filters` as a JSON string literal."""
    text = json.dumps(native_filters(), indent=1, ensure_ascii=True)
    if ")o3dseqcc\"" in text:  # pragma: no cover - the raw string's delimiter
        raise RuntimeError("the filters' text contains the raw-string delimiter")
    return ("// Generated by `python -m meshlab_filters.native header` from the o3d_seqcc library: do not edit.\n"
            "#pragma once\n"
            f"static const char O3D_SEQCC_FILTERS_JSON[] = R\"o3dseqcc({text})o3dseqcc\";\n")


def _value(text: str) -> Any:
    """A ``NAME=VALUE`` value as typed: true/false, an integer, or the text."""
    if text.lower() in ("true", "false"):
        return text.lower() == "true"
    try:
        return int(text)
    except ValueError:
        return text


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(
        prog="python -m meshlab_filters.native", description=__doc__.split("\n\n")[0],
        epilog="examples: python -m meshlab_filters.native header build/o3d_seqcc_filters.h; python -m "
               "meshlab_filters.native script \"Seamless texture from rasters (o3d_seqcc)\" tnpm=100 savedir=textured "
               "> texture.mlx (then: meshlabserver -p /abs/project.mlp -s /abs/texture.mlx -o /abs/out.ply -m wt)")
    p.add_argument("what", choices=("header", "json", "script"),
                   help="the C++ header the plugin is built with, the same as JSON, or a filter script (.mlx)")
    p.add_argument("args", nargs="*", help="header / json: the output file (default: standard output; written only "
                   "when its content changes); script: the filter's name, then its parameters as NAME=VALUE (the rest "
                   "take the library's defaults)")
    args = p.parse_args(argv)
    if args.what == "script":
        if not args.args:
            p.error(f"script: give a filter name: {', '.join(repr(f.title) for f in NATIVE_FILTERS)}")
        values = {}
        for item in args.args[1:]:
            name, sep, value = item.partition("=")
            if not sep:
                p.error(f"script: parameters are NAME=VALUE, got {item!r}")
            values[name] = _value(value)
        try:
            sys.stdout.write(filter_script((args.args[0], values)))
        except (KeyError, TypeError, ValueError) as e:
            p.error(f"script: {e}")
        return 0
    text = cpp_header() if args.what == "header" else json.dumps(native_filters(), indent=1) + "\n"
    if not args.args or args.args[0] == "-":
        sys.stdout.write(text)
        return 0
    out = Path(args.args[0])
    if not out.is_file() or out.read_text(encoding="utf-8") != text:  # unchanged: no rebuild
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(text, encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
