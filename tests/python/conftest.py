import os
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
# the benchmarks' package (benchmarks/gdmlt_bench: Cycles as a reference, the peer
# translations) is not part of gdmlt; the tests that need it import it from the checkout
sys.path.insert(0, str(ROOT / "benchmarks"))
os.environ.setdefault("BLENDER_USER_RESOURCES", str(Path(tempfile.gettempdir()) / "gdmlt-test-blender-user"))


def read_exr(path, channel="RGB"):
    import OpenEXR

    with OpenEXR.File(str(path)) as f:
        ch = f.channels()
        key = channel if channel in ch else ("RGBA" if channel == "RGB" and "RGBA" in ch else channel)
        px = np.asarray(ch[key].pixels, dtype=np.float32)
    return px[..., :3] if px.ndim == 3 and key == "RGBA" and channel == "RGB" else px


def block_means(img, b):
    h, w = img.shape[0] // b * b, img.shape[1] // b * b
    x = img[:h, :w].astype(np.float64)
    return x.reshape(h // b, b, w // b, b, -1).mean(axis=(1, 3))


@pytest.fixture(scope="session")
def bpy_mod():
    """bpy with the GDMLT addon registered (once per test session)."""
    from gdmlt.blend import import_bpy
    import gdmlt

    bpy = import_bpy()
    gdmlt.enable_addon()
    return bpy


@pytest.fixture
def tmp_out(tmp_path):
    return tmp_path
