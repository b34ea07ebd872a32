"""Writes blender_addon/blackbody.py: Blender's blackbody colour (the Blackbody node's and a
light's Temperature colour — Rec.709, luminance 1) sampled from `Light.temperature_color`
at 256 temperatures evenly spaced in 1/T over Blender's range 800–12000 K, where its
function is defined (it is constant outside). Linear interpolation between the samples is
within 1.1e-3 of Blender's value everywhere (measured at 500 random temperatures).
Usage: python tools/make_blackbody_table.py (needs bpy: `make build` installs it)."""

import pathlib
import sys

import numpy as np

sys.path[:0] = [str(pathlib.Path(__file__).resolve().parents[1] / "python")]

SAMPLES = 256
T_MIN, T_MAX = 800.0, 12000.0

HEADER = '''"""Blender's blackbody colour of a temperature (the Blackbody node's Color, a light's
Temperature colour): Rec.709, luminance 1, constant below {lo:g} K and above {hi:g} K. The table
holds Blender {version}'s own values at {n} temperatures evenly spaced in 1/T (written by
tools/make_blackbody_table.py from `Light.temperature_color`; do not edit); `colour`
interpolates them linearly in 1/T (within 1.1e-3 of Blender's value)."""

import numpy as np

T_MIN, T_MAX = {lo!r}, {hi!r}

# R, G, B at 1/T = 1/T_MAX … 1/T_MIN (evenly spaced)
TABLE = np.array([
'''

FOOTER = '''], np.float64)


def colour(kelvin):
    """The blackbody colour of temperatures `kelvin` (an array, (N,)): (N, 3) float32."""
    t = np.clip(np.asarray(kelvin, np.float64), T_MIN, T_MAX)
    grid = np.linspace(1.0 / T_MAX, 1.0 / T_MIN, len(TABLE))
    return np.stack([np.interp(1.0 / t, grid, TABLE[:, c]) for c in range(3)], axis=-1).astype(np.float32)
'''


def main():
    from gdmlt.blend import import_bpy

    bpy = import_bpy()
    light = bpy.data.lights.new("blackbody", "POINT")
    light.use_temperature = True
    rows = []
    for inv in np.linspace(1.0 / T_MAX, 1.0 / T_MIN, SAMPLES):
        light.temperature = float(min(max(1.0 / inv, T_MIN), T_MAX))
        rows.append("    [" + ", ".join(f"{c:.7g}" for c in light.temperature_color[:3]) + "],\n")
    out = pathlib.Path(__file__).resolve().parents[1] / "blender_addon" / "blackbody.py"
    out.write_text(HEADER.format(lo=T_MIN, hi=T_MAX, n=SAMPLES, version=bpy.app.version_string)
                   + "".join(rows) + FOOTER)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
