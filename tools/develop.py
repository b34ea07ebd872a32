"""The portable core for this checkout, as `make build` makes it: the manylinux_2_28 wheel that
the Blender extension bundles (tools/build_addon.py's `build_wheel`: linked by zig against
glibc 2.28), its core copied into python/gdmlt/ for the checkout's editable install. The
tests so run the binary users get, and the extension's build (`make addon`, the extension
tests) takes this wheel instead of compiling the core a second time.

The editable install — a .pth naming python/ in the venv's site-packages and the `gdmlt`
command beside its Python — is written where it is missing (what `maturin develop` would
install, without its second, glibc-bound build).

Usage: python tools/develop.py"""

import sys
import sysconfig
import zipfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from build_addon import ROOT, build_wheel  # noqa: E402

WHEELS = ROOT / "target" / "addon-wheels"
CORE = "gdmlt/_core.abi3.so"


def core_of(wheel: Path) -> bytes:
    """The compiled core inside `wheel`."""
    with zipfile.ZipFile(wheel) as z:
        return z.read(CORE)


def install_editable(package_dir: Path):
    site = Path(sysconfig.get_paths()["purelib"])
    pth = site / "gdmlt.pth"
    if not pth.exists() or pth.read_text().strip() != str(package_dir):
        pth.write_text(f"{package_dir}\n")
    command = Path(sys.executable).parent / "gdmlt"
    script = f"#!{sys.executable}\nimport sys\nfrom gdmlt.cli import main\n\nif __name__ == '__main__':\n    sys.exit(main())\n"
    if not command.exists() or command.read_text() != script:
        command.write_text(script)
        command.chmod(0o755)


def main():
    wheel = build_wheel(WHEELS)
    target = ROOT / "python" / CORE
    tmp = target.with_name(target.name + ".tmp")
    tmp.write_bytes(core_of(wheel))
    tmp.replace(target)
    install_editable(ROOT / "python")
    return 0


if __name__ == "__main__":
    sys.exit(main())
