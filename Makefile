# Two entry points that work on a fresh machine with only Python >= 3.11:
#   make demo   set up .venv, run the main job on the built-in default, write out/demo/
#   make test   set up .venv, run the whole test suite (about 38 min on 2 cores)
#   make check  set up .venv, run the suite without the slow tests (-m "not slow", ~10 min)
# Both install the exact versions of requirements/lock.txt (with hashes), then flexarm
# itself without dependencies; only pip is needed. `make lock` regenerates the lock from
# pyproject.toml's ranges (keeping the current pins where they still fit; add
# LOCK_FLAGS=--upgrade to move every pin to the newest allowed version).
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
LOCK   := requirements/lock.txt
# The lock tool lives in its own throwaway venv, never in .venv; its version is pinned
# so that two developers regenerating the lock get the same resolver.
LOCKVENV   := .venv-lock
UV_VERSION := 0.13.9
LOCK_FLAGS ?=

.PHONY: demo test check bench lock docs notebooks clean

$(STAMP): pyproject.toml $(LOCK)
	@$(PYTHON) -c 'import sys; assert sys.version_info >= (3, 11), "flexarm needs Python >= 3.11, found " + sys.version.split()[0]'
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet --require-hashes -r $(LOCK)
	$(BIN)/python -m pip install --quiet --no-deps -e .
	@touch $(STAMP)

# The test and demo environment: Python 3.11 on Linux x86_64, pyproject.toml + [test] +
# [docs] + [distributed] (the docs site and Dask, so that the suite builds the docs and runs the distributed tests).
lock:
	$(PYTHON) -m venv $(LOCKVENV)
	$(LOCKVENV)/bin/python -m pip install --quiet 'uv==$(UV_VERSION)'
	$(LOCKVENV)/bin/uv pip compile pyproject.toml --extra test --extra docs --extra distributed \
	    --python-version 3.11 --python-platform x86_64-unknown-linux-gnu \
	    --generate-hashes --quiet --custom-compile-command 'make lock' $(LOCK_FLAGS) -o $(LOCK)

demo: $(STAMP)
	$(BIN)/flexarm demo --out out/demo --overwrite

# The suite runs its files on TEST_WORKERS processes (pytest-xdist; --dist loadfile keeps
# each file, and so its module-scoped shared fits, in one process). TEST_WORKERS=0: one
# process, as plain `pytest` does.
TEST_WORKERS ?= 2

# The HTML report's browser test needs Chromium: in CI (CI=true, root, apt-get) it is
# installed when missing; if that fails the test skips, saying why.
test: $(STAMP)
	@if [ "$$CI" = true ] && ! command -v chromium >/dev/null 2>&1 \
	    && command -v apt-get >/dev/null 2>&1 && [ "$$(id -u)" = 0 ]; then \
	    echo "installing chromium for the HTML report's browser test"; \
	    (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium) \
	    >/dev/null 2>&1 || echo "chromium not installed: the browser test will skip"; fi
	$(BIN)/python -m pytest -q -n $(TEST_WORKERS) --dist loadfile

# The quick check: the suite without the slow end-to-end tests (docs/performance.md: 693
# passed in 10 min 24 s on two processes of a 2-core EPYC, nothing else running).
check: $(STAMP)
	$(BIN)/python -m pytest -q -n $(TEST_WORKERS) --dist loadfile -m "not slow"

# The documentation site (mkdocs.yml: mkdocs-material, mkdocstrings, mkdocs-jupyter) into
# site/, warnings as errors, the notebooks executed; docs/hooks.py generates the scenario
# reference and the API pages at build time. tests/test_docs__site.py builds it too.
docs: $(STAMP)
	NO_MKDOCS_2_WARNING=1 FLEXARM_DOCS_EXECUTE=true $(BIN)/python -m mkdocs build --strict --site-dir site

# The notebooks of docs/notebooks/ executed and written with their outputs, so that GitHub
# shows their figures (docs/make_notebooks.py --execute; about 2.5 min on 2 cores, the
# real-log cells where ../shared/data is present). Not part of `make test`, which executes
# them without keeping the outputs (tests/test_docs__notebooks.py).
notebooks: $(STAMP)
	$(BIN)/python docs/make_notebooks.py --execute

bench: $(STAMP)
	for f in benchmarks/*.py; do $(BIN)/python $$f || exit 1; done

clean:
	rm -rf $(VENV) $(LOCKVENV) out site .pytest_cache
