"""The files the CLI writes beside the one the user named, and the rule that protects the
rest: a PNG is written next to the EXR (`-o x.exr` → `x.png`), but a file already there is
replaced only if GDMLT wrote it (its PNG tEXt chunk Software=GDMLT). A scene's texture that
happens to share the output's name is never overwritten."""

import struct
import sys
import zlib
from pathlib import Path

MARK = b"tEXtSoftware\x00GDMLT"


def written_by_gdmlt(path: Path) -> bool:
    """Whether `path` is a PNG that GDMLT wrote."""
    try:
        with open(path, "rb") as f:
            head = f.read(65536)
    except OSError:
        return False
    return head.startswith(b"\x89PNG") and MARK in head


def png_beside(out: Path, warn=None):
    """The PNG path to write next to the EXR `out`, or None (with a warning) when a file there
    was not written by GDMLT."""
    png = Path(out).with_suffix(".png")
    if png.exists() and not written_by_gdmlt(png):
        (warn or (lambda m: print(f"gdmlt: warning: {m}", file=sys.stderr)))(
            f"not replacing {png}: GDMLT did not write it; only the EXR was written (or use another -o)")
        return None
    return png


def mark_png(path: Path):
    """Adds the Software=GDMLT tEXt chunk to a PNG written by someone else for GDMLT (Blender's
    save_render), right after its IHDR chunk."""
    data = Path(path).read_bytes()
    if not data.startswith(b"\x89PNG") or MARK in data[:65536]:
        return
    ihdr_end = 8 + 4 + 4 + 13 + 4
    body = MARK[4:]
    chunk = struct.pack(">I", len(body)) + MARK + struct.pack(">I", zlib.crc32(MARK) & 0xFFFFFFFF)
    Path(path).write_bytes(data[:ihdr_end] + chunk + data[ihdr_end:])


def with_alpha(layers: dict):
    """The Combined image, as RGBA when the render has an "Alpha" layer (a transparent film:
    the colour is premultiplied, as Blender's and Cycles' EXRs), else RGB."""
    import numpy as np

    c = layers["Combined"]
    a = layers.get("Alpha")
    if a is None:
        return c
    return np.ascontiguousarray(np.concatenate([c[..., :3], a[..., :1]], axis=2), dtype=np.float32)
