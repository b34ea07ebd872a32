"""Render settings at scene.gdmlt. These names are a public interface: scripts drive the
engine through them (method, samples, time_limit, max_bounces, use_nee, seed, threads, use_denoising)."""

import bpy
from bpy.props import BoolProperty, EnumProperty, FloatProperty, IntProperty, PointerProperty
from gdmlt.settings import PRODUCT as D  # every render setting's default, in one place

# Each item has a fixed number: Blender stores an enum in a .blend as that number, so adding
# an item must not renumber the others (files saved with GDPSSMLT must still open as that).
METHOD_ITEMS = [
    ("AUTO", "Automatic", "A short pilot (5% of the time) measures each method's error per second on this scene "
                          "and renders with the best one", 4),
    ("PT", "Path Tracing", "Unidirectional path tracing (Kajiya 1986)", 0),
    ("GDPT", "Gradient-Domain Path Tracing",
     "Path tracing with shifted offset paths and screened Poisson reconstruction (Kettunen et al. 2015)", 1),
    ("PSSMLT", "Metropolis (PSSMLT)", "Primary-sample-space Metropolis light transport (Kelemen et al. 2002)", 2),
    ("GDPSSMLT", "Gradient-Domain Metropolis",
     "Metropolis sampling of image gradients with screened Poisson reconstruction (Lehtinen et al. 2013)", 3),
    ("BDPT", "Bidirectional Path Tracing",
     "Paths from the camera and from the lights, joined every way and weighed by multiple importance sampling "
     "(Veach 1997): caustics, light through glass and small openings", 5),
]

RECON_ITEMS = [
    ("L1", "L1", "Robust reconstruction (iteratively reweighted least squares): fewer artefacts, slightly biased"),
    ("L2", "L2", "Least-squares reconstruction (exact, by DCT): unbiased, can show dipole artefacts"),
]


def _kind_bounces(name, what, key):
    """A per-kind bounce limit of the Light Paths panel (Cycles' meaning)."""
    return IntProperty(name=name, default=D[key], min=0, max=1024,
                       description=f"Maximum number of {what} bounces, as in Cycles (1024: only the total limits them)")


class GDMLTRenderSettings(bpy.types.PropertyGroup):
    method: EnumProperty(name="Method", items=METHOD_ITEMS, default=D["method"].upper(),
                         description="Light transport algorithm")
    samples: IntProperty(name="Samples", default=D["spp"], min=1, soft_max=4096,
                         description="Samples per pixel (mutations per pixel for Metropolis methods)")
    use_adaptive_sampling: BoolProperty(name="Noise Threshold", default=D["adaptive_threshold"] > 0,
                                        description="Adaptive sampling, as Cycles': pixels whose estimate has settled "
                                                    "stop sampling and the time goes to the noisy ones (Path Tracing, "
                                                    "and Automatic when it picks path tracing)")
    adaptive_threshold: FloatProperty(name="Noise Threshold", default=D["adaptive_threshold"] or 0.01, min=0.0, max=1.0,
                                      soft_min=0.001, precision=4, step=0.1,
                                      description="Relative noise level at which a pixel stops sampling (Cycles' "
                                                  "Noise Threshold; lower is cleaner and slower)")
    adaptive_min_samples: IntProperty(name="Min Samples", default=D["adaptive_min_samples"], min=0, max=1 << 24,
                                      description="Samples every pixel takes before adaptive sampling may stop it "
                                                  "(0 = automatic: 64 at a threshold of 0.01)")
    preview_samples: IntProperty(name="Viewport", default=1024, min=0, soft_max=4096,
                                 description="Samples per pixel of the viewport's Rendered shading, one path-traced "
                                             "sample per pass (0 = unlimited)")
    time_limit: FloatProperty(name="Time Limit", default=D["time_limit"], min=0.0, subtype="TIME_ABSOLUTE", unit="TIME_ABSOLUTE",
                              description="Stop after this many seconds (0 = no limit); whichever of samples and time comes first")
    max_bounces: IntProperty(name="Max Bounces", default=D["max_bounces"], min=0, max=1024,
                             description="Total maximum number of bounces, as in Cycles (0 = direct light only)")
    diffuse_bounces: _kind_bounces("Diffuse", "diffuse reflection", "diffuse_bounces")
    glossy_bounces: _kind_bounces("Glossy", "glossy reflection", "glossy_bounces")
    transmission_bounces: _kind_bounces("Transmission", "transmission (through glass)", "transmission_bounces")
    volume_bounces: _kind_bounces("Volume", "scattering in a volume (fog, smoke)", "volume_bounces")
    transparent_max_bounces: IntProperty(name="Transparent", default=D["transparent_bounces"], min=0, max=1024,
                                         description="Maximum number of transparent surfaces a path crosses, as "
                                                     "Cycles' Transparent Max Bounces (crossings are not bounces)")
    clamp_direct: FloatProperty(name="Direct Light", default=D["clamp_direct"], min=0.0,
                                description="Clamp Direct, as in Cycles: limit a light sample's contribution "
                                            "before any bounce (0 = off). Biased; not applied by the "
                                            "gradient-domain methods")
    clamp_indirect: FloatProperty(name="Indirect Light", default=D["clamp_indirect"], min=0.0,
                                  description="Clamp Indirect, as in Cycles: limit a light sample's contribution "
                                              "after a bounce (0 = off; Cycles' default is 10). Biased; not "
                                              "applied by the gradient-domain methods")
    use_nee: BoolProperty(name="Next Event Estimation", default=D["nee"],
                          description="Sample lights directly with shadow rays (off: lights are found only by hitting them, the paper's naive mode)")
    seed: IntProperty(name="Seed", default=D["seed"], min=0, description="Random seed; the same seed and settings give the same image")
    reconstruction: EnumProperty(name="Reconstruction", items=RECON_ITEMS, default=D["reconstruction"].upper(),
                                 description="Norm of the screened Poisson reconstruction (gradient-domain methods)")
    alpha_reconstruction: FloatProperty(name="Alpha", default=D["alpha_rec"], min=0.0, soft_max=2.0,
                                        description="Weight of the primal image against the gradients in the reconstruction; "
                                                    "0 = automatic, measured from the render's own noise")
    alpha_target: FloatProperty(name="Target Alpha", default=D["alpha_target"], min=0.01, soft_max=4.0,
                                description="Gradient-domain Metropolis: weight of the primal image in the target function")
    large_step_probability: FloatProperty(name="Large Step Probability", default=D["large_step_probability"], min=0.0, max=1.0,
                                          description="Metropolis methods: probability of a fresh independent sample per mutation")
    chains: IntProperty(name="Chains", default=D["chains"], min=0, max=1000000,
                        description="Metropolis methods: number of Markov chains (0 = automatic, one per 2000 mutations up to 1024)")
    use_denoising: BoolProperty(name="Denoise", default=D["denoise"],
                                description="Denoise the final render with Intel Open Image Denoise, guided by the "
                                            "prefiltered albedo and normal passes (as Cycles' OpenImageDenoise, "
                                            "Accurate); the raw image is kept as the Noisy Image pass")
    pixel_filter_type: EnumProperty(
        name="Pixel Filter", default="BLACKMAN_HARRIS",
        items=[("BLACKMAN_HARRIS", "Blackman-Harris", "Blackman-Harris filter, as Cycles' default", 0),
               ("BOX", "Box", "Box filter: each sample lands in its own pixel", 1)],
        description="Pixel filter type (Cycles' Film panel)")
    filter_width: FloatProperty(name="Width", default=1.5, min=0.01, max=10.0, subtype="PIXEL",
                                description="Pixel filter width (Blackman-Harris)")
    threads: IntProperty(name="Threads", default=D["threads"], min=0, max=1024, description="Render threads (0 = all cores)")


def register():
    bpy.utils.register_class(GDMLTRenderSettings)
    bpy.types.Scene.gdmlt = PointerProperty(type=GDMLTRenderSettings)


def unregister():
    del bpy.types.Scene.gdmlt
    bpy.utils.unregister_class(GDMLTRenderSettings)
