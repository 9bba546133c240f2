"""One settings object for a whole run: the stages' settings and the run's own options.

:class:`RunSettings` holds a :class:`~o3d_seqcc.visibility.settings.VisibilitySettings`, a
:class:`~o3d_seqcc.correction.settings.CorrectionSettings` and a
:class:`~o3d_seqcc.texturing.settings.TextureSettings`, plus what only a run decides (seam metric,
comparison with the uncorrected photos, Table 2 metrics). Every default is its stage class's;
:func:`o3d_seqcc.pipeline.run`, ``texture``, ``correct_scene``, the Open3D front door, the
pymeshlab filters, the MeshLab plugin and the command line all build their options from here::

    import o3d_seqcc as sc
    s = sc.RunSettings.from_options(method="seqcc", max_angle=60, atlas_size=4096)
    res = sc.pipeline.run("scene.json", settings=s)        # the same as run(..., method="seqcc", ...)
    s.correction.method, s.visibility.max_angle, s.texture.atlas_size

Options are given flat (each name belongs to one stage, except ``seed``, which seeds both the
correction and the view selection) or as whole stage objects (``visibility=VisibilitySettings(...)``).
"""

from __future__ import annotations

import inspect
from dataclasses import dataclass, field, replace
from typing import Any, Callable, Mapping

from ._shared.options import SettingsBase, UnknownSettingError, check_names, check_types
from .correction.settings import CorrectionSettings
from .errors import InputError
from .texturing import SELECTION_METHODS
from .texturing.settings import TextureSettings
from .visibility.settings import VisibilitySettings

__all__ = ["CORRECTION_ONLY", "CorrectionSettings", "RunSettings", "TEXTURE_ONLY", "TextureSettings",
           "VisibilitySettings", "keyword_defaults"]

#: the stage fields of :class:`RunSettings` and their classes
STAGES: dict[str, type] = {"visibility": VisibilitySettings, "correction": CorrectionSettings,
                           "texture": TextureSettings}


@dataclass(frozen=True)
class RunSettings(SettingsBase):
    """Everything a run is configured with (:func:`o3d_seqcc.pipeline.run` and the ``run`` command).

    Attributes
    ----------
    visibility : VisibilitySettings, default VisibilitySettings()
        Projection, filters and face split (:func:`~o3d_seqcc.visibility.compute_visibility`).
    correction : CorrectionSettings, default CorrectionSettings()
        Reference, method, ``t_npm``, mapping mode, seed (:func:`~o3d_seqcc.correction.correct`).
    texture : TextureSettings, default TextureSettings()
        View selection, atlas, seam leveling (:func:`~o3d_seqcc.texturing.bake_texture`).
    seams : bool, default True
        Compute the seam metric of the result (``--no-seams`` turns it off).
    compare_original : bool, default False
        Also bake the uncorrected images (in memory) and report their seam metric.
    metrics : bool, default True
        Per-pair PSNR / CIEDE2000 before and after in the report of a correction
        (:func:`~o3d_seqcc.pipeline.correct_scene`; the slowest part; ``--no-metrics`` turns it off).
    """

    _label = "run setting"

    visibility: VisibilitySettings = field(default_factory=VisibilitySettings)
    correction: CorrectionSettings = field(default_factory=CorrectionSettings)
    texture: TextureSettings = field(default_factory=TextureSettings)
    seams: bool = True
    compare_original: bool = False
    metrics: bool = True

    def __post_init__(self) -> None:
        for name, kind in STAGES.items():
            if not isinstance(getattr(self, name), kind):
                raise InputError(f"{name} must be a {kind.__name__}, got {type(getattr(self, name)).__name__}")
        check_types(self)
        if self.texture.selection not in SELECTION_METHODS:
            raise InputError(f"unknown selection method {self.texture.selection!r}; valid: "
                             f"{', '.join(sorted(SELECTION_METHODS))}")

    @classmethod
    def routes(cls) -> dict[str, tuple[str, ...]]:
        """Flat option name -> the stages that hold it (``()``: an option of the run itself).

        ``seed`` is the correction's and the texture's; every other name belongs to one place.
        """
        out: dict[str, tuple[str, ...]] = {}
        for stage, kind in STAGES.items():
            for n in kind.field_names():
                out[n] = out.get(n, ()) + (stage,)
        for n in cls.field_names():
            if n not in STAGES:
                out[n] = ()
        return out

    @classmethod
    def option_names(cls) -> tuple[str, ...]:
        """Every name :meth:`replace` and :meth:`from_options` take (flat names and the stage names), sorted."""
        return tuple(sorted({*cls.routes(), *STAGES}))

    @classmethod
    def check_names(cls, names, *, where: str = "") -> None:
        check_names(names, list(cls.option_names()), label="setting", where=where)

    def replace(self, **changes: Any) -> "RunSettings":
        """A copy with options changed: flat names (``method="seqcc"``, ``max_angle=60``, ``seed=1``) go to
        their stage, stage names (``texture=TextureSettings(...)``) replace a stage; unknown names raise
        :class:`~o3d_seqcc._shared.options.UnknownSettingError` listing the valid ones."""
        type(self).check_names(changes)
        stages = {n: changes[n] for n in STAGES if n in changes}
        own = {n: v for n, v in changes.items() if n in self.field_names() and n not in STAGES}
        base = replace(self, **stages, **own) if stages or own else self
        routes = self.routes()
        per_stage: dict[str, dict[str, Any]] = {}
        for n, v in changes.items():
            for stage in routes.get(n, ()) if n not in STAGES else ():
                per_stage.setdefault(stage, {})[n] = v
        if not per_stage:
            return base
        return replace(base, **{st: getattr(base, st).replace(**kw) for st, kw in per_stage.items()})

    @classmethod
    def resolve(cls, settings: Any = None, options: Mapping[str, Any] | None = None, *, where: str = "",
                exclude: tuple[str, ...] = ()) -> "RunSettings":
        """What an entry point runs with: ``settings`` (a RunSettings, or one stage's settings, which then
        replaces that stage; default the defaults) with the keyword ``options`` given (not None) on top.

        ``exclude``: option names the entry point does not take (``texture`` does not correct).
        """
        if settings is None:
            base = cls()
        elif isinstance(settings, cls):
            base = settings
        else:
            stage = next((n for n, k in STAGES.items() if isinstance(settings, k)), None)
            if stage is None:
                raise InputError(f"{where + ': ' if where else ''}settings must be a RunSettings, "
                                 f"{', '.join(k.__name__ for k in STAGES.values())} or None, got "
                                 f"{type(settings).__name__}")
            base = cls(**{stage: settings})
            if stage == "texture":  # a run's seed seeds its correction too (as seed= does)
                base = replace(base, correction=base.correction.replace(seed=settings.seed))
        given = {k: v for k, v in (options or {}).items() if v is not None}
        cls.check_names(given, where=where)
        off = sorted(set(given) & set(exclude))
        if off:
            raise UnknownSettingError(f"{where + ': ' if where else ''}option(s) {off} do not apply here; valid: "
                                      f"{sorted(set(cls.option_names()) - set(exclude))}")
        return base.replace(**given)


def _only(stage: str, *own: str) -> tuple[str, ...]:
    routes = RunSettings.routes()
    return (*sorted(n for n, st in routes.items() if st == (stage,)), stage, *own)


#: options a texturing without correction (:func:`o3d_seqcc.pipeline.texture`) does not take
CORRECTION_ONLY = _only("correction", "compare_original", "metrics")
#: options a correction without texturing (:func:`o3d_seqcc.pipeline.correct_scene`) does not take
TEXTURE_ONLY = _only("texture", "seams", "compare_original")


def keyword_defaults(fn: Callable) -> dict[str, Any]:
    """The keyword defaults of a library function, so that a front door's defaults are the library's.

    Parameters
    ----------
    fn : callable
        A function or method (``o3d_seqcc.pipeline.RunResult.save``, ``make_synthetic_scene``, ...).

    Returns
    -------
    dict
        Parameter name -> its default, for every parameter of ``fn`` that has one (the command
        line's and the MeshLab filters' defaults of the options that are not settings fields).
    """
    return {n: p.default for n, p in inspect.signature(fn).parameters.items() if p.default is not inspect.Parameter.empty}
