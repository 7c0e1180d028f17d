# Two commands matter (README): `make demo` and `make test`. Both set up everything first.
# The venv's packages are installed by uv (from PyPI, into the venv): the same versions as pip
# picks, in 8 s instead of pip's 35 s with a warm cache (28 Nov 2026); `make test` waits for it.
PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: demo test suite lint typecheck system-deps bench clean screenshots vendor-web

$(STAMP): pyproject.toml
	@$(PYTHON) -c 'import sys; sys.exit("GuideBot needs Python 3.11 or newer, found " + sys.version.split()[0]) if sys.version_info < (3, 11) else None'
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet 'uv>=0.5'
	$(BIN)/uv pip install --quiet --python $(BIN)/python -e '.[dev,peers]'
	touch $(STAMP)

system-deps:
	@bash scripts/system-deps.sh

# The demo's VDA 5050 vehicle needs a broker: Debian's mosquitto, installed when missing.
demo: $(STAMP)
	@bash scripts/system-deps.sh mosquitto
	$(BIN)/guidebot demo

# The web pages' JavaScript against web/lib/messages.d.ts (`guidebot webtypes`): the TypeScript
# checker pinned in tools/typecheck/ (a development tool; the pages need no Node.js).
TSC_STAMP := tools/typecheck/node_modules/.installed
$(TSC_STAMP): tools/typecheck/package-lock.json
	@bash scripts/system-deps.sh nodejs npm
	npm ci --prefix tools/typecheck --no-audit --no-fund --ignore-scripts
	touch $@

lint: $(STAMP) $(TSC_STAMP)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .
	$(BIN)/lint-imports
	tools/typecheck/node_modules/.bin/tsc -p tools/typecheck

typecheck: $(STAMP)
	$(BIN)/mypy guidebot backend robot_agent building_sim petri_nets bench

# The suite's tests wait on servers, browsers and robots, but the CPUs are busy most of the run:
# four pytest-xdist workers (WORKERS) share 2 CPUs (six took 20 min and 2305 CPU-s, four 17 min and
# 1600 CPU-s, three 18.5 min: README), and lint and the type check (15 s of one CPU) run beside them
# (their few lines come among pytest's first ones); any of the three failing fails `make test`
# once the others end. The set-up runs side by side too: the venv's install, the Debian
# packages' check (and the sign-on tests' npm ci) and the TypeScript checker's npm ci
# (scripts/system-deps.sh takes a lock, so two of its runs never call apt at once).
# `--dist loadgroup` keeps the docker tests in one worker; they start first (tests/conftest.py).
WORKERS ?= 4
test:
	$(MAKE) --no-print-directory -j 3 lint typecheck suite

suite: $(STAMP) system-deps
	$(BIN)/python -m pytest -n $(WORKERS) --dist loadgroup

# docs/screenshots/*.png from the browser tests' scenarios (needs Debian's chromium-headless-shell).
screenshots: $(STAMP) system-deps
	GUIDEBOT_SCREENSHOTS=1 $(BIN)/python -m pytest tests/web -q

# Re-copy the pinned front-end libraries into web/vendor/ (needs npm; run after a version bump).
vendor-web:
	bash scripts/vendor-web.sh

clean:
	rm -rf $(VENV) .pytest_cache .mypy_cache .ruff_cache
