# Two commands matter (README): `make demo` and `make test`. Both set up everything first.
PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: demo test lint typecheck system-deps bench clean screenshots

$(STAMP): pyproject.toml
	@$(PYTHON) -c 'import sys; sys.exit("GuideBot needs Python 3.11 or newer, found " + sys.version.split()[0]) if sys.version_info < (3, 11) else None'
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[dev]'
	touch $(STAMP)

system-deps:
	@bash scripts/system-deps.sh

demo: $(STAMP)
	$(BIN)/guidebot demo

lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .

typecheck: $(STAMP)
	$(BIN)/mypy guidebot backend robot_agent building_sim petri_nets bench

test: $(STAMP) system-deps lint typecheck
	$(BIN)/python -m pytest

# The docs' screenshots (docs/screenshots/) come from the browser tests' scenarios.
screenshots: $(STAMP) system-deps
	GUIDEBOT_SCREENSHOTS=1 $(BIN)/python -m pytest tests/web -q

clean:
	rm -rf $(VENV) .pytest_cache .mypy_cache .ruff_cache
