"""Builds the Blender extension zip: dist/gdmlt-<version>.zip, the addon of blender_addon/ with
the compiled core bundled as an abi3 wheel (one wheel serves Blender's Python 3.11 and 3.13;
nothing is fetched at enable time). No Blender binary is needed: Blender's own extension
builder (blender_ext.py, shipped in the bpy package) validates the manifest and writes the zip.

Usage: python tools/build_addon.py [--wheel PATH] [--out-dir dist]"""

import argparse
import importlib.util
import os
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def blender_ext_cli() -> Path:
    spec = importlib.util.find_spec("bpy")
    if spec is None or not spec.submodule_search_locations:
        raise SystemExit("build_addon: the bpy package is needed for Blender's extension builder (pip install bpy)")
    base = Path(list(spec.submodule_search_locations)[0])
    found = sorted(base.glob("*/scripts/addons_core/bl_pkg/cli/blender_ext.py"))
    if not found:
        raise SystemExit(f"build_addon: blender_ext.py not found under {base}")
    return found[-1]


def build_wheel(out: Path) -> Path:
    out.mkdir(parents=True, exist_ok=True)
    for old in out.glob("gdmlt-*.whl"):
        old.unlink()
    venv_bin = Path(sys.executable).parent
    local = venv_bin / "maturin"  # the venv's, when not on PATH
    maturin = str(local) if local.exists() else "maturin"
    # Linked by zig (PyPI's ziglang, found through the venv's python) against glibc 2.28, the
    # manylinux_2_28 baseline Blender's own wheels target, not against this machine's newer
    # glibc: render nodes on RHEL/Rocky 8 or Ubuntu 20.04 can load the core.
    # The x86-64-v3 core `make build` puts beside the portable one is linked against this
    # machine's glibc: it stays out of the extension (set aside while maturin packs the
    # package folder), which carries the portable core only.
    env = dict(os.environ, PATH=f"{venv_bin}{os.pathsep}{os.environ.get('PATH', '')}")
    v3 = ROOT / "python" / "gdmlt" / "_core_v3.abi3.so"
    aside = v3.with_name(v3.name + ".aside")
    if v3.exists():
        v3.replace(aside)
    try:
        subprocess.run([maturin, "build", "--release", "--quiet", "--zig", "--compatibility", "manylinux_2_28",
                        "--out", str(out)], cwd=ROOT, check=True, env=env)
    finally:
        if aside.exists():
            aside.replace(v3)
    wheels = sorted(out.glob("gdmlt-*.whl"))
    if len(wheels) != 1:
        raise SystemExit(f"build_addon: expected one wheel in {out}, found {wheels}")
    return wheels[0]


# What the extension bundles beside the core: the denoiser's binding (its wheel carries the
# OIDN library) and what it needs, for each Python Blender ships (4.2–4.5: 3.11, 5.x: 3.13).
# Pinned to what requirements-dev.txt tests with; Blender provides numpy.
DEPENDENCIES = ("pyoidn==2.5.1.0", "cffi==2.1.1", "pycparser==3.12")
BLENDER_PYTHONS = ("3.11", "3.13")


def download_dependencies(out: Path) -> list:
    """The dependency wheels for every Blender Python, from the package index (pip's cache
    keeps a second build offline)."""
    out.mkdir(parents=True, exist_ok=True)
    for old in out.glob("*.whl"):
        old.unlink()
    for py in BLENDER_PYTHONS:
        subprocess.run([sys.executable, "-m", "pip", "download", "--quiet", "--no-deps", "--only-binary=:all:",
                        "--platform", "manylinux_2_28_x86_64", "--platform", "manylinux2014_x86_64", "--python-version", py, "--implementation", "cp",
                        "--dest", str(out), *DEPENDENCIES], check=True)
    return sorted(out.glob("*.whl"))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--wheel", type=Path, help="use this wheel instead of building one with maturin")
    ap.add_argument("--out-dir", type=Path, default=ROOT / "dist")
    args = ap.parse_args(argv)

    manifest_src = (ROOT / "blender_addon" / "blender_manifest.toml").read_text()
    version = re.search(r'^version\s*=\s*"([^"]+)"', manifest_src, re.M).group(1)
    py_version = re.search(r'^version\s*=\s*"([^"]+)"', (ROOT / "pyproject.toml").read_text(), re.M).group(1)
    if version != py_version:
        raise SystemExit(f"build_addon: manifest version {version} differs from pyproject version {py_version}")
    wheel = args.wheel or build_wheel(ROOT / "target" / "addon-wheels")
    deps = download_dependencies(ROOT / "target" / "addon-deps")

    with tempfile.TemporaryDirectory() as tmp:
        stage = Path(tmp) / "gdmlt"
        shutil.copytree(ROOT / "blender_addon", stage, ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
        (stage / "wheels").mkdir()
        for whl in [wheel, *deps]:
            shutil.copy2(whl, stage / "wheels" / whl.name)
        listed = ", ".join(f'"./wheels/{w.name}"' for w in [wheel, *deps])
        (stage / "blender_manifest.toml").write_text(
            manifest_src.rstrip() + f'\n\n# added by tools/build_addon.py\nwheels = [{listed}]\n'
            '# the core and the OIDN library are x86-64 Linux builds\nplatforms = ["linux-x64"]\n')
        args.out_dir.mkdir(parents=True, exist_ok=True)
        subprocess.run([sys.executable, str(blender_ext_cli()), "build", "--source-dir", str(stage),
                        "--output-dir", str(args.out_dir)], check=True)
    zips = sorted(args.out_dir.glob(f"gdmlt-{version}*.zip"))
    if not zips:
        raise SystemExit(f"build_addon: no zip was written to {args.out_dir}")
    print(f"wrote {zips[-1]}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
