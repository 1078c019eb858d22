# tagloc: the two commands are `make demo` and `make test`.
PYTHON ?= $(shell command -v python3.11 2>/dev/null || command -v python3)
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed

.PHONY: demo test test-slow lint typecheck bench clean

$(STAMP): pyproject.toml
	@command -v $(PYTHON) >/dev/null 2>&1 || { echo "error: $(PYTHON) not found (tagloc needs Python >= 3.11)"; exit 1; }
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -e '.[dev]'
	@touch $(STAMP)

demo: $(STAMP)
	MPLBACKEND=Agg $(BIN)/tagloc demo --out out

lint: $(STAMP)
	$(BIN)/ruff check src tests benchmarks

typecheck: $(STAMP)
	$(BIN)/mypy

# poppler's pdftoppm rasterizes the printed tag sheets in the tests (apt-get only where it is
# missing and apt-get exists; without it those tests skip with a message)
TOOLS_STAMP := $(VENV)/.test-tools

$(TOOLS_STAMP): $(STAMP)
	@command -v pdftoppm >/dev/null 2>&1 || { command -v apt-get >/dev/null 2>&1 && \
		{ { apt-get install -y -q poppler-utils || { apt-get update -q && \
		    apt-get install -y -q poppler-utils; }; } >/dev/null 2>&1 || \
		  echo "note: could not install poppler-utils; the tag-sheet tests will skip"; }; } || true
	@touch $(TOOLS_STAMP)

# the suite runs on every core (pytest-xdist; one module's tests stay on one worker, so its
# module fixtures are computed once)
test: lint typecheck $(TOOLS_STAMP)
	MPLBACKEND=Agg $(BIN)/pytest -q -n auto --dist loadscope

test-slow: $(STAMP) $(TOOLS_STAMP)
	MPLBACKEND=Agg $(BIN)/pytest -q -n auto --dist loadscope --runslow

bench: $(STAMP)
	@for b in benchmarks/bench_*.py; do echo "== $$b"; $(BIN)/python $$b || exit 1; done

clean:
	rm -rf $(VENV) out .pytest_cache .mypy_cache .ruff_cache
