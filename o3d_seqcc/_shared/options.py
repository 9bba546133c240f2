"""What every settings object of the library shares (mvs-texturing's one ``Settings`` struct, per stage).

The settings classes (:class:`~o3d_seqcc.visibility.settings.VisibilitySettings`,
:class:`~o3d_seqcc.correction.settings.CorrectionSettings`,
:class:`~o3d_seqcc.texturing.settings.TextureSettings`, :class:`~o3d_seqcc.settings.RunSettings`)
are frozen dataclasses that derive from :class:`SettingsBase`: the default of an option is written
once, as the field's default, and every entry point builds its options from the class
(:meth:`SettingsBase.resolve`). A wrong value raises :class:`~o3d_seqcc.errors.InputError`
naming the field and its valid values; an unknown name raises :class:`UnknownSettingError`
(an ``InputError`` and a ``TypeError``, as Python's own unknown keywords) listing the valid ones.
"""

from __future__ import annotations

import difflib
from dataclasses import fields, replace
from typing import Any, ClassVar, Iterable, Mapping, TypeVar

import numpy as np

from ..errors import InputError

__all__ = ["SettingsBase", "UnknownSettingError", "check_choice", "check_names", "check_types"]

S = TypeVar("S", bound="SettingsBase")


class UnknownSettingError(InputError, TypeError):
    """An option name no settings object has (a ``TypeError``, as an unknown keyword argument is)."""


def check_names(names: Iterable[str], valid: list[str], *, label: str, where: str = "") -> None:
    """Raise :class:`UnknownSettingError` for the ``names`` not in ``valid``: each with its closest valid name,
    then the valid ones (in the order given)."""
    bad = sorted(set(names) - set(valid))
    if bad:
        close = {b: difflib.get_close_matches(b, valid, n=1) for b in bad}
        hint = "; ".join(f"did you mean {c[0]!r} for {b!r}?" for b, c in close.items() if c)
        raise UnknownSettingError(f"{where + ': ' if where else ''}unknown {label}(s) {bad}"
                                  f"{' (' + hint + ')' if hint else ''}; valid: {list(valid)}")


class SettingsBase:
    """Mixin of the frozen settings dataclasses: field names and defaults, checked copies, keyword resolution."""

    #: how messages call one field ("visibility setting")
    _label: ClassVar[str] = "setting"

    @classmethod
    def field_names(cls) -> tuple[str, ...]:
        """The fields, in declaration order."""
        return tuple(f.name for f in fields(cls))  # type: ignore[arg-type]

    @classmethod
    def defaults(cls) -> dict[str, Any]:
        """``field -> default`` (of a default-constructed object)."""
        d = cls()
        return {n: getattr(d, n) for n in cls.field_names()}

    @classmethod
    def check_names(cls, names: Iterable[str], *, where: str = "") -> None:
        """Raise :class:`UnknownSettingError` for names that are not fields, listing the valid ones."""
        check_names(names, sorted(cls.field_names()), label=cls._label, where=where)

    def replace(self: S, **changes: Any) -> S:
        """A copy with some fields changed (validated); unknown names raise :class:`UnknownSettingError`."""
        type(self).check_names(changes)
        return replace(self, **changes) if changes else self  # type: ignore[type-var]

    @classmethod
    def from_options(cls: type[S], **options: Any) -> S:
        """The defaults with ``options`` changed (``VisibilitySettings.from_options(max_angle=60)``)."""
        return cls().replace(**options)

    @classmethod
    def resolve(cls: type[S], settings: Any = None, options: Mapping[str, Any] | None = None, *,
                where: str = "") -> S:
        """What an entry point runs with: ``settings`` (default: the defaults) with the keyword ``options``
        given (not None) on top. ``settings`` of another type raises ``InputError``."""
        if settings is not None and not isinstance(settings, cls):
            raise InputError(f"{where + ': ' if where else ''}settings must be a {cls.__name__} or None, got "
                             f"{type(settings).__name__}")
        given = {k: v for k, v in (options or {}).items() if v is not None}
        cls.check_names(given, where=where)
        base = settings if settings is not None else cls()
        return base.replace(**given)

    def to_dict(self) -> dict[str, Any]:
        """``field -> value`` (nested settings as dicts), for reports."""
        out = {}
        for n in self.field_names():
            v = getattr(self, n)
            out[n] = v.to_dict() if isinstance(v, SettingsBase) else (list(v) if isinstance(v, tuple) else v)
        return out


def check_choice(name: str, value: Any, valid: Iterable[str], *, flag: str = "") -> None:
    """Raise ``InputError`` unless ``value`` is one of ``valid`` (the message names the field and lists them)."""
    valid = tuple(valid)
    if not isinstance(value, str) or value not in valid:
        raise InputError(f"unknown {name}{f' ({flag})' if flag else ''} {value!r}; valid: "
                         f"{', '.join(map(repr, valid))}")


def _is_int(v: Any) -> bool:
    return isinstance(v, (int, np.integer)) and not isinstance(v, (bool, np.bool_))


_TYPES = {"int": (_is_int, "an integer"),
          "float": (lambda v: _is_int(v) or isinstance(v, (float, np.floating)), "a number"),
          "bool": (lambda v: isinstance(v, (bool, np.bool_)) or _is_int(v) and v in (0, 1), "True or False"),
          "str": (lambda v: isinstance(v, str), "a string")}


def check_types(settings: Any) -> None:
    """Every field of the simple type it is declared with (``padding="big"`` names the field, not ``int()``)."""
    for f in fields(settings):
        kind = _TYPES.get(str(f.type))
        v = getattr(settings, f.name)
        if kind is not None and not kind[0](v):
            raise InputError(f"{f.name} must be {kind[1]}, got {v!r:.60} ({type(v).__name__})")
