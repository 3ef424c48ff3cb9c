# Two entry points for a fresh machine with Python 3.11 and make:
#   make run   - install into .venv if needed, then run the main job
#   make test  - install into .venv if needed, then run the test suite
PYTHON ?= python3.11
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed

.PHONY: run test venv lock bench docs clean

venv: $(STAMP)

# requirements.lock is a full freeze (`make lock`): nothing needs resolving, and --no-deps keeps
# out what the packages of requirements-nodeps.in declare but do not need here.
$(STAMP): requirements.lock pyproject.toml
	@command -v $(PYTHON) >/dev/null 2>&1 || { echo "error: $(PYTHON) not found (Python 3.11 is required)"; exit 1; }
	@test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip
	$(BIN)/python -m pip install -q --no-deps -r requirements.lock
	$(BIN)/python -m pip install -q --no-deps -e .
	@touch $(STAMP)

run: $(STAMP)
	$(BIN)/ellipsled run case1 --out runs/latest

# Two workers for every test that asserts no wall-clock figure (real-time SIL runs one at a
# time among them: marker realtime), then the few timing tests alone (marker timing).
test: $(STAMP)
	$(BIN)/python -m pytest -q -n 2 --dist loadgroup -m "not timing"
	$(BIN)/python -m pytest -q -m timing

bench: $(STAMP)
	$(BIN)/ellipsled bench --out runs/bench.json

# The documentation site: the reference pages generated from the code (ellipsled/docsgen.py),
# then MkDocs with --strict (a broken link or a page missing from the nav fails) into site/.
docs: $(STAMP)
	$(BIN)/python -m ellipsled.docsgen
	$(BIN)/python -m interfaces.event_metadata
	NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs build --strict --site-dir site

# Refresh the full lock from the direct dependencies (requirements-nodeps.in: without theirs).
lock:
	$(PYTHON) -m venv /tmp/ellipsled-lock && /tmp/ellipsled-lock/bin/pip install -q -r requirements.in \
	  && /tmp/ellipsled-lock/bin/pip install -q --no-deps -r requirements-nodeps.in \
	  && /tmp/ellipsled-lock/bin/pip freeze --exclude-editable > requirements.lock && rm -rf /tmp/ellipsled-lock

clean:
	rm -rf $(VENV) runs
