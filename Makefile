# droidw: set-up, tests and the demo.  `make install` is all a fresh machine needs.
PYTHON ?= python3
VENV   ?= .venv
PY      = $(VENV)/bin/python
PIP     = $(PY) -m pip
PYTEST_ARGS ?=

.PHONY: install test demo bench clean

$(PY):
	$(PYTHON) -m venv $(VENV)

install: $(PY)
	$(PIP) install -q --upgrade pip
	# torch first: 2.13.0 resolves to the local CPU wheel (any other pin pulls CUDA).
	$(PIP) install -q torch==2.13.0
	# the optional extras too (Ray for `droidw batch`, rerun for `droidw view`), so that `make test` covers them
	# constraints.txt pins the builds the README's figures were measured with (OpenCV moves them)
	$(PIP) install -q -c constraints.txt -e ".[test,ray,view]" -e backends/cpu -e backends/cuda -e backends/native

test: install
	$(PY) -m pytest -q $(PYTEST_ARGS)

demo: install
	$(VENV)/bin/droidw demo

bench: install
	$(PY) benchmarks/ba_bench.py
	$(PY) benchmarks/track_bench.py
	$(PY) benchmarks/dynamic_bench.py
	$(PY) benchmarks/flow_bench.py

clean:
	rm -rf $(VENV) build dist droidw-demo .pytest_cache
