# nbrdf: `make demo` builds everything and runs the main job; `make test` builds everything and
# runs every test. Both start from `make setup`, which is idempotent.

SHELL := /bin/bash
PYTHON ?= python3
CARGO ?= cargo
VENV := .venv
PY := $(VENV)/bin/python
LIB := target/release/libnbrdf_ffi.so
TRAIN_LIB := target/release/libnbrdf_train.so
CLI := target/release/nbrdf
PLUGIN_SOURCES := $(shell find mitsuba-plugin -name '*.py' -not -path '*/build/*') mitsuba-plugin/pyproject.toml nbrdf-ffi/include/nbrdf.h nbrdf-ffi/train/include/nbrdf_train.h

.PHONY: setup build install demo test test-rust test-python test-cuda bench lint clean chromium FORCE

setup: $(VENV)/.plugin-installed llvm chromium

# Python environment: Mitsuba, Dr.Jit and the script and test dependencies, and the scripts'
# package nbrdf_tools (editable: `python -m nbrdf_tools scenes` runs this checkout's code).
$(VENV)/.deps-installed: python/requirements.txt python/pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -r python/requirements.txt
	$(PY) -m pip install -q --no-deps --no-build-isolation -e ./python
	touch $@

# Three release builds, each its own cargo call so that features do not unify, and each the
# cargo call mitsuba-plugin/setup.py makes (so that the plugin's install below and the wheel built
# from the sdist in tests/test_packaging.py find them built): the C ABI library without
# nbrdf-core's training stack and CLI dependencies; the trainer's C ABI for `python -m
# nbrdf_mitsuba.distill` (libnbrdf_train, nbrdf-ffi/train); the CLI (target/release/nbrdf,
# feature `cli`), as setuptools-rust builds it. Building the last two in one call compiles
# nbrdf-core once for both, but for a library as well as a binary, which setuptools-rust's build
# of the binary alone cannot reuse: it compiled nbrdf-core and its dependencies again.
build: $(LIB)
$(LIB): FORCE
	$(CARGO) build --release -p nbrdf-ffi
	$(CARGO) build --release -p nbrdf-train-ffi
	$(CARGO) build --release --manifest-path nbrdf-core/Cargo.toml --features cli --bin nbrdf

# The trainer library and the CLI come out of $(LIB)'s recipe; naming them lets a change to
# either alone (the CLI's sources, say) reinstall the plugin that bundles them.
$(TRAIN_LIB) $(CLI): $(LIB) ;

# The plugin package, bundling the libraries and the CLI just built (no second cargo build).
$(VENV)/.plugin-installed: $(VENV)/.deps-installed $(LIB) $(TRAIN_LIB) $(CLI) $(PLUGIN_SOURCES)
	NBRDF_LIBRARY=$(abspath $(LIB)) NBRDF_TRAIN_LIBRARY=$(abspath $(TRAIN_LIB)) $(PY) -m pip install -q --no-deps --no-build-isolation --force-reinstall ./mitsuba-plugin
	touch $@

# Dr.Jit's LLVM backend needs libLLVM >= 16; install Debian's libllvm19 only when none is found.
llvm: $(VENV)/.plugin-installed
	@if ! $(PY) -m nbrdf_mitsuba.llvm --quiet; then \
	  if command -v apt-get >/dev/null && [ "$$(id -u)" = 0 ]; then \
	    echo "installing libllvm19 for Dr.Jit's LLVM backend"; \
	    apt-get install -y -q libllvm19 >/dev/null || { apt-get update -q >/dev/null && apt-get install -y -q libllvm19 >/dev/null; }; \
	  else \
	    echo "error: no libLLVM >= 16 found; install one (Debian: sudo apt-get install libllvm19) or set DRJIT_LIBLLVM_PATH"; exit 1; \
	  fi; \
	  $(PY) -m nbrdf_mitsuba.llvm; \
	fi

# tests/test_library_page.py sorts the library's index.html in headless Chromium through its
# chromedriver; install Debian's chromium and chromium-driver only when either is missing. Only a
# test needs them: elsewhere say how, and the test is skipped, naming what is missing.
chromium:
	@if ! command -v chromium >/dev/null || ! command -v chromedriver >/dev/null; then \
	  if command -v apt-get >/dev/null && [ "$$(id -u)" = 0 ]; then \
	    echo "installing chromium and chromium-driver for the library page's browser test"; \
	    packages="chromium chromium-driver"; \
	    DEBIAN_FRONTEND=noninteractive apt-get install -y -q --no-install-recommends $$packages >/dev/null || \
	      { apt-get update -q >/dev/null && DEBIAN_FRONTEND=noninteractive apt-get install -y -q --no-install-recommends $$packages >/dev/null; } || \
	      echo "warning: could not install $$packages; tests/test_library_page.py will be skipped"; \
	  else \
	    echo "note: no chromium or chromedriver found; tests/test_library_page.py will be skipped (Debian: sudo apt-get install chromium chromium-driver)"; \
	  fi; \
	fi

# C users: `make install PREFIX=...` installs the nbrdf command, libnbrdf_ffi (SONAME
# libnbrdf_ffi.so.$(SOVERSION)), nbrdf.h and a pkg-config file nbrdf.pc (see examples/c/).
PREFIX ?= /usr/local
LIBDIR ?= $(PREFIX)/lib
VERSION := $(shell sed -n 's/^version = "\(.*\)"/\1/p' Cargo.toml | head -n 1)
# The ABI's major version, set in nbrdf-ffi/build.rs (which gives the library its SONAME).
SOVERSION := $(shell sed -n 's/^const SOVERSION: &str = "\(.*\)";/\1/p' nbrdf-ffi/build.rs)
install: build
	install -d $(DESTDIR)$(PREFIX)/bin $(DESTDIR)$(LIBDIR)/pkgconfig $(DESTDIR)$(PREFIX)/include
	install -m 755 $(CLI) $(DESTDIR)$(PREFIX)/bin/nbrdf
	install -m 755 $(LIB) $(DESTDIR)$(LIBDIR)/libnbrdf_ffi.so.$(VERSION)
	ln -sf libnbrdf_ffi.so.$(VERSION) $(DESTDIR)$(LIBDIR)/libnbrdf_ffi.so.$(SOVERSION)
	ln -sf libnbrdf_ffi.so.$(SOVERSION) $(DESTDIR)$(LIBDIR)/libnbrdf_ffi.so
	install -m 644 nbrdf-ffi/include/nbrdf.h $(DESTDIR)$(PREFIX)/include/nbrdf.h
	printf '%s\n' 'prefix=$(PREFIX)' 'libdir=$(LIBDIR)' 'includedir=$${prefix}/include' '' \
	  'Name: nbrdf' 'Description: Neural BRDFs and MERL tables (C ABI of nbrdf)' 'Version: $(VERSION)' \
	  'Libs: -L$${libdir} -lnbrdf_ffi' 'Cflags: -I$${includedir}' > $(DESTDIR)$(LIBDIR)/pkgconfig/nbrdf.pc

# The main job on embedded data (about a minute): table, network and sampling fit of one material,
# the Veach scene rendered with both; writes under out/demo/ only. `make demo DEMO_ARGS=--docs-figure`
# writes the labelled picture to the README's docs/images/demo.png instead.
DEMO_ARGS ?=
demo: setup
	$(PY) -m nbrdf_tools demo $(DEMO_ARGS)

# `make test` on CI's two cores: the Rust tests' build runs beside the release builds (its own
# profile directory, so cargo does not serialise them, and the release crates' single codegen unit
# leaves a core idle much of the time), then the Python tests on PYTEST_WORKERS pytest-xdist
# workers (much of a test's time is Dr.Jit's LLVM compiling one kernel on one core). Starting the
# Python tests beside the Rust tests' build instead was slower on two cores.
NPROC := $(shell nproc 2>/dev/null || echo 2)
PYTEST_WORKERS ?= 2
test:
	+$(MAKE) --no-print-directory -j$(NPROC) --output-sync=target setup test-rust
	+$(MAKE) --no-print-directory test-python

test-rust:
	$(CARGO) test --workspace --profile test-release --all-features

test-python: setup
	$(PY) -m pytest tests -q -n $(PYTEST_WORKERS) --dist worksteal

# The plugin's parity, chi2, variant and estimation tests in cuda_ad_* variants instead of llvm_ad_*
# (needs an NVIDIA GPU and driver; tests/conftest.py, NBRDF_TEST_JIT). The CLI's subprocess tests
# are left out: they ask for llvm variants by name.
CUDA_TESTS = test_backends test_sampling test_variants test_spectral test_spectral_networks test_two_lobe \
	test_anisotropic test_tabulated test_many_materials test_usage test_merl_bsdf test_nbrdf_eval \
	test_hardening_plugin test_estimate_latent test_estimate
test-cuda: setup
	NBRDF_TEST_JIT=cuda $(PY) -m pytest $(CUDA_TESTS:%=tests/%.py) -q -rs

# Speed figures (criterion): NBRDF evaluations, MERL lookups and Blinn-Phong samples per second.
bench:
	$(CARGO) bench --workspace

lint:
	$(CARGO) fmt --all --check
	$(CARGO) clippy --workspace --all-targets --all-features -- -D warnings
	$(VENV)/bin/ruff check python tests mitsuba-plugin nbrdf-core/fuzz

clean:
	rm -rf target $(VENV) out mitsuba-plugin/build
