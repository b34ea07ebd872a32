# GDMLT — `make demo` renders the bundled demo scene, `make test` runs every test.
# Both set everything up first: the Python venv at .venv (bpy, usd-core, numpy, maturin,
# pytest) and the Rust core built into it with maturin.

# The Python the default venv is made with follows the bpy it installs (requirements-dev.txt:
# bpy 5.0.1 is built for Python 3.11): tools/python_for.sh finds it (PATH, then pyenv).
HERE   := $(dir $(abspath $(lastword $(MAKEFILE_LIST))))
PYTHON ?= $(shell $(HERE)tools/python_for.sh 3.11 || echo python3)
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.deps-stamp
export VIRTUAL_ENV := $(abspath $(VENV))
export PATH := $(abspath $(VENV))/bin:$(PATH)
# Keep Blender's user config out of $HOME during demos and tests.
export BLENDER_USER_RESOURCES := $(abspath out/blender-user)

.PHONY: all setup build demo test lint test-rust test-rust-v3 test-python test-blender-versions examples addon bench bench-monastery bench-peers bench-lights bench-hard bench-media bench-denoise bench-scale scalebench skipbench raybench clean

all: demo

$(STAMP): requirements-dev.txt
	@command -v cargo >/dev/null || { echo "cargo (Rust) is required: https://rustup.rs"; exit 1; }
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --upgrade pip >/dev/null
	$(PY) -m pip install --no-compile -r requirements-dev.txt
	touch $(STAMP)

setup: $(STAMP)

# The core twice: portable (maturin, installed editable into the venv) and, on x86-64, with
# -C target-cpu=x86-64-v3 as gdmlt/_core_v3; `import gdmlt` loads the v3 one only on CPUs
# that run it. The v3 flag goes to the core crate alone (`cargo rustc`), so both builds
# share every dependency (with maturin's PyO3 configuration, so PyO3 is not rebuilt): the
# second build costs the core's compile, not a second tree of crates (measured: samples/s
# and Mrays/s within the machine's ±8% run-to-run spread of the all-crates v3 build). The
# two builds share cargo's fingerprint of the core, so each is redone only when the sources
# change (Make's timestamps), never because the other ran.
CORE_SO := python/gdmlt/_core.abi3.so
V3_SO := python/gdmlt/_core_v3.abi3.so
CORE_SRC := $(shell find src -name '*.rs') build.rs Cargo.toml Cargo.lock pyproject.toml
# The benchmarks live beside the product (benchmarks/gdmlt_bench), not in its wheel.
BENCH := PYTHONPATH=benchmarks $(PY) -m gdmlt_bench
build: $(CORE_SO)
	@if [ "$$(uname -m)" = x86_64 ] && [ ! $(V3_SO) -nt $(CORE_SO) ]; then \
		echo "cargo rustc (the x86-64-v3 core)"; \
		cfg=$$(ls $(abspath target)/maturin/pyo3-config-*-abi3.txt 2>/dev/null | head -1); \
		if [ -n "$$cfg" ]; then export PYO3_CONFIG_FILE=$$cfg; fi; \
		cargo rustc --release --quiet --lib --features v3-module -- -C target-cpu=x86-64-v3 && \
		cp target/release/libgdmlt.so $(V3_SO).tmp && mv $(V3_SO).tmp $(V3_SO); \
	fi

$(CORE_SO): $(STAMP) $(CORE_SRC)
	$(VENV)/bin/maturin develop --release --quiet
	@touch $@

demo: build
	@mkdir -p out
	$(VENV)/bin/gdmlt render examples/cornell.blend -o out/cornell.exr

test: build lint test-rust test-python test-blender-versions

# Style and static checks: rustfmt (rustfmt.toml), clippy with warnings as errors (the
# binding included), and ruff's pyflakes checks (ruff.toml).
lint: $(STAMP)
	cargo fmt --check
	cargo clippy --release --all-targets --features python -q -- -D warnings
	$(VENV)/bin/ruff check python blender_addon tools tests benchmarks

# Every Rust test on the portable build. The x86-64-v3 build is tested through the module
# `make build` made of it (tests/python/test_core.py: its BVH against the portable one's and
# against every triangle, single rays, packets and occlusion; its renders), which saves
# compiling the core a third time. `make test-rust-v3` runs the Rust BVH and packet tests
# on that build too.
test-rust:
	cargo test --release

test-rust-v3:
	RUSTFLAGS="-C target-cpu=x86-64-v3" cargo test --release --lib --target-dir target/x86-64-v3 -- accel packet

test-python: build
	$(PY) -m pytest -q tests/python

# Blender versions besides the default (requirements-dev.txt's bpy): the current release and
# the long-term-support lines, each as bpy in its own venv with the Python that bpy is built
# for (tools/python_for.sh finds it: PATH, then pyenv). On each, the headless tests marked
# `compat` (tests/python/test_blender.py: F12, export, panels, errors, Cycles agreement) run
# with the core the default venv built; the versions run side by side
# (tools/test_blender_versions.sh).
BLENDER_VERSIONS := 5.3.0:3.13 5.2.0:3.13 4.5.15:3.11
test-blender-versions: build
	tools/test_blender_versions.sh $(BLENDER_VERSIONS)

# The Blender extension: dist/gdmlt-<version>.zip with the core bundled as an abi3 wheel.
# Install it in Blender with Edit > Preferences > Get Extensions > Install from Disk, or
# blender --command extension install-file -r user_default -e dist/gdmlt-<version>.zip
addon: build
	$(PY) tools/build_addon.py

# Error over time on the built-in Cornell box (prints a table, draws out/bench-cornell.png).
bench: build
	$(PY) -m pip install -q -r requirements-bench.txt
	$(BENCH) bench --scene cornell --size 128 --budgets 1,2,4,8 --plot out/bench-cornell.png

# The seed paper's setting: a large scene lit by one small light (pybullet's monastery),
# naive and NEE, every method and auto, also after OIDN, against Cycles raw and with its OIDN;
# table + out/bench-monastery.png. About 8 minutes on 2 cores.
bench-monastery: build
	$(PY) -m pip install -q -r requirements-bench.txt
	$(PY) tools/make_monastery.py out/monastery.blend --size 192 108
	$(BENCH) bench --scene out/monastery.blend --budgets 1,2,4,8 --reference-spp 8192 \
		--methods auto,pt,gdpt,pssmlt,gdpssmlt --denoise --peers cycles --plot out/bench-monastery.png

# Ray throughput of the core's BVH against Embree on 1M triangles (prints a table).
# Against the peers, in one run each (docs/benchmarks-history.md): path-tracing samples/s against
# Mitsuba 3 and LuxCore, then error over time of every method against Cycles, LuxCore (path
# and Metropolis) and Mitsuba on the Cornell box and the gap-lit scene. About 12 minutes.
LLVM19 := /usr/lib/x86_64-linux-gnu/libLLVM.so.19.1
bench-peers: build
	$(PY) -m pip install -q -r requirements-bench.txt
	@[ -e $(LLVM19) ] || apt-get install -y -q libllvm19 || \
		echo "note: Mitsuba's LLVM backend needs libllvm19 (apt-get install libllvm19); its rows will be skipped"
	$(BENCH) pathbench
	$(BENCH) bench --scene cornell --size 128 --budgets 1,2,4,8 --methods pt,gdpt,pssmlt,gdpssmlt \
		--peers cycles,luxcore,luxcore-mlt,mitsuba --plot out/bench-peers-cornell.png
	$(BENCH) bench --scene gap --size 128 --budgets 1,2,4,8 --methods pt,gdpt,pssmlt,gdpssmlt \
		--peers cycles,luxcore,luxcore-mlt,mitsuba --plot out/bench-peers-gap.png

# Equal time against Cycles on .blend scenes built as artists build them (Blender lights, a
# world colour, an HDRI interior, a 64-lamp hall): tools/make_bench_scenes.py writes them,
# each is benchmarked at 1, 2, 4 s (table + out/bench/NAME.png). About 15 minutes.
BENCH_SCENES := area point sun world area_point_sun area_world area_point_sun_world hall hdri_interior
bench-lights: build
	$(PY) -m pip install -q -r requirements-bench.txt
	$(PY) tools/make_bench_scenes.py out/bench
	@for s in $(BENCH_SCENES); do \
		$(BENCH) bench --scene out/bench/$$s.blend --budgets 1,2,4 --methods pt,gdpt,gdpssmlt \
			--modes nee --max-bounces 4 --reference-spp 4096 --peers cycles --plot out/bench/$$s.png || exit 1; \
	done

# Hard light (issue 44): a room lit through a glazed window, caustics on a table, a bulb in a
# shade and a room lit through a door left ajar; every method that starts paths from the
# lights against pt and Cycles (raw, with path guiding, with OIDN), reference bdpt at 4096
# spp with its own noise measured. About 80 minutes.
HARD_SCENES := window caustics lampshade door_ajar
bench-hard: build
	$(PY) -m pip install -q -r requirements-bench.txt
	$(PY) tools/make_bench_scenes.py out/bench
	@for s in $(HARD_SCENES); do \
		$(BENCH) bench --scene out/bench/$$s.blend --budgets 2,10 --methods pt,bdpt,pssmlt-bd,gdpssmlt \
			--modes nee --max-bounces 12 --reference bdpt --reference-spp 4096 --peers cycles,cycles-guiding \
			--denoise || exit 1; \
	done

# Media (issue 46): a fog-filled attic lit by a spot, every method against Cycles (raw and
# with OIDN) at 2 and 10 s, reference Cycles at 4096 spp with its own noise measured.
bench-media: build
	$(PY) -m pip install -q -r requirements-bench.txt
	$(PY) tools/make_bench_scenes.py out/bench
	$(BENCH) bench --scene out/bench/attic.blend --budgets 2,10 --methods pt,bdpt,gdpt,gdpssmlt \
		--modes nee --max-bounces 12 --reference-spp 4096 --peers cycles --denoise

# As artists render, denoiser on (issue 16): every method, `auto` (the default) and Cycles,
# raw and each after its own OIDN, at 1, 2, 4, 8 s; relMSE, SMAPE, block error and FLIP, and
# ratios to Cycles (+OIDN), on a door left ajar, a glass-and-mirror box, a multi-light scene
# and the built-in gap. About 25 minutes.
DENOISE_SCENES := out/bench/door_ajar.blend out/bench/glass_box.blend out/bench/area_point_sun_world.blend gap
bench-denoise: build
	$(PY) -m pip install -q -r requirements-bench.txt
	$(PY) tools/make_bench_scenes.py out/bench
	@for s in $(DENOISE_SCENES); do \
		$(BENCH) bench --scene $$s --budgets 1,2,4,8 --methods auto,pt,gdpt,gdpssmlt --modes nee \
			--reference-spp 16384 --peers cycles --denoise --plot out/bench-denoise-$$(basename $$s .blend).png \
			|| exit 1; \
	done

# Time per mutation / per path as the scene grows from 10k to 10M triangles and threads 1 → all.
scalebench: build
	$(BENCH) scalebench

# Scatters of 10^3..10^6 instances (and one realized into a 5M-triangle mesh) against Cycles:
# F12 wall time and peak memory, each render in its own process.
bench-scale: build
	$(BENCH) instancebench

# What skipping what a scene does not need saves: samples/s with and without the shortcuts.
skipbench: build
	$(BENCH) skipbench

raybench: build
	$(PY) -m pip install -q -r requirements-bench.txt
	$(BENCH) raybench

# Regenerates examples/*.blend from the built-in scene definitions (needs bpy).
examples: build
	$(PY) tools/make_examples.py

clean:
	rm -rf target out $(VENV) .venv-bpy-* python/gdmlt/*.so
