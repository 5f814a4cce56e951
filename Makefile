# The README's two commands: `make demo` (the main job on the paper's radar) and `make test`.
# Both build a virtual environment in .venv from pyproject.toml first; nothing else is needed
# on a fresh machine with Python 3.10+ (PoCL, the OpenCL CPU device, comes from PyPI).
PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin

.PHONY: demo test bench info clean

$(BIN)/.installed: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[test,serial]'
	touch $@

demo: $(BIN)/.installed
	$(BIN)/radarcl demo --out out/demo

test: $(BIN)/.installed
	$(BIN)/python -m pytest -q

bench: $(BIN)/.installed
	$(BIN)/radarcl bench range-fft

info: $(BIN)/.installed
	$(BIN)/radarcl info

clean:
	rm -rf $(VENV) out build *.egg-info
