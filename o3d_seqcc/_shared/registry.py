"""One registry of named methods (colour-science's ``*_METHODS`` tables with one dispatcher).

Every method table of the package is a :class:`Registry`: the correction methods
(:data:`o3d_seqcc.correction.METHODS`), the colour mapping functions
(:data:`o3d_seqcc.correction.cmf.CMF_METHODS`), the view selections
(:data:`o3d_seqcc.texturing.SELECTION_METHODS`), the scene formats
(:data:`o3d_seqcc.io.load.SCENE_FORMATS`) and the pymeshlab-style filters
(:mod:`o3d_seqcc.meshlab_filters`). Each is written out literally where it is defined (name ->
function), never filled by importing a module for its side effects; users add theirs with
:meth:`Registry.register`. An unknown name or option raises :class:`~o3d_seqcc.errors.InputError`
naming the kind of entry, the bad name and the valid names, sorted.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable, Iterable, Iterator, Mapping, MutableMapping
from typing import Any, Generic, TypeVar

from ..errors import InputError

__all__ = ["Registry", "UnknownNameError", "UnknownOptionError", "accepted_options"]

T = TypeVar("T")
_MISSING: Any = object()


class UnknownNameError(InputError, KeyError):
    """A name the registry does not hold (an :class:`InputError`, and a ``KeyError`` for mapping code)."""

    __str__ = BaseException.__str__  # KeyError would quote the message


class UnknownOptionError(InputError, TypeError):
    """An option the entry does not take (an :class:`InputError`, and the ``TypeError`` of a bad keyword)."""


def accepted_options(fn: Callable) -> tuple[str, ...] | None:
    """Sorted keyword-only parameter names of ``fn``, or None when it takes ``**kwargs`` (anything)."""
    try:
        params = inspect.signature(fn).parameters
    except (TypeError, ValueError):
        return None
    if any(p.kind == inspect.Parameter.VAR_KEYWORD for p in params.values()):
        return None
    return tuple(sorted(n for n, p in params.items() if p.kind == inspect.Parameter.KEYWORD_ONLY))


class Registry(MutableMapping, Generic[T]):
    """A table ``name -> entry`` of one kind of method, with the package's error messages.

    Parameters
    ----------
    kind : str
        What an entry is, for messages: ``"correction method"``, ``"CMF method"``, ...
    entries : mapping of str to entry, optional
        The built-in entries, written out where the table is defined.
    options : mapping of str to iterable of str, optional
        Per entry, the options it accepts (default: an entry's keyword-only parameters).
    info : mapping of str to dict, optional
        Per entry, facts its dispatcher reads (e.g. ``{"needs_graph": False}``); see :meth:`info`.

    Notes
    -----
    A registry is a mutable mapping (``name in R``, ``R[name]``, ``sorted(R)``, ``R[name] = fn``):
    ``R[name]`` and :meth:`get` raise :class:`UnknownNameError` (an ``InputError`` and a
    ``KeyError``) listing the valid names.
    """

    def __init__(self, kind: str, entries: Mapping[str, T] | None = None, *,
                 options: Mapping[str, Iterable[str]] | None = None, info: Mapping[str, dict] | None = None) -> None:
        self.kind = str(kind)
        self._entries: dict[str, T] = dict(entries or {})
        self._options: dict[str, tuple[str, ...]] = {k: tuple(sorted(v)) for k, v in (options or {}).items()}
        self._info: dict[str, dict] = {k: dict(v) for k, v in (info or {}).items()}

    # ---- mapping ---------------------------------------------------------------------------

    def __getitem__(self, name: str) -> T:
        try:
            return self._entries[name]
        except (KeyError, TypeError):
            raise UnknownNameError(self._unknown(name)) from None

    def __setitem__(self, name: str, entry: T) -> None:
        self._entries[str(name)] = entry

    def __delitem__(self, name: str) -> None:
        self[name]  # noqa: B018 (the message for an unknown name)
        del self._entries[name]
        self._options.pop(name, None)
        self._info.pop(name, None)

    def __iter__(self) -> Iterator[str]:
        return iter(self._entries)

    def __len__(self) -> int:
        return len(self._entries)

    def __contains__(self, name: object) -> bool:
        return name in self._entries

    def __repr__(self) -> str:
        return f"Registry({self.kind!r}, {self.names()})"

    # ---- the registry ----------------------------------------------------------------------

    def names(self) -> list[str]:
        """Sorted names of the entries."""
        return sorted(self._entries)

    list = names  # ``R.list()``: the same sorted names

    def register(self, name: str, entry: T | None = None, *, options: Iterable[str] | None = None, **info: Any):
        """Add (or replace) the entry ``name``.

        ``R.register("mine", fn)`` registers ``fn`` and returns it; ``@R.register("mine")`` as a
        decorator does the same. ``options`` lists the options the entry accepts (default: its
        keyword-only parameters); further keywords are stored as its :meth:`info`.
        """
        if not isinstance(name, str) or not name:
            raise InputError(f"a {self.kind} needs a non-empty string name, got {name!r}")

        def add(fn: T) -> T:
            self._entries[name] = fn
            if options is None:
                self._options.pop(name, None)
            else:
                self._options[name] = tuple(sorted(options))
            self._info[name] = dict(info)
            return fn

        return add if entry is None else add(entry)

    def get(self, name: str, default: Any = _MISSING) -> T:
        """The entry ``name``; an unknown name raises :class:`UnknownNameError` unless ``default`` is given."""
        if default is not _MISSING and name not in self._entries:
            return default
        return self[name]

    def check(self, name: str) -> None:
        """Raise :class:`UnknownNameError` (an :class:`InputError`) for a name the registry does not hold."""
        self[name]  # noqa: B018

    def info(self, name: str) -> dict:
        """The facts registered with the entry (``{}`` when none)."""
        self.check(name)
        return dict(self._info.get(name, {}))

    def options(self, name: str) -> tuple[str, ...] | None:
        """Sorted options the entry accepts, None when it accepts any (``**kwargs``)."""
        entry = self[name]
        if name in self._options:
            return self._options[name]
        return accepted_options(entry) if callable(entry) else ()

    def check_options(self, name: str, options: Iterable[str], *, what: str = "option") -> None:
        """Raise :class:`UnknownOptionError` (an :class:`InputError`) naming the options ``name`` does not take
        and the ones it does."""
        allowed = self.options(name)
        if allowed is None:
            return
        bad = sorted(set(options) - set(allowed))
        if bad:
            raise UnknownOptionError(f"{self.kind} {name!r} does not take {what}{'s' if len(bad) > 1 else ''} "
                                     f"{', '.join(map(repr, bad))}; valid: {', '.join(allowed) or '(none)'}")

    def _unknown(self, name: object) -> str:
        return f"unknown {self.kind} {name!r}; valid: {', '.join(self.names())}"
