"""What a file's first bytes promise, checked before anything is decoded or allocated.

Pure functions over bytes (or a binary file object): the structure of JPEG and PNG files (is the
main image complete?), the size an OpenEXR header declares, and the element counts of PLY, OFF
and binary STL headers against the file's size. The file layer (:mod:`o3d_seqcc.io.raster_checks`,
:mod:`o3d_seqcc.io.images`, :mod:`o3d_seqcc.io.depth`, :mod:`o3d_seqcc.io.mesh_files`) calls them before it
hands a file to a decoder (OpenCV, Pillow, Open3D), so that a cut or hostile file is an error
naming it, never a grey half-image, a multi-gigabyte allocation or a ``MemoryError``.
"""

from __future__ import annotations

import re
import struct
from typing import BinaryIO

__all__ = ["exr_size", "jpeg_complete", "jpeg_precision", "jpeg_scan_offset", "mesh_header_problem", "png_complete"]

_JPEG_STANDALONE = {0x01, 0xD8} | set(range(0xD0, 0xD8))


def jpeg_scan_offset(f: BinaryIO) -> int | None:
    """Offset of the main image's first start-of-scan (SOS) marker, walking the segments from the start.

    Segments before the scan (APPn with an EXIF thumbnail, ICC profiles, tables) are skipped by
    their lengths, so nothing inside them (a thumbnail's own end-of-image marker) is taken for
    the main image's. None when the file ends (or is not a JPEG) before a scan starts.
    """
    f.seek(0)
    if f.read(2) != b"\xff\xd8":
        return None
    pos = 2
    while True:
        f.seek(pos)
        b = f.read(2)
        if len(b) < 2 or b[0] != 0xFF:
            return None
        marker = b[1]
        if marker == 0xFF:  # fill byte
            pos += 1
            continue
        if marker in _JPEG_STANDALONE:
            pos += 2
            continue
        if marker == 0xD9:  # end of image before any scan
            return None
        ln = f.read(2)
        if len(ln) < 2:
            return None
        if marker == 0xDA:
            return pos
        pos += 2 + int.from_bytes(ln, "big")


def jpeg_complete(f: BinaryIO, size: int, *, tail: int | None = 65536) -> bool:
    """The main image of a JPEG ends with its end-of-image marker (EOI) after its first scan.

    Inside the entropy-coded data every 0xFF byte is followed by 0x00 or a restart marker, so
    the first ``FF D9`` after the main image's first scan is its EOI. ``tail``: look only at the
    last ``tail`` bytes (a header-only check: an image followed by more than ``tail`` bytes of
    other data, e.g. an appended multi-picture image, is then judged by that data's end); None
    reads from the scan to the end.
    """
    sos = jpeg_scan_offset(f)
    if sos is None:
        return False
    start = sos + 2 if tail is None else max(sos + 2, size - int(tail))
    f.seek(start)
    return b"\xff\xd9" in f.read()


_JPEG_SOF = {0xC0, 0xC1, 0xC2, 0xC3, 0xC5, 0xC6, 0xC7, 0xC9, 0xCA, 0xCB, 0xCD, 0xCE, 0xCF}


def jpeg_precision(head: bytes) -> int | None:
    """Sample precision (bits) from a JPEG's start-of-frame segment, None when not found."""
    i = 2
    while i + 4 <= len(head):
        if head[i] != 0xFF:
            return None
        marker = head[i + 1]
        if marker == 0xFF:  # fill byte
            i += 1
            continue
        if marker in (0xD8, 0x01) or 0xD0 <= marker <= 0xD7:
            i += 2
            continue
        length = int.from_bytes(head[i + 2:i + 4], "big")
        if marker in _JPEG_SOF:
            return head[i + 4] if i + 4 < len(head) else None
        i += 2 + length
    return None


def png_complete(f: BinaryIO, size: int) -> bool:
    """A PNG's chunks, followed by their lengths from the signature, reach the IEND chunk inside the file."""
    f.seek(0)
    if f.read(8) != b"\x89PNG\r\n\x1a\n":
        return False
    pos = 8
    while pos + 12 <= size:
        f.seek(pos)
        head = f.read(8)
        if len(head) < 8:
            return False
        length = int.from_bytes(head[:4], "big")
        if head[4:8] == b"IEND":
            return True
        pos += 12 + length
    return False


def png_exif(f: BinaryIO) -> bytes | None:
    """The payload of a PNG's ``eXIf`` chunk (None without one), from the chunk headers alone.

    Pillow finds an ``eXIf`` chunk that follows the image data only by decoding the image
    (``PngImageFile.getexif`` loads it): half a second per 6 MP photo, on every read. Walking
    the chunks' 8-byte headers (seeking over ``IDAT``) finds it without decoding.
    """
    f.seek(8)
    while True:
        head = f.read(8)
        if len(head) < 8:
            return None
        n, kind = struct.unpack(">I4s", head)
        if kind == b"eXIf":
            return f.read(n)
        if kind == b"IEND":
            return None
        f.seek(n + 4, 1)


def exr_size(head: bytes) -> tuple[int, int] | None:
    """(width, height) of an OpenEXR file from its header's ``dataWindow`` (box2i), None if not found."""
    if not head.startswith(b"\x76\x2f\x31\x01") or len(head) < 8:
        return None
    pos = 8
    while pos < len(head):
        end = head.find(b"\0", pos)
        if end < 0 or end == pos:
            return None
        name = head[pos:end]
        tend = head.find(b"\0", end + 1)
        if tend < 0 or tend + 5 > len(head):
            return None
        n = struct.unpack("<i", head[tend + 1:tend + 5])[0]
        value = head[tend + 5:tend + 5 + n]
        if name == b"dataWindow" and n == 16 and len(value) == 16:
            x0, y0, x1, y1 = struct.unpack("<4i", value)
            return max(0, x1 - x0 + 1), max(0, y1 - y0 + 1)
        pos = tend + 5 + n
    return None


_PLY_SIZES = {"char": 1, "int8": 1, "uchar": 1, "uint8": 1, "short": 2, "int16": 2, "ushort": 2, "uint16": 2,
              "int": 4, "int32": 4, "uint": 4, "uint32": 4, "float": 4, "float32": 4, "double": 8, "float64": 8}


def _ply_problem(head: bytes, size: int) -> str | None:
    end = head.find(b"end_header")
    if end < 0:
        return None if len(head) < size else "its header has no end_header line"
    body = size - (head.find(b"\n", end) + 1 if head.find(b"\n", end) >= 0 else end + 10)
    fmt, elements = None, []
    for line in head[:end].decode("latin-1").splitlines():
        w = line.split()
        if not w or w[0] in ("comment", "obj_info"):
            continue
        if w[0] == "format" and len(w) >= 2:
            fmt = w[1]
        elif w[0] == "element" and len(w) >= 3:
            try:
                count = int(w[2])
            except ValueError:
                return f"its header declares a non-integer count {w[2]!r} of {w[1]}"
            if count < 0:
                return f"its header declares {count} {w[1]} elements"
            elements.append([w[1], count, 0, 0])  # name, count, min bytes (binary), properties
        elif w[0] == "property" and elements:
            el = elements[-1]
            el[3] += 1
            if len(w) >= 5 and w[1] == "list":
                el[2] += _PLY_SIZES.get(w[2], 1)  # an empty list still holds its count
            elif len(w) >= 3:
                el[2] += _PLY_SIZES.get(w[1], 1)
    need = 0
    for name, count, nbytes, nprops in elements:
        per = nbytes if fmt and fmt.startswith("binary") else max(1, 2 * nprops)  # ascii: "0 0 0\n"
        need += count * per
        if need > body:
            return (f"its header declares {count} {name} elements (at least {count * per} bytes) but the file holds "
                    f"{max(body, 0)} bytes after the header")
    return None


def _off_problem(head: bytes, size: int) -> str | None:
    text = head[:4096].decode("latin-1")
    nums = re.findall(r"^\s*(\d+)\s+(\d+)(?:\s+(\d+))?\s*$", "\n".join(
        ln.split("#", 1)[0] for ln in text.splitlines()[1:12]), flags=re.M)
    if not nums:
        return None
    nv, nf = int(nums[0][0]), int(nums[0][1])
    if nv * 6 + nf * 8 > size:
        return f"its header declares {nv} vertices and {nf} faces, more than its {size} bytes can hold"
    return None


def _stl_problem(head: bytes, size: int) -> str | None:
    if size < 84 or head[:5].lower() == b"solid" and b"facet" in head[:4096].lower():
        return None
    n = struct.unpack("<I", head[80:84])[0]
    if 84 + 50 * n != size:
        return f"as a binary STL it declares {n} triangles ({84 + 50 * n} bytes) but the file holds {size} bytes"
    return None


def mesh_header_problem(head: bytes, size: int, suffix: str) -> str | None:
    """What is wrong with a mesh / point-cloud file's header, or None.

    Parameters
    ----------
    head : bytes
        The file's first bytes (64 KB is plenty for a header).
    size : int
        The file's size in bytes.
    suffix : str
        Its lower-case suffix (``.ply``, ``.off``, ``.stl``, ...); the content decides when it has
        a known signature.

    Returns
    -------
    str or None
        E.g. ``"its header declares 2000000000 vertex elements (at least 24000000000 bytes) but
        the file holds 74 bytes after the header"``: counts no file of this size can hold, which
        readers would otherwise try to allocate.
    """
    if head.startswith(b"ply"):
        return _ply_problem(head, size)
    if head.lstrip()[:3] in (b"OFF", b"COF", b"NOF") or suffix == ".off":
        return _off_problem(head, size)
    if suffix == ".stl":
        return _stl_problem(head, size)
    return None
