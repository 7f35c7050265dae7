# The two commands of the README: `make demo` and `make test`.
# Each bootstraps a project-local virtual environment (.venv) once, and again only when pyproject.toml changes.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
OUT    ?= out/cube_stacking

.PHONY: demo test lint bench clean

$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[test]'
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/hrc show tasks/cube_stacking.yaml
	$(BIN)/hrc compile tasks/cube_stacking.yaml --out $(OUT)

test: $(STAMP)
	$(BIN)/ruff check hrc tests scripts
	$(BIN)/mypy hrc
	$(BIN)/python -m pytest -q

lint: $(STAMP)
	$(BIN)/ruff check hrc tests scripts
	$(BIN)/mypy hrc

clean:
	rm -rf $(VENV) out .pytest_cache .hypothesis
