# Two commands on a fresh machine: `make demo` and `make test`.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: demo test bench lint docs-images clean

$(PY):
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip

$(STAMP): pyproject.toml | $(PY)
	$(PY) -m pip install --quiet -e ".[viz,dev,scale,fast]"
	touch $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/regrasp-pin demo --out out

# The suite runs on one pytest-xdist worker per logical core (`make test PYTEST_WORKERS=0`:
# in one process). worksteal gives each worker a contiguous share of the tests, so that a
# module's fixtures are mostly built once, and lets an idle worker take over the end of
# another's share.
PYTEST_WORKERS ?= logical

test: $(STAMP)
	$(PY) -m pytest -q -n $(PYTEST_WORKERS) --dist worksteal

bench: $(STAMP)
	$(PY) bench/ik.py
	$(PY) bench/polygon.py
	$(PY) bench/manifold.py
	$(PY) bench/demo.py

lint: $(STAMP)
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .
	$(PY) -m mypy

# the README's table and figures: what make demo prints and draws
docs-images: $(STAMP)
	$(VENV)/bin/regrasp-pin demo --out out --quiet
	cp out/fig9_joint_angles.png out/fig2_manifold.png out/fig8_hopfield_path.png docs/
	$(PY) docs/make_screenshots.py --plan out/plan.json

clean:
	rm -rf $(VENV) out .pytest_cache build *.egg-info
