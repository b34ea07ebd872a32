"""Render settings' defaults, each in one place.

`CORE` are `gdmlt.render`'s (the core's `RenderSettings::default()`, read from the core);
`PRODUCT` are what a user gets from the command line, the Blender add-on's properties and
`gdmlt export`: the core's, with the automatic method, 64 samples per pixel, adaptive
sampling at a noise threshold of 0.01, denoising on and Cycles' Light Paths (12 bounces in
all, 4 diffuse, 4 glossy, 12 transmission, 0 volume, 8 transparent) — Cycles' defaults, so that a
scene renders with the light transport it has in Cycles. The names are
`gdmlt.render`'s keyword arguments (plus `denoise`); `gdmlt.blend.PROPERTY_OF` maps them to
the add-on's `scene.gdmlt` properties.
"""

from ._core import DEFAULT_SETTINGS as _CORE_DEFAULTS

CORE = dict(_CORE_DEFAULTS)
PRODUCT = dict(CORE, method="auto", spp=64, adaptive_threshold=0.01, denoise=True, max_bounces=12, diffuse_bounces=4,
               glossy_bounces=4, transmission_bounces=12, volume_bounces=0, transparent_bounces=8)
