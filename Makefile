# The README's two commands: `make demo` (the main job on the paper's radar, 0.2 m voxels) and `make test`.
# Both build a virtual environment in .venv from pyproject.toml first (PoCL, the OpenCL CPU
# device, comes from PyPI) and check the system libraries the viewer needs: Mesa's EGL for
# headless rendering and Xvfb for the window test; `make test` also Chromium (the reports are
# opened in a real browser), and Debian's PoCL where apt-get can (see SYSTEM_PACKAGES_OPENCL).
# Missing ones are installed with apt-get when
# running as root (CI, a fresh machine); otherwise make stops and names them.
PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin

SYSTEM_PACKAGES_EGL := libegl1 libegl-mesa0 libgl1-mesa-dri
SYSTEM_PACKAGES_X := xvfb xauth
SYSTEM_PACKAGES_BROWSER := chromium
# Debian's PoCL 3.1 (LLVM 15) beside PyPI's 3.0 (LLVM 14): it builds on CPUs LLVM 14 does not know
# (AMD Zen 5 reads as 'generic' there and every build fails) and ran our kernels faster
# (ARCHITECTURE.md). Optional: installed where apt-get can, otherwise PyPI's PoCL is used.
SYSTEM_PACKAGES_OPENCL := pocl-opencl-icd
# Oclgrind, a simulated OpenCL device that reports out-of-bounds accesses, data races and API
# misuse: `make check-kernels` runs the kernels' tests on it, `make test` a small slice of them.
SYSTEM_PACKAGES_OCLGRIND := oclgrind

.PHONY: demo demo-full test docs check-kernels fuzz bench bench-device info clean system

$(BIN)/.installed: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[test,serial,viewer,export,fleet,docs,ros]'
	touch $@

system:
	@missing=""; \
	ldconfig -p | grep -q 'libEGL_mesa.so' || missing="$$missing $(SYSTEM_PACKAGES_EGL)"; \
	command -v xvfb-run >/dev/null || missing="$$missing $(SYSTEM_PACKAGES_X)"; \
	[ -z "$(NEED_BROWSER)" ] || command -v chromium >/dev/null || missing="$$missing $(SYSTEM_PACKAGES_BROWSER)"; \
	[ -z "$(NEED_OCLGRIND)" ] || command -v oclgrind >/dev/null || missing="$$missing $(SYSTEM_PACKAGES_OCLGRIND)"; \
	{ [ -e /etc/OpenCL/vendors/pocl.icd ] && ldconfig -p | grep -q 'libpocl.so'; } || { [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null && missing="$$missing $(SYSTEM_PACKAGES_OPENCL)"; } || \
	  echo "note: no system PoCL; using PyPI's PoCL 3.0 (LLVM 14), which cannot build for CPUs newer than LLVM 14 (AMD Zen 4/5): radarcl info says"; \
	if [ -n "$$missing" ]; then \
	  if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null; then \
	    echo "installing$$missing (apt-get)"; \
	    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $$missing >/dev/null; \
	  else \
	    echo "missing system packages:$$missing; install them (apt-get install$$missing) and rerun"; exit 1; \
	  fi; \
	fi

demo: system $(BIN)/.installed
	$(BIN)/radarcl demo --out out/demo

# The main job at the paper's 0.1 m voxels: eight times the voxels of `make demo`, several GiB.
demo-full: system $(BIN)/.installed
	$(BIN)/radarcl demo --full --out out/demo-full

test: NEED_BROWSER := 1
test: NEED_OCLGRIND := 1
test: system $(BIN)/.installed
	$(BIN)/python -m pytest -q

# Every kernel file's tests on Oclgrind (--check-api --data-races, built at -cl-opt-disable), once
# on the CPU code paths and once with a 32 KiB GPU's limits; fails on any report Oclgrind prints and
# prints the counts per kernel file (tests/oclgrind_check.py; --full there runs every size).
check-kernels: NEED_OCLGRIND := 1
check-kernels: system $(BIN)/.installed
	$(BIN)/python tests/oclgrind_check.py

# The long fuzz run: 16x the CI examples, the counts written to out/fuzz.json (configurations,
# frames, files, streams) and out/fuzz_store.json (map stores, stream recordings).
fuzz: $(BIN)/.installed
	mkdir -p out && RADARCL_FUZZ=long RADARCL_FUZZ_REPORT=out/fuzz.json RADARCL_FUZZ_STORE_REPORT=out/fuzz_store.json \
	  $(BIN)/python -m pytest -q -W ignore::hypothesis.errors.HypothesisWarning tests/test_fuzz.py tests/test_fuzz_store.py

bench: $(BIN)/.installed
	$(BIN)/radarcl bench range-fft

# Every benchmark that tells a device apart, in one run of at most about 5 minutes (for a lent GPU;
# a GPU is preferred, RADARCL_DEVICE picks another device): a table on stdout, every figure in
# out/bench-device.json; the exit status is 1 when a bench failed (its error is in both).
bench-device: $(BIN)/.installed
	$(BIN)/radarcl bench all --json out/bench-device.json

# The documentation site into site/ (mkdocs.yml; `$(BIN)/mkdocs serve` to browse it while editing).
docs: $(BIN)/.installed
	$(BIN)/mkdocs build --strict --site-dir site

info: $(BIN)/.installed
	$(BIN)/radarcl info

clean:
	rm -rf $(VENV) out build site *.egg-info
