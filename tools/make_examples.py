"""Writes examples/cornell.blend from the core's built-in Cornell box arrays, so that the
demo file and `gdmlt render cornell` are the same scene (one definition, in Rust).

Run with the project venv: .venv/bin/python tools/make_examples.py
"""

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def build_cornell(bpy, gdmlt, width=256, height=256):
    from gdmlt import blendscene

    return blendscene.build(bpy, gdmlt.builtin_scene("cornell", width, height))


def main():
    sys.path.insert(0, str(ROOT / "python"))
    from gdmlt.blend import import_bpy
    import gdmlt

    bpy = import_bpy()
    scene = build_cornell(bpy, gdmlt)
    gdmlt.enable_addon()
    scene.render.engine = "GDMLT"
    scene.gdmlt.method = "GDPSSMLT"
    scene.gdmlt.samples = 64
    scene.gdmlt.max_bounces = 8
    out = ROOT / "examples" / "cornell.blend"
    out.parent.mkdir(exist_ok=True)
    bpy.ops.wm.save_as_mainfile(filepath=str(out), compress=True)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
