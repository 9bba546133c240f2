"""HTML pieces shared by the report's sections: escaping, embedded images, numbers."""

from __future__ import annotations

import base64
import html
from typing import Any

__all__ = ["esc", "img", "num"]


def esc(x: Any) -> str:
    """``x`` as HTML text (quotes escaped too)."""
    return html.escape(str(x), quote=True)


def img(data: bytes, mime: str, alt: str, cls: str = "") -> str:
    """An ``<img>`` with the image embedded as a base64 data URI."""
    c = f' class="{cls}"' if cls else ""
    return f'<img{c} src="data:{mime};base64,{base64.b64encode(data).decode("ascii")}" alt="{esc(alt)}">'


def num(x: Any, digits: int = 2) -> str:
    """A number with ``digits`` decimals (floats), as text otherwise, an en dash for None."""
    return "–" if x is None else (f"{x:.{digits}f}" if isinstance(x, float) else esc(x))
