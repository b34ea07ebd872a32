"""`python -m gdmlt_bench COMMAND` — the benchmarks, kept out of the gdmlt package (and so out
of its wheel and the Blender extension): they import the product, the product never imports
them. `make bench`, `make bench-lights`, `make bench-peers`, ... run them with
PYTHONPATH=benchmarks.

Commands: bench (error over time against a reference, with --peers Cycles, LuxCore, Mitsuba),
instancebench, pathbench, raybench, reconbench, scalebench, skipbench."""

import argparse
import sys

from gdmlt.cli import BUILTIN, RENDER_METHODS, _nonneg_int, _pos_float, _positive_int, _unit_float


def build_parser():
    p = argparse.ArgumentParser(prog="python -m gdmlt_bench", description=__doc__.splitlines()[0])
    sub = p.add_subparsers(dest="command", required=True)
    rb = sub.add_parser("raybench", help="ray throughput of the core's BVH against Embree (embreex)",
                        description="Closest-hit and occlusion rays, coherent and incoherent, 1 thread and all, "
                                    "on a procedural mesh and the Cornell box: Mrays/s of the core and of Embree.")
    rb.add_argument("--triangles", type=_positive_int, default=1_000_000)
    rb.add_argument("--rays", type=_positive_int, default=1_000_000)
    pb = sub.add_parser("pathbench", help="path-tracing samples/s against Mitsuba 3 and LuxCore",
                        description="Camera samples per second of `pt` (NEE and naive) against Mitsuba 3 and LuxCore "
                                    "PATHCPU on the Cornell box and on it with a ~1M-triangle sphere inside; same "
                                    "scene arrays, resolution, depth and threads. Needs requirements-bench.txt and "
                                    "Debian's libllvm19 (for Mitsuba's LLVM backend).")
    pb.add_argument("--size", type=_positive_int, default=128)
    pb.add_argument("--triangles", type=_positive_int, default=1_000_000)
    pb.add_argument("--max-bounces", type=int, default=8)
    pb.add_argument("--seconds", type=float, default=8.0, help="about how long each cell renders")
    kb = sub.add_parser("skipbench", help="what skipping what a scene does not need saves (samples/s)",
                        description="Samples per second of pt and gdpt with the scene's shortcuts and with the "
                                    "general code paths (the scene setting general_paths), on the built-in Cornell box, "
                                    "its glass/mirror/plastic variant and its transparent variant.")
    kb.add_argument("--size", type=_positive_int, default=96)
    kb.add_argument("--seconds", type=float, default=2.0, help="about how long each timed render takes")
    sb = sub.add_parser("scalebench", help="time per mutation and per path as scene size and threads grow",
                        description="µs per GDPSSMLT mutation and per PT path on the Cornell box with a bumpy "
                                    "sphere of 10k to 10M triangles, 1 thread and all; build time and memory.")
    sb.add_argument("--sizes", default="10000,100000,1000000,10000000", help="comma-separated triangle counts")
    sb.add_argument("--size", type=_positive_int, default=64, help="image side in pixels")
    sb.add_argument("--memory", action="store_true",
                    help="instead: peak bytes per pixel of each method by image size and thread count")
    sb.add_argument("--images", default="512x512,1024x1024,1920x1080",
                    help="with --memory: comma-separated WxH image sizes")
    ib = sub.add_parser("instancebench", help="Geometry Nodes scatters of 10^3 to 10^6 instances against Cycles",
                        description="Wall time and peak memory of F12 (pt, 16 spp, 128x96) on scatters of a "
                                    "5,120-triangle sphere and on the instances realized into one mesh, GDMLT and "
                                    "Cycles in the same run, each render in its own process.")
    ib.add_argument("--counts", default="1000,10000,100000,1000000", help="comma-separated instance counts")
    ib.add_argument("--realized", default="1000", help="comma-separated counts rendered realized into one mesh")
    ib.add_argument("--keep", help="a folder to keep the rendered images in")
    cb = sub.add_parser("reconbench", help="seconds of the L1 and L2 reconstruction by image size",
                        description="Times gdmlt.reconstruct (L1 and L2) on synthetic noisy RGB inputs and prints "
                                    "the MSE of each result against the image the inputs were made from.")
    cb.add_argument("--sizes", default="480x270,960x540,1920x1080", help="comma-separated WxH")
    b = sub.add_parser("bench", help="error against a converged reference at equal time budgets, per method",
                       description="Renders a built-in scene or a .blend file with every method for the same "
                                   "wall-clock budgets and prints relMSE and SMAPE against a converged path-traced "
                                   "reference (and, with --plot, draws them).")
    b.add_argument("--scene", default="cornell", help="built-in name (" + ", ".join(BUILTIN) + ") or a .blend file")
    b.add_argument("--size", type=_positive_int, nargs="+", metavar="N",
                   help="image size: N (square) or W H (default: 128 for built-ins, the file's own for .blend)")
    b.add_argument("--budgets", default="1,2,4", help="comma-separated seconds (default 1,2,4)")
    b.add_argument("--methods", default="pt,gdpt,pssmlt,gdpssmlt", help="comma-separated methods")
    b.add_argument("--modes", default="nee,naive", help="light modes: nee, naive or both (default nee,naive)")
    b.add_argument("--reference-spp", type=_positive_int, default=8192)
    b.add_argument("--reference", choices=("pt", "bdpt", "cycles"), default="pt",
                   help="what every render is compared with: GDMLT pt (default) or bdpt (hard light) at "
                        "--reference-spp, or Cycles "
                        "rendered for --reference-seconds (then GDMLT's error includes any difference from Cycles)")
    b.add_argument("--reference-seconds", type=_pos_float, default=60.0)
    b.add_argument("--max-bounces", type=_nonneg_int, default=8)
    b.add_argument("--alpha-target", type=float, help="GDPSSMLT's α_target for every run")
    b.add_argument("--threads", type=_nonneg_int, default=0)
    b.add_argument("--runs", type=_positive_int, default=1,
                   help="renders per cell, seeds 1…N for GDMLT and Cycles alike; each figure their mean (default 1)")
    b.add_argument("--plot", help="write a PNG of relMSE against time (needs matplotlib)")
    b.add_argument("--adaptive", type=_unit_float, default=0.0, metavar="THRESHOLD",
                   help="adaptive sampling at this noise threshold for GDMLT's pt and auto and for Cycles, as "
                        "artists render (Blender's default 0.01; default 0 = off, every pixel sampled alike)")
    b.add_argument("--denoise", action="store_true",
                   help="also report every render after Intel Open Image Denoise (needs pyoidn)")
    b.add_argument("--peers", default="",
                   help="also render with these at the same budgets: cycles, cycles-guiding (path guiding on), "
                        "luxcore (PATHCPU + Sobol), "
                        "luxcore-mlt (PATHCPU + Metropolis), mitsuba (comma-separated; needs requirements-bench.txt)")
    return p


def _image_sizes(parser, option: str, text: str) -> list:
    """'WxH,WxH,…' as [(W, H), …]; a usage error (exit 2) naming `option` otherwise."""
    try:
        sizes = [tuple(int(v) for v in s.lower().split("x")) for s in text.split(",")]
    except ValueError:
        sizes = []
    if not sizes or any(len(s) != 2 or min(s) < 1 for s in sizes):
        parser.error(f"{option}: '{text}' is not a comma-separated list of WxH")
    return sizes


def main(argv=None):
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command == "bench":
        from .bench import run
        try:
            budgets = tuple(float(x) for x in args.budgets.split(","))
        except ValueError:
            parser.error(f"--budgets: '{args.budgets}' is not a comma-separated list of seconds")
        methods = tuple(m.strip() for m in args.methods.split(",") if m.strip())
        # (NAME-bd: a Metropolis method over bidirectional states, `bidirectional=True`)
        bad = [m for m in methods if m not in RENDER_METHODS and m not in ("pssmlt-bd",)]
        if bad:
            parser.error(f"--methods: unknown {', '.join(bad)} (choose from {', '.join(RENDER_METHODS)}, pssmlt-bd)")
        mode_of = {"nee": True, "naive": False}
        modes = tuple(mode_of.get(m.strip()) for m in args.modes.split(","))
        if None in modes:
            parser.error(f"--modes: '{args.modes}' must list nee and/or naive")
        if args.size and len(args.size) > 2:
            parser.error("--size takes N or W H")
        size = None if not args.size else (args.size[0], args.size[-1])
        extra = {} if args.alpha_target is None else {"alpha_target": args.alpha_target}
        if args.adaptive:
            extra["adaptive_threshold"] = args.adaptive
        from .bench import PEERS

        peers = tuple(x.strip() for x in args.peers.split(",") if x.strip())
        bad = [x for x in peers if x not in PEERS]
        if bad:
            parser.error(f"--peers: unknown {', '.join(bad)} (choose from {', '.join(PEERS)})")
        try:
            run(args.scene, size, budgets, methods, modes, reference_spp=args.reference_spp,
                max_bounces=args.max_bounces, threads=args.threads, plot=args.plot, extra=extra,
                denoise=args.denoise, peers=peers, reference=args.reference,
                reference_seconds=args.reference_seconds, runs=args.runs)
        except (ValueError, RuntimeError, FileNotFoundError) as e:
            print(f"gdmlt: error: {e}", file=sys.stderr)
            return 1
        return 0
    if args.command == "scalebench" and args.memory:
        from .membench import run as membench

        membench(_image_sizes(parser, "--images", args.images))
        return 0
    if args.command == "scalebench":
        from .scalebench import run as scalebench

        try:
            sizes = tuple(int(x) for x in args.sizes.split(","))
        except ValueError:
            parser.error(f"--sizes: '{args.sizes}' is not a comma-separated list of triangle counts")
        scalebench(sizes, args.size)
        return 0
    if args.command == "instancebench":
        from .instancebench import run as instancebench

        try:
            counts = tuple(int(x) for x in args.counts.split(",") if x.strip())
            realized = tuple(int(x) for x in args.realized.split(",") if x.strip())
        except ValueError:
            parser.error("--counts and --realized take comma-separated instance counts")
        instancebench(counts, realized, keep=args.keep)
        return 0
    if args.command == "reconbench":
        from .reconbench import run as reconbench

        reconbench(_image_sizes(parser, "--sizes", args.sizes))
        return 0
    if args.command == "skipbench":
        from .skipbench import run as skipbench

        skipbench(args.size, args.seconds)
        return 0
    if args.command == "pathbench":
        from .pathbench import run as pathbench

        pathbench(args.size, args.triangles, args.max_bounces, args.seconds)
        return 0
    if args.command == "raybench":
        from .raybench import run as raybench

        try:
            raybench(args.triangles, args.rays)
        except RuntimeError as e:
            print(f"gdmlt: error: {e}", file=sys.stderr)
            return 1
        return 0
    return 0


if __name__ == "__main__":
    sys.exit(main())
