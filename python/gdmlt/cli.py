"""`gdmlt` command line: render a .blend file (through the Blender addon, as Blender would)
or a built-in scene, headless."""

import argparse
import sys
import time
from pathlib import Path

from .passes import CLI_NAMES as CLI_PASS_NAMES

BUILTIN = ("cornell", "spheres", "gap", "furnace", "fog")
METHODS = ("pt", "bdpt", "gdpt", "pssmlt", "gdpssmlt")
RENDER_METHODS = ("auto",) + METHODS  # auto: gdmlt/auto.py picks one of them per scene
USD_SUFFIXES = (".usd", ".usda", ".usdc", ".usdz")


U32_MAX, U64_MAX = 2 ** 32 - 1, 2 ** 64 - 1


def _int_at_least(lowest, highest=U32_MAX):
    """An integer in [lowest, highest] (the core's field holds at most `highest`)."""
    def parse(s):
        if isinstance(s, bool) or not isinstance(s, (int, str)):
            raise argparse.ArgumentTypeError(f"'{s}' is not an integer")
        try:
            v = int(s)
        except ValueError:
            raise argparse.ArgumentTypeError(f"'{s}' is not an integer")
        if v < lowest:
            raise argparse.ArgumentTypeError(f"must be at least {lowest}, got {v}")
        if v > highest:
            raise argparse.ArgumentTypeError(f"must be at most {highest}, got {v}")
        return v
    return parse


_positive_int = _int_at_least(1)
_nonneg_int = _int_at_least(0)
_seed = _int_at_least(0, U64_MAX)
_bounces = _int_at_least(0, 1024)
_threads = _int_at_least(0, 1024)
_chains = _int_at_least(0, 1_000_000)
_side = _int_at_least(1, 65536)
_min_samples = _int_at_least(0, 1 << 24)


def _nonneg_float(s):
    if isinstance(s, bool):
        raise argparse.ArgumentTypeError(f"'{s}' is not a number")
    try:
        v = float(s)
    except (TypeError, ValueError):
        raise argparse.ArgumentTypeError(f"'{s}' is not a number")
    if not (v >= 0.0 and v != float("inf")):
        raise argparse.ArgumentTypeError(f"must be a finite number ≥ 0, got {s}")
    return v


def _pos_float(s):
    v = _nonneg_float(s)
    if v <= 0.0:
        raise argparse.ArgumentTypeError(f"must be > 0, got {s}")
    return v


def _unit_float(s):
    v = _nonneg_float(s)
    if v > 1.0:
        raise argparse.ArgumentTypeError(f"must be at most 1, got {s}")
    return v


def _version():
    try:
        import gdmlt

        return f"gdmlt {gdmlt.__version__} ({gdmlt.BUILD_TARGET})"
    except ImportError as e:  # the core did not load: say so, still answer --version
        return f"gdmlt (core not loaded: {e})"


def build_parser():
    from .settings import PRODUCT as D  # the defaults the help texts name

    p = argparse.ArgumentParser(prog="gdmlt", description="GDMLT: gradient-domain Metropolis light transport renderer")
    p.add_argument("--version", action="version", version=_version())
    sub = p.add_subparsers(dest="command", required=True)
    r = sub.add_parser("render", help="render a .blend file or a built-in scene to EXR (+ PNG)",
                       description="Render SCENE (a .blend file, a USD stage (.usd, .usda, .usdc, .usdz), or a built-in name: " + ", ".join(BUILTIN) + ") "
                                   "to OUT.exr (linear 32-bit float) and OUT.png (sRGB). "
                                   "Options left out keep the .blend file's own GDMLT settings.")
    r.add_argument("scene", help="path to a .blend or USD file, or a built-in scene name (" + ", ".join(BUILTIN) + ")")
    r.add_argument("-o", "--output", required=True, help="output EXR path; a PNG is written next to it")
    r.add_argument("--method", choices=RENDER_METHODS, type=str.lower,
                   help="light transport method: pt (path tracing), bdpt (bidirectional path tracing), "
                        "gdpt (gradient-domain path tracing), "
                        "pssmlt (primary-sample-space Metropolis), gdpssmlt (gradient-domain Metropolis), "
                        "auto (a short pilot picks the one with the least error per second on this scene); "
                        f"default: the file's, else {D['method']}")
    r.add_argument("--alpha-target", type=_pos_float, dest="alpha_target",
                   help=f"gdpssmlt: weight of the primal term in the target function (default {D['alpha_target']})")
    r.add_argument("--large-step", type=_nonneg_float, dest="large_step_probability",
                   help=f"Metropolis methods: probability of a large step (default {D['large_step_probability']})")
    r.add_argument("--chains", type=_chains,
                   help="Metropolis methods: number of Markov chains (default 0 = one per 2000 mutations, up to 1024)")
    r.add_argument("--recon", choices=["l1", "l2"], type=str.lower, dest="reconstruction",
                   help=f"gradient-domain reconstruction norm, l1 (robust) or l2 (unbiased); default {D['reconstruction']}")
    r.add_argument("--alpha-rec", type=_nonneg_float, dest="alpha_rec",
                   help="screened-Poisson weight of the primal image in the reconstruction; 0 (the default) "
                        "measures it from the render's own noise")
    r.add_argument("--spp", type=_positive_int, help=f"samples (PT methods) or mutations (Metropolis methods) per pixel (default: the file's, else {D['spp']})")
    r.add_argument("--time", type=_nonneg_float, dest="time_limit", help="time limit in seconds, 0 = none; halts on whichever of --spp and --time comes first")
    r.add_argument("--noise-threshold", type=_unit_float, dest="adaptive_threshold",
                   help="pt: adaptive sampling, as Cycles' Noise Threshold: pixels whose estimate has settled to "
                        "this relative error stop sampling and the rest get the time (0 = off, every pixel gets "
                        f"--spp; default: the file's, else {D['adaptive_threshold']})")
    r.add_argument("--adaptive-min-samples", type=_min_samples, dest="adaptive_min_samples",
                   help="pt: samples every pixel takes before adaptive sampling may stop it (default 0 = automatic: "
                        "64 at a threshold of 0.01)")
    r.add_argument("--max-bounces", type=_bounces, help=f"maximum bounces as in Cycles (0 = direct light; default {D['max_bounces']})")
    for kind in BOUNCE_KINDS:
        default = D[f"{kind}_bounces"]
        r.add_argument(f"--{kind}-bounces", type=_bounces,
                       help=f"maximum {kind} bounces as in Cycles (default {default}"
                            + (": only the total limits them)" if default >= 1024 else ")"))
    for kind in ("direct", "indirect"):
        r.add_argument(f"--clamp-{kind}", type=_nonneg_float, dest=f"clamp_{kind}",
                       help=f"Cycles' Clamp {kind.title()}: limit a light sample's contribution (default 0 = off; "
                            "biased; pt and pssmlt only)")
    nee = r.add_mutually_exclusive_group()
    nee.add_argument("--nee", dest="nee", action="store_true", default=None, help="next-event estimation with MIS (default)")
    nee.add_argument("--no-nee", dest="nee", action="store_false", help="naive path tracing: lights found only by hitting them")
    guide = r.add_mutually_exclusive_group()
    guide.add_argument("--guiding", dest="guiding", action="store_true", default=None,
                       help="pt: path guiding, learned during the render (Mueller et al. 2017); off by default: "
                            "on a room lit through a door left ajar it lowers the block error after denoising by 7-9%% "
                            "at equal time; on directly lit scenes and the built-in gap it costs more than it gains "
                            "(docs/benchmarks.md)")
    guide.add_argument("--no-guiding", dest="guiding", action="store_false", help="pt: no path guiding (default)")
    bidir = r.add_mutually_exclusive_group()
    bidir.add_argument("--bidirectional", dest="bidirectional", action="store_true", default=None,
                       help="pssmlt: each Markov state is a whole bidirectional sample (paths from the camera and "
                            "the lights, every join; docs/bidirectional.md)")
    bidir.add_argument("--no-bidirectional", dest="bidirectional", action="store_false",
                       help="pssmlt: Markov states are camera paths (the paper's setting; default)")
    r.add_argument("--seed", type=_seed, help=f"random seed (default {D['seed']})")
    den = r.add_mutually_exclusive_group()
    den.add_argument("--denoise", dest="denoise", action="store_true", default=None,
                     help="denoise the image with Intel Open Image Denoise, the raw one kept as the 'Noisy Image' "
                          "layer (default: the file's setting, else on, as in Cycles)")
    den.add_argument("--no-denoise", dest="denoise", action="store_false", help="write the raw image")
    r.add_argument("--width", type=_side, help="image width in pixels (overrides the scene)")
    r.add_argument("--height", type=_side, help="image height in pixels (overrides the scene)")
    r.add_argument("--threads", type=_threads, help="render threads, 0 = all cores (default)")
    r.add_argument("--no-png", action="store_true", help="write only the EXR")
    r.add_argument("--frame", type=float, help="the frame (.blend) or time code (USD) to render (default: the "
                                               "file's current frame, the stage's default time)")
    r.add_argument("--passes", metavar="NAMES",
                   help="data passes to add to the EXR, comma-separated: " + ", ".join(CLI_PASS_NAMES)
                        + ", or all (default: those the .blend's view layer has on, or the USD stage stored)")
    r.add_argument("--camera", help="USD: path of the camera prim (default: the first camera)")
    r.add_argument("--partial", metavar="K/N",
                   help="render partial K of N (its own seed) into OUT.npz, for gdmlt merge")
    r.add_argument("--dask", nargs="?", const="", metavar="ADDRESS",
                   help="render --partials partials on a Dask cluster (tcp://host:8786; without an address "
                        "a local cluster of --workers processes) and merge them")
    r.add_argument("--partials", type=_positive_int, default=4, help="with --dask: number of partials (default 4)")
    r.add_argument("--workers", type=_positive_int, default=2, help="with --dask and no address: local workers")
    r.add_argument("--dask-timeout", type=float, default=10.0, metavar="SECONDS",
                   help="with --dask ADDRESS: how long to keep trying to reach the scheduler (default 10)")
    ex = sub.add_parser("export", help="export a .blend to USD for render nodes without Blender",
                        description="Blender's USD exporter, plus the scene's GDMLT settings and image size "
                                    "stored in the stage, which `gdmlt render OUT.usdc` then uses as defaults.")
    ex.add_argument("scene", help=".blend file")
    ex.add_argument("-o", "--output", required=True, help="output .usd, .usda, .usdc or .usdz")
    ex.add_argument("--frame", type=int, help="the frame to export (default: the file's current frame)")
    mg = sub.add_parser("merge", help="merge partial renders (--partial K/N) into one EXR",
                        description="Averages partial renders weighted by their samples and, for the "
                                    "gradient-domain methods, reconstructs once from the merged buffers.")
    mg.add_argument("partials", nargs="+", help="partial .npz files")
    mg.add_argument("-o", "--output", required=True, help="output EXR path; a PNG is written next to it")
    mg.add_argument("--recon", choices=["l1", "l2"], type=str.lower, dest="reconstruction",
                    help="reconstruction norm (default: the partials')")
    mg.add_argument("--alpha-rec", type=float, help="reconstruction α (default: the partials')")
    mg.add_argument("--no-png", action="store_true", help="write only the EXR")
    mgd = mg.add_mutually_exclusive_group()
    mgd.add_argument("--denoise", dest="denoise", action="store_true", default=True,
                     help="denoise the merged image (default)")
    mgd.add_argument("--no-denoise", dest="denoise", action="store_false", help="write the raw merged image")
    return p


# Path length limits per kind of scattering besides the total (Cycles' Light Paths panel).
BOUNCE_KINDS = ("diffuse", "glossy", "transmission", "volume", "transparent")


def _settings(args):
    return {k: v for k, v in {
        "method": args.method, "spp": args.spp, "time_limit": args.time_limit, "max_bounces": args.max_bounces,
        "nee": args.nee, "guiding": args.guiding, "bidirectional": args.bidirectional, "seed": args.seed,
        "threads": args.threads,
        "reconstruction": args.reconstruction, "alpha_rec": args.alpha_rec,
        "alpha_target": args.alpha_target, "large_step_probability": args.large_step_probability,
        "chains": args.chains, "clamp_direct": args.clamp_direct, "clamp_indirect": args.clamp_indirect,
        "adaptive_threshold": args.adaptive_threshold, "adaptive_min_samples": args.adaptive_min_samples,
        **{f"{k}_bounces": getattr(args, f"{k}_bounces") for k in BOUNCE_KINDS}}.items()
        if v is not None}


def finish_layers(layers: dict, denoise: bool, threads=0) -> dict:
    """The layers to write: denoised when asked (a warning and the raw image when OIDN is
    missing)."""
    if not denoise:
        return layers
    from .oidn import denoise_or_warn

    return denoise_or_warn(layers, lambda m: print(f"gdmlt: warning: {m}", file=sys.stderr), threads=threads)


def _choice(*names):
    def parse(s):
        if not isinstance(s, str) or s.lower() not in names:
            raise argparse.ArgumentTypeError(f"'{s}' is not one of {', '.join(names)}")
        return s.lower()
    return parse


def _flag(s):
    if not isinstance(s, bool):
        raise argparse.ArgumentTypeError(f"'{s}' is not true or false")
    return s


# The one check of every render setting, whatever it comes from: the CLI's options use these
# parsers (argparse), and so do the settings a USD stage stores (customLayerData "gdmlt"),
# which no CLI parser saw. The core validates again (gdmlt.render raises ValueError).
SETTING_PARSERS = {"method": _choice(*RENDER_METHODS), "spp": _positive_int, "time_limit": _nonneg_float,
                   "max_bounces": _bounces, "nee": _flag, "guiding": _flag, "bidirectional": _flag, "seed": _seed,
                   "threads": _threads,
                   **{f"{k}_bounces": _bounces for k in BOUNCE_KINDS},
                   "clamp_direct": _nonneg_float, "clamp_indirect": _nonneg_float,
                   "reconstruction": _choice("l1", "l2"), "alpha_rec": _nonneg_float, "alpha_target": _pos_float,
                   "large_step_probability": _nonneg_float, "chains": _chains, "denoise": _flag,
                   "adaptive_threshold": _unit_float, "adaptive_min_samples": _min_samples,
                   "width": _side, "height": _side}


def checked_settings(stored: dict, where: str) -> dict:
    """`stored` with every known key parsed as the CLI parses it; ValueError naming the key
    and `where` for a bad value."""
    out = {}
    for k, v in stored.items():
        if k not in SETTING_PARSERS:
            continue
        try:
            out[k] = SETTING_PARSERS[k](v)
        except argparse.ArgumentTypeError as e:
            raise ValueError(f"{where}: setting '{k}': {e}") from None
    if out.get("large_step_probability", 0.0) > 1.0:
        raise ValueError(f"{where}: setting 'large_step_probability' must be at most 1")
    return out


def render_settings(args, stored: dict) -> tuple:
    """(gdmlt.render's settings, whether to denoise): the CLI's options over the settings the
    scene file holds (`stored`: a .blend's scene.gdmlt, what `gdmlt export` stored in a USD
    stage) over the defaults; denoising defaults to on, as in Cycles."""
    from .settings import PRODUCT

    opts = {k: v for k, v in PRODUCT.items() if k not in ("denoise", "data_passes")}
    opts.update({k: v for k, v in stored.items() if k in opts})
    opts.update(_settings(args))
    denoise = args.denoise if args.denoise is not None else stored.get("denoise", PRODUCT["denoise"])
    return opts, denoise


def render_desc(desc, settings: dict, denoise: bool, out: Path, png: bool, view=None, passes=()):
    """Renders a scene dict with `settings` (render_settings'); writes the EXR with the data
    `passes` (names, gdmlt.passes) beside the method's own, and the PNG through `view`
    (gdmlt.colour)."""
    import gdmlt

    from .passes import needs_core_pass, select

    settings = dict(settings, data_passes=needs_core_pass(passes))
    scene = gdmlt.Scene(desc)
    if settings["method"] == "auto":
        from .auto import plan

        settings, pick = plan(desc, settings, denoise=denoise, scene=scene)
        print(f"gdmlt: method auto chose {pick['method']} ({pick['why']})", file=sys.stderr)
    import signal

    line = ProgressLine(settings["method"])
    # Ctrl-C during the render: a flag the progress callback hands to the core (which stops
    # and returns what it has), not a KeyboardInterrupt that would lose the work
    import threading

    main = threading.current_thread() is threading.main_thread()  # (signals only go there)
    previous = signal.signal(signal.SIGINT, lambda *_: setattr(line, "interrupted", True)) if main else None
    try:
        res = gdmlt.render(scene, **settings, progress=line)
    finally:
        if main:
            signal.signal(signal.SIGINT, previous)
    st = res["stats"]
    meta = {"gdmlt/version": gdmlt.__version__, "gdmlt/method": st["method"], "gdmlt/samples": str(st["spp_max"]),
            "gdmlt/render_seconds": f"{st['elapsed']:.3f}", "gdmlt/interrupted": "yes" if st["cancelled"] else "no"}
    if st["cancelled"]:
        # Ctrl-C (the core stops at the signal and returns what it has): keep the work under
        # a name that says so, never as the image the user asked for, and say so in its header
        out = out.with_name(out.stem + ".interrupted" + out.suffix)
        write_layers(out, select(res["layers"], passes), png, dict(meta, **{"gdmlt/denoised": "no"}), view)
        raise Interrupted(out)
    layers = select(finish_layers(res["layers"], denoise, settings["threads"]), passes)
    write_layers(out, layers, png, dict(meta, **{"gdmlt/denoised": "yes" if "Noisy Image" in layers else "no"}),
                 view)
    return st


class ProgressLine:
    """The render's progress on stderr — a line per 10% or per 10 s, with the time left (what
    a farm log keeps) — and Ctrl-C: it stops the render, which returns what it has."""

    def __init__(self, method, out=None):
        from .progress import ProgressThrottle

        self.method, self.out = method, out or sys.stderr
        self.throttle, self.interrupted = ProgressThrottle(), False

    def __call__(self, fraction, elapsed):
        from .progress import seconds_left

        try:
            if self.throttle(fraction, elapsed):
                left = seconds_left(fraction, elapsed)
                left = f", {left:.1f} s left" if left is not None else ""
                print(f"gdmlt: {self.method} {fraction * 100:.0f}% after {elapsed:.1f} s{left}", file=self.out,
                      flush=True)
        except KeyboardInterrupt:
            self.interrupted = True
        return self.interrupted


class Interrupted(Exception):
    """The render was stopped by Ctrl-C; its partial image was written to `path`."""

    def __init__(self, path):
        super().__init__(str(path))
        self.path = path


def main(argv=None):
    """The command line; a failure the code did not foresee (a panic in the core arrives as
    PyO3's PanicException, a BaseException) is reported in one line with exit 1, never as a
    traceback or an image written anyway."""
    try:
        return _main(argv)
    except KeyboardInterrupt:
        print("gdmlt: interrupted", file=sys.stderr)
        return 130
    except SystemExit:
        raise
    except BaseException as e:  # noqa: BLE001
        print(f"gdmlt: internal error ({type(e).__name__}): {e} — please report it with the command line",
              file=sys.stderr)
        return 1


def _main(argv=None):
    parser = build_parser()
    args = parser.parse_args(argv)
    command = {"merge": merge_command, "export": export_command, "render": render_command}[args.command]
    return command(args, parser)


def export_command(args, parser):
    """`gdmlt export x.blend -o x.usd`: the scene and its settings to USD."""
    out, src = Path(args.output), Path(args.scene)
    if out.suffix.lower() not in USD_SUFFIXES:
        parser.error(f"output must be a USD file ({', '.join(USD_SUFFIXES)}), got '{out}'")
    if src.suffix.lower() != ".blend" or not src.is_file():
        print(f"gdmlt: error: not a .blend file: {src}", file=sys.stderr)
        return 1
    from .blend import export_usd

    try:
        stored = export_usd(src, out, frame=args.frame)
    except RuntimeError as e:
        print(f"gdmlt: error: {e}", file=sys.stderr)
        return 1
    print(f"wrote {out} ({stored['width']}×{stored['height']}, method {stored['method']}, "
          f"{stored['spp']} per pixel)")
    return 0


def _checked_render_args(args, parser):
    """The render command's arguments checked before any work: the output's type, --partial's
    K/N, the scene's kind. Returns (K, N) of --partial or None."""
    out = Path(args.output)
    want = ".npz" if args.partial is not None else ".exr"
    if out.suffix.lower() != want:
        parser.error(f"output must be a {want} file" + (" with --partial" if want == ".npz" else "") + f", got '{out}'")
    partial = None
    if args.partial is not None:
        try:
            k, n = (int(x) for x in args.partial.split("/"))
            if not 0 <= k < n:
                raise ValueError
        except ValueError:
            parser.error(f"--partial: '{args.partial}' must be K/N with 0 ≤ K < N")
        partial = (k, n)
    if args.dask is not None and args.partials < 1:
        parser.error("--partials must be at least 1")
    if not args.dask_timeout > 0:  # (also NaN)
        parser.error("--dask-timeout must be a positive number of seconds")
    suffix = Path(args.scene).suffix.lower()
    if args.scene not in BUILTIN and suffix != ".blend" and suffix not in USD_SUFFIXES:
        parser.error(f"'{args.scene}' is neither a .blend or USD file nor a built-in scene ({', '.join(BUILTIN)})")
    if args.passes is not None:
        from .passes import parse_cli

        try:
            parse_cli(args.passes)
        except ValueError as e:
            parser.error(f"--passes: {e}")
    return partial


def render_command(args, parser):
    """`gdmlt render SCENE -o x.exr`: load the scene (load_source), settle the settings (the
    file's under the options), render — here, as one partial, or on Dask — and write."""
    partial = _checked_render_args(args, parser)
    out, path, t0 = Path(args.output), Path(args.scene), time.perf_counter()
    distributed = partial is not None or args.dask is not None
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        if args.scene not in BUILTIN and not path.is_file():
            print(f"gdmlt: error: file not found: {path}", file=sys.stderr)
            return 1
        src = load_source(args)
        settings, denoise = render_settings(args, src["stored"])
        from .passes import parse_cli

        wanted = parse_cli(args.passes) if args.passes is not None else src["passes"]
        if not distributed:
            stats = render_desc(src["desc"], settings, denoise, out, not args.no_png, src["view"], wanted)
            return _report(args, out, stats, t0)
        if args.passes:
            print("gdmlt: warning: --passes: distributed renders write no data passes", file=sys.stderr)
        if settings["method"] == "auto":
            if partial is not None:
                parser.error("--partial needs a method other than auto: each machine's pilot could pick "
                             "another one, and partials of different methods do not merge")
            from .auto import plan

            settings, pick = plan(src["desc"], settings, denoise=denoise)
            print(f"gdmlt: method auto chose {pick['method']} ({pick['why']})", file=sys.stderr)
        if partial is not None:
            from .distributed import render_partial, save_partial

            p = render_partial(src["desc"], partial[0], partial[1], settings)
            save_partial(out, p)
            print(f"wrote partial {partial[0]}/{partial[1]} to {out} ({p['work']:.0f} samples)")
            return 0
        from .distributed import render_dask

        layers, dropped = render_dask(src["desc"], args.partials, settings, address=args.dask or None,
                                      workers=args.workers, log=lambda m: print(m, file=sys.stderr),
                                      connect_timeout=args.dask_timeout)
        write_layers(out, finish_layers(layers, denoise), not args.no_png, view=src["view"])
        print(f"wrote {out}: {args.partials - len(dropped)} of {args.partials} partials merged "
              f"in {time.perf_counter() - t0:.2f} s")
        return 0
    except Interrupted as e:
        print(f"gdmlt: interrupted: the unfinished image was written to {e.path}", file=sys.stderr)
        return 130
    except KeyboardInterrupt:
        print("gdmlt: interrupted", file=sys.stderr)
        return 130
    except (ValueError, RuntimeError, FileNotFoundError, OSError) as e:
        print(f"gdmlt: error: {e}", file=sys.stderr)
        return 1


def _report(args, out: Path, stats: dict, t0: float) -> int:
    """The render's warnings, what was written and how long it took."""
    for w in stats.get("warnings", []):
        print(f"gdmlt: warning: {w}", file=sys.stderr)
    total = time.perf_counter() - t0
    from .outputs import written_by_gdmlt

    png = out.with_suffix(".png")
    print(f"wrote {out}" + (f" and {png}" if not args.no_png and written_by_gdmlt(png) else ""))
    unit = "mutations" if stats.get("chains") else "samples"
    from .progress import samples_per_pixel

    alpha = f", reconstruction α {stats['alpha_rec']:.3g}" if stats.get("alpha_rec") else ""
    print(f"render {stats.get('elapsed', 0.0):.2f} s ({samples_per_pixel(stats)} {unit} per pixel"
          f"{', method ' + stats['method'] if 'method' in stats else ''}{alpha}), total {total:.2f} s")
    return 0


def load_source(args) -> dict:
    """The scene to render and what its file says about rendering it: {"desc": scene dict,
    "stored": render settings (checked as the CLI's own), "view": colour management for the
    PNG (gdmlt.colour), "passes": data pass names (gdmlt.passes)} — of a built-in scene
    (defaults, Standard, none), a USD stage (what `gdmlt export` stored in it) or a .blend
    (its scene's, exported through the add-on). Prints the loader's warnings."""
    import gdmlt

    from . import colour

    src = {"stored": {}, "view": dict(colour.STANDARD), "passes": ()}
    path = Path(args.scene)
    if args.scene in BUILTIN:
        src["desc"], warnings = gdmlt.builtin_scene(args.scene, args.width or 256, args.height or 256), []
    elif path.suffix.lower() in USD_SUFFIXES:
        from .passes import parse_cli
        from .usd import load, stored_settings

        where = f"{args.scene} (customLayerData gdmlt)"
        stored = stored_settings(args.scene)
        src["stored"] = checked_settings(stored, where)
        if "view" in stored:
            src["view"] = colour.checked_view(stored["view"], where)
        if "passes" in stored:
            src["passes"] = parse_cli(str(stored["passes"]))
        src["desc"], warnings = load(path, frame=args.frame, width=args.width, height=args.height,
                                     camera=args.camera)
    else:
        from .blend import load

        b = load(path, frame=args.frame, width=args.width, height=args.height)
        src.update(desc=b["desc"], view=b["view"], passes=b["passes"],
                   stored=checked_settings(b["settings"], f"{path} (scene.gdmlt)"))
        warnings = b["warnings"]
    for w in warnings:
        print(f"gdmlt: warning: {w}", file=sys.stderr)
    return src


def write_layers(out: Path, layers: dict, png: bool, metadata=None, view=None):
    """The EXR (every layer; `metadata`: text attributes in its header) and the PNG beside it
    (through `view`: gdmlt.colour)."""
    import gdmlt

    from .colour import write_png
    from .outputs import png_beside, with_alpha

    combined = with_alpha(layers)
    names = [n for n in layers if n not in ("Combined", "Alpha")]
    gdmlt.write_exr(str(out), [("Combined", combined)] + [(n, layers[n]) for n in names], metadata)
    path = png_beside(out) if png else None
    if path is not None:
        write_png(path, combined, view)



def merge_command(args, parser=None):
    from .distributed import load_partial, merge

    out = Path(args.output)
    if out.suffix.lower() != ".exr":
        print(f"gdmlt: error: output must be an .exr file, got '{out}'", file=sys.stderr)
        return 2
    try:
        partials = [load_partial(p) for p in args.partials]
        layers = merge(partials, alpha_rec=args.alpha_rec, reconstruction=args.reconstruction)
    except (ValueError, OSError, KeyError) as e:
        print(f"gdmlt: error: {e}", file=sys.stderr)
        return 1
    layers = finish_layers(layers, args.denoise)
    out.parent.mkdir(parents=True, exist_ok=True)
    write_layers(out, layers, not args.no_png)
    print(f"wrote {out}: {len(partials)} partials merged")
    return 0

if __name__ == "__main__":
    sys.exit(main())
