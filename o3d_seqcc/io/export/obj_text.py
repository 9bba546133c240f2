"""The OBJ's text, a whole array at a time: the bytes of Python's ``%d``, ``%.Nf`` and ``%.Ng``, from numpy.

Millions of numbers (the OBJ's ``v`` / ``vt`` / ``vn`` / ``f`` lines) formatted one by one in
Python hold the interpreter for a second (the report's threads wait) and build a Python float
per number; here each column becomes a character matrix with a mask of the characters kept
(:class:`Field`), :func:`rows` joins the fields of every row into one block of bytes, and
:func:`obj_lines` gives an OBJ's lines in chunks (:func:`o3d_seqcc.io.export.obj.export_obj` writes them).

The digits are exactly Python's: a float is scaled by a power of ten (exact up to 10**22) and
rounded to an integer, which is the correctly rounded decimal unless the scaled value lies
within rounding error of a half; those few numbers (and non-finite ones, or precisions beyond
what a float64 integer holds) are formatted by Python itself. ``tests/io/test_export.py``
checks the output against Python's on random and adversarial values.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Iterator

import numpy as np

__all__ = ["OBJ_CHUNK_ROWS", "Field", "const_field", "fixed_field", "general_field", "int_field", "joined", "obj_lines",
           "rows"]

_ZERO, _DOT, _MINUS, _PLUS, _E = 48, 46, 45, 43, 101
#: largest integer a float64 holds exactly (scaled values beyond it are formatted by Python)
_EXACT = float(2 ** 53)


@dataclass(frozen=True)
class Field:
    """One column of text: ``chars`` (n, w) uint8 and ``keep`` (n, w) bool (the characters written, in order)."""

    chars: np.ndarray
    keep: np.ndarray

    def take(self, idx: np.ndarray) -> "Field":
        """The rows ``idx`` (e.g. each face's vertices' texts)."""
        return Field(self.chars[idx], self.keep[idx])

    def __len__(self) -> int:
        return len(self.chars)


def const_field(text: str, n: int) -> Field:
    """The same ASCII ``text`` on each of ``n`` rows."""
    b = np.frombuffer(text.encode("ascii"), dtype=np.uint8)
    return Field(np.broadcast_to(b, (n, len(b))), np.ones((n, len(b)), dtype=bool))


def _digits(k: np.ndarray, width: int) -> np.ndarray:
    """(n, width) uint8 decimal digits of the non-negative int64 ``k`` < 10**18 (most significant first, zero-padded)."""
    out = np.empty((len(k), width), dtype=np.uint8)
    if width > 9:  # two int32 halves: numpy divides int32 by a scalar several times faster than int64
        hi, lo = np.divmod(k, 10 ** 9)
        out[:, :width - 9] = _digits(hi, width - 9)
        out[:, width - 9:] = _digits(lo, 9)
        return out
    k = k.astype(np.int32)
    for j in range(width - 1, -1, -1):  # one division by the scalar 10 per column
        q = k // 10
        out[:, j] = k - 10 * q
        k = q
    return out


def _ndigits(k: np.ndarray) -> np.ndarray:
    """Number of decimal digits of the non-negative int64 ``k`` (1 for 0)."""
    n = np.ones(len(k), dtype=np.int64)
    t = k // 10
    while np.any(t):
        n += t > 0
        t //= 10
    return n


def int_field(a: np.ndarray) -> Field:
    """``"%d" % v`` of every entry of the integer array ``a``."""
    a = np.asarray(a).reshape(-1).astype(np.int64)
    neg = a < 0
    k = np.abs(a)
    w = int(_ndigits(np.array([k.max(initial=0)]))[0])
    nd = _ndigits(k)
    chars = np.concatenate([np.full((len(a), 1), _MINUS, np.uint8), (_digits(k, w) + _ZERO).astype(np.uint8)], axis=1)
    keep = np.concatenate([neg[:, None], np.arange(w)[None, :] >= (w - nd)[:, None]], axis=1)
    return Field(chars, keep)


def _with_python(field_chars: np.ndarray, keep: np.ndarray, idx: np.ndarray, x: np.ndarray, fmt: str) -> Field:
    """``field`` with rows ``idx`` replaced by Python's ``fmt % x[idx]`` (left-aligned, widened when needed)."""
    if len(idx) == 0:
        return Field(field_chars, keep)
    texts = [(fmt % float(v)).encode("ascii") for v in x[idx]]
    w = max(field_chars.shape[1], max(len(t) for t in texts))
    if w > field_chars.shape[1]:
        pad = w - field_chars.shape[1]
        field_chars = np.concatenate([field_chars, np.zeros((len(field_chars), pad), np.uint8)], axis=1)
        keep = np.concatenate([keep, np.zeros((len(keep), pad), bool)], axis=1)
    for i, t in zip(idx, texts):
        field_chars[i] = 0
        field_chars[i, :len(t)] = np.frombuffer(t, np.uint8)
        keep[i] = False
        keep[i, :len(t)] = True
    return Field(field_chars, keep)


#: the powers of ten a float64 holds exactly
_POW10 = 10.0 ** np.arange(23)


def _scaled(a: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``a * 10**s`` with one rounding (a product, or a quotient for s < 0, by an exact power), and where |s| > 22."""
    far = np.abs(s) > 22
    m = a * _POW10[np.clip(s, 0, 22)]
    down = np.flatnonzero(s < 0)
    if len(down):
        m[down] = a[down] / _POW10[np.clip(-s[down], 0, 22)]
    return m, far


def _rounded(m: np.ndarray, tol: float) -> tuple[np.ndarray, np.ndarray]:
    """``rint(m)`` as int64, and where that may not be the correctly rounded value: within ``tol`` of a half (the
    error of ``m``), or not an exact float64 integer."""
    unsure = (np.abs(m - np.floor(m) - 0.5) < tol) | ~(m < _EXACT)
    return np.rint(np.where(unsure, 0.0, m)).astype(np.int64), unsure


def _tolerance(top: float) -> float:
    """Twice the spacing of float64 numbers below ``top`` (at least 1e-6): the error bound of one rounding."""
    return max(1e-6, 2.0 * float(np.spacing(np.float64(top))))


def fixed_field(x: np.ndarray, decimals: int) -> Field:
    """``"%.{decimals}f" % v`` of every entry of the float array ``x``."""
    with np.errstate(all="ignore"):  # non-finite values: Python's text
        return _fixed(x, decimals)


def _fixed(x: np.ndarray, decimals: int) -> Field:
    x = np.asarray(x, dtype=np.float64).reshape(-1)
    d = int(decimals)
    finite = np.isfinite(x)
    a = np.where(finite, np.abs(x), 0.0)
    m = a * 10.0 ** d if d <= 22 else a * np.inf
    k, unsure = _rounded(m, _tolerance(float(m.max(initial=0.0))))
    unsure |= ~finite
    k = np.where(unsure, 0, k)
    ip, fp = k // 10 ** d, k % 10 ** d
    w = int(_ndigits(np.array([ip.max(initial=0)]))[0])
    nd = _ndigits(ip)
    chars = np.concatenate([np.full((len(x), 1), _MINUS, np.uint8), (_digits(ip, w) + _ZERO).astype(np.uint8),
                            np.full((len(x), 1 if d else 0), _DOT, np.uint8), (_digits(fp, d) + _ZERO).astype(np.uint8)],
                           axis=1)
    keep = np.concatenate([np.signbit(x)[:, None], np.arange(w)[None, :] >= (w - nd)[:, None],
                           np.ones((len(x), (1 if d else 0) + d), bool)], axis=1)
    return _with_python(chars, keep, np.flatnonzero(unsure), x, f"%.{d}f")


def general_field(x: np.ndarray, precision: int) -> Field:
    """``"%.{precision}g" % v`` of every entry of the float array ``x`` (precision 1-15; beyond, Python's)."""
    with np.errstate(all="ignore"):  # non-finite values: Python's text
        return _general(x, precision)


def _general(x: np.ndarray, precision: int) -> Field:
    x = np.asarray(x, dtype=np.float64).reshape(-1)
    P = int(precision)
    n = len(x)
    if not 1 <= P <= 15:
        return _with_python(np.zeros((n, 0), np.uint8), np.zeros((n, 0), bool), np.arange(n), x, f"%.{P}g")
    finite = np.isfinite(x)
    zero = x == 0
    a = np.where(finite & ~zero, np.abs(x), 1.0)
    e = np.floor(np.log10(a)).astype(np.int64)
    tol = _tolerance(10.0 ** P)
    m, far = _scaled(a, P - 1 - e)
    k, unsure = _rounded(m, tol)
    for _ in range(2):  # the exponent of the value rounded to P digits (log10 may be one off near a power of ten)
        off = np.flatnonzero((k >= 10 ** P) | (k < 10 ** (P - 1)))
        if len(off) == 0:
            break
        e[off] += np.where(k[off] >= 10 ** P, 1, -1)
        m_off, far[off] = _scaled(a[off], P - 1 - e[off])
        k[off], unsure[off] = _rounded(m_off, tol)
    unsure |= far | ~finite | (k >= 10 ** P) | (k < 10 ** (P - 1))
    k = np.where(unsure, 10 ** (P - 1), k)
    k[zero] = 0
    e[zero] = 0
    fixed = (e >= -4) & (e < P)
    if np.count_nonzero(~fixed) * 20 < n:  # a few numbers in scientific notation: Python's
        unsure |= ~fixed
        fixed[:] = True
    dg = _digits(k, P)
    nz = np.where(zero, 1, P - np.argmax(dg[:, ::-1] != 0, axis=1)).astype(np.int8)[:, None]  # without trailing zeros
    e8 = np.where(fixed, np.clip(e, -5, P), 0).astype(np.int8)[:, None]
    # fixed notation: the digits after four zeros ("0000" + the P digits) with a point after each, the integer part
    # and the fraction (to its last non-zero digit) kept, the point after the integer part when a fraction follows;
    # scientific: the first digit, its point, the others; then "e", the exponent's sign and its 2-3 digits
    sci = ~fixed
    W = 2 * (P + 4) + (5 if sci.any() else 0)
    chars = np.empty((n, 1 + W), dtype=np.uint8)
    keep = np.empty((n, 1 + W), dtype=bool)
    chars[:, 0] = _MINUS
    keep[:, 0] = np.signbit(x)
    body, bkeep = chars[:, 1:1 + 2 * (P + 4)], keep[:, 1:1 + 2 * (P + 4)]
    body[:, 0:8:2] = _ZERO
    body[:, 8::2] = dg + _ZERO
    body[:, 1::2] = _DOT
    q = np.arange(P + 4, dtype=np.int8)[None, :]
    first = np.where(sci[:, None], 4, np.minimum(e8 + 4, 4))  # the first digit written
    last = np.where(sci[:, None], 4 + nz - 1, np.maximum(e8 + 4, 3 + nz))  # the last one
    bkeep[:, 0::2] = (q >= first) & (q <= last)
    point = np.where(sci[:, None], 4, e8 + 4)
    bkeep[:, 1::2] = (q == point) & (last > point)
    if sci.any():
        ae = np.abs(e)
        chars[:, -5:] = np.stack([np.full(n, _E), np.where(e < 0, _MINUS, _PLUS), ae // 100 + _ZERO,
                                  ae // 10 % 10 + _ZERO, ae % 10 + _ZERO], axis=1)
        keep[:, -5:] = sci[:, None]
        keep[:, -3] &= ae >= 100
    return _with_python(chars, keep, np.flatnonzero(unsure), x, f"%.{P}g")


def joined(fields: list[Field | str]) -> Field:
    """One field of the fields (and ASCII constants, the same on every row) one after the other."""
    n = next(len(f) for f in fields if isinstance(f, Field))
    parts = [const_field(f, n) if isinstance(f, str) else f for f in fields]
    return Field(np.concatenate([f.chars for f in parts], axis=1), np.concatenate([f.keep for f in parts], axis=1))


def rows(fields: list[Field | str]) -> bytes:
    """The rows' text: each row's fields (and ASCII constants) one after the other, rows one after the other."""
    f = joined(fields)
    return f.chars[f.keep].tobytes()


#: rows of OBJ text formatted at a time (a few megabytes of characters in flight)
OBJ_CHUNK_ROWS = 1 << 16


def obj_lines(verts: np.ndarray, vt: np.ndarray, normals: np.ndarray, faces: np.ndarray, face_page: np.ndarray,
              pages: int, *, digits: int = 9) -> Iterator[bytes]:
    """The ``v`` / ``vt`` / ``vn`` lines, then per page ``usemtl`` and its ``f a/a/a b/b/b c/c/c`` lines, in chunks.

    The bytes of Python's ``"v %.{digits}g %.{digits}g %.{digits}g"``, ``"vt %.7f %.7f"``, ``"vn %.5f %.5f %.5f"``
    and ``"f %d/%d/%d ..."`` (1-based), formatted by numpy without holding the interpreter: every vertex's
    ``i/i/i`` once, each face its three vertices' texts; :data:`OBJ_CHUNK_ROWS` rows at a time.

    Parameters
    ----------
    verts : (M, 3) float64
    vt : (M, 2) float64
        Texture coordinates (on their page).
    normals : (M, 3) float64
    faces : (F, 3) int64
        0-based vertex indices.
    face_page : (F,) int
        Page of each face (faces are written page by page, each after its ``usemtl material_<page>``).
    pages : int
    digits : int, default 9
        Significant digits of the positions.
    """
    for prefix, a, field in (("v", verts, lambda c: general_field(c, digits)), ("vt", vt, lambda c: fixed_field(c, 7)),
                             ("vn", normals, lambda c: fixed_field(c, 5))):
        for r in range(0, len(a), OBJ_CHUNK_ROWS):
            block = a[r:r + OBJ_CHUNK_ROWS]
            yield rows([prefix] + [f for c in range(block.shape[1]) for f in (" ", field(block[:, c]))] + ["\n"])
    ids = int_field(np.arange(1, len(verts) + 1))
    token = joined([" ", ids, "/", ids, "/", ids])  # " i/i/i" of every vertex
    for p in range(pages):  # faces grouped by page, one material each
        yield f"usemtl material_{p}\n".encode("ascii")
        fp = faces[face_page == p]
        for r in range(0, len(fp), OBJ_CHUNK_ROWS):
            block = fp[r:r + OBJ_CHUNK_ROWS]
            yield rows(["f", token.take(block[:, 0]), token.take(block[:, 1]), token.take(block[:, 2]), "\n"])
