# The two commands of the README: `make demo` and `make test`.
# Each bootstraps a project-local virtual environment (.venv) once, and again only when pyproject.toml changes.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
OUT    ?= out/cube_stacking

.PHONY: demo test lint bench clean browser

$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[test]'
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/hrc show tasks/cube_stacking.yaml
	$(BIN)/hrc compile tasks/cube_stacking.yaml --out $(OUT)

test: $(STAMP) browser
	$(BIN)/ruff check hrc tests scripts
	$(BIN)/mypy hrc
	$(BIN)/python -m pytest -q

# The console's browser tests drive Debian's Chromium: installed here when missing and run as root (as CI
# runs); otherwise those tests skip and say why.
browser:
	@command -v chromium >/dev/null 2>&1 || { [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1 && \
	  DEBIAN_FRONTEND=noninteractive apt-get update -q && \
	  DEBIAN_FRONTEND=noninteractive apt-get install -y -q chromium >/dev/null; } || \
	  echo "make: no chromium (as root: apt-get install chromium): the console's browser tests will skip"

lint: $(STAMP)
	$(BIN)/ruff check hrc tests scripts
	$(BIN)/mypy hrc

clean:
	rm -rf $(VENV) out .pytest_cache .hypothesis
