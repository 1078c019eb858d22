# tagloc: the two commands are `make demo` and `make test`.
PYTHON ?= $(shell command -v python3.11 2>/dev/null || command -v python3)
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed

.PHONY: demo test test-slow test-dimos lint typecheck bench clean

$(STAMP): pyproject.toml
	@command -v $(PYTHON) >/dev/null 2>&1 || { echo "error: $(PYTHON) not found (tagloc needs Python >= 3.11)"; exit 1; }
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -e '.[dev]'
	@touch $(STAMP)

demo: $(STAMP)
	MPLBACKEND=Agg $(BIN)/tagloc demo --out out

lint: $(STAMP)
	$(BIN)/ruff check src tests tests_dimos benchmarks

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

# The dimos adapter against the real dimos (its own virtualenv, about 3.2 GB; not part of `make test`).
# dimos brings opencv-contrib-python, which provides the same cv2 as tagloc's
# opencv-python-headless: tagloc's other requirements are installed beside it, never the second cv2.
DVENV  := .venv-dimos
DBIN   := $(DVENV)/bin
DSTAMP := $(DVENV)/.installed

$(DSTAMP): pyproject.toml
	@command -v $(PYTHON) >/dev/null 2>&1 || { echo "error: $(PYTHON) not found (dimos needs Python 3.10-3.12)"; exit 1; }
	@ldconfig -p | grep -q 'libusb-1.0.so.0' || apt-get install -y --no-install-recommends libusb-1.0-0 \
		|| { apt-get update && apt-get install -y --no-install-recommends libusb-1.0-0; }
	test -x $(DBIN)/python || $(PYTHON) -m venv $(DVENV)
	$(DBIN)/pip install --quiet --upgrade pip
	$(DBIN)/pip install --quiet 'dimos==0.0.15' pytest
	$(DBIN)/pip install --quiet $$($(DBIN)/python -c "import tomllib; d = tomllib.load(open('pyproject.toml', 'rb'))['project']['dependencies']; print(' '.join(r for r in d if not r.startswith('opencv-python-headless')))")
	$(DBIN)/pip install --quiet --no-deps -e .
	@touch $(DSTAMP)

test-dimos: $(DSTAMP)
	MPLBACKEND=Agg $(DBIN)/pytest -q -p no:cacheprovider tests_dimos

bench: $(STAMP)
	@for b in benchmarks/bench_*.py; do echo "== $$b"; $(BIN)/python $$b || exit 1; done

clean:
	rm -rf $(VENV) $(DVENV) out .pytest_cache .mypy_cache .ruff_cache
