# All set-up lives here: `make demo` and `make test` work from a clean clone.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.setup-stamp
DEMO_OUT ?= demo_out
# Test worker processes (pytest-xdist): each takes whole test modules, so a module's fixtures are built once.
# Two on a 2-core machine: the suite alone keeps one core about half idle (Python between renders).
TEST_WORKERS ?= 2

.PHONY: setup demo test lint format clean

setup: $(STAMP)

# Idempotent: re-runs only when the pins or the package metadata change.
$(STAMP): requirements.txt requirements-nodeps.txt pyproject.toml scripts/ensure_llvm.sh
	bash scripts/ensure_llvm.sh
	bash scripts/ensure_sandbox.sh
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip setuptools
	$(PY) -m pip install --quiet -r requirements.txt
	$(PY) -m pip install --quiet --no-deps -r requirements-nodeps.txt
	$(PY) -c "import torch; v = torch.__version__.split('+')[0]; assert v == '2.13.0', f'torch {v} replaced 2.13.0'"
	$(PY) -m pip install --quiet --no-deps --no-build-isolation -e .
	touch $(STAMP)

demo: setup
	$(VENV)/bin/denoisebench demo --out $(DEMO_OUT)

test: setup lint
	bash scripts/ensure_chromium.sh
	$(PY) -m pytest -q -n $(TEST_WORKERS) --dist loadfile tests

# One style, enforced: ruff's linter and formatter, configured in pyproject.toml.
lint: setup
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .

format: setup
	$(VENV)/bin/ruff check --fix .
	$(VENV)/bin/ruff format .

clean:
	rm -rf $(VENV) $(DEMO_OUT) build *.egg-info
