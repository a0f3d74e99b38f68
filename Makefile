# Local virtual environment with everything the stack and its tests need.
# torch is pinned to the CPU build (2.13.0) in the same install, so that nothing else pulls a CUDA build.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed

.PHONY: demo test lint venv clean

venv: $(STAMP)

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet torch==2.13.0 -e '.[test]'
	# MAVProxy without its declared dependencies: on Linux they pull vtk and the GUI opencv-python, which would
	# replace opencv-python-headless; the ones its command line needs are in the test extra (pyproject.toml).
	$(BIN)/python -m pip install --quiet --no-deps MAVProxy==1.8.75
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/hrlsac mission replay missions/library/demo.yaml --policy policies/pretrained/hrl-sac.pt

# One worker per core plus three (at most 5), whole test files per worker so that module fixtures are built once:
# much of the suite waits on real time (UDP flights at 1x, subprocesses starting), and the extra workers fill that.
# The files go out in collection order, the longest first (tests/conftest.py), not reordered by test count.
WORKERS := $(shell $(PYTHON) -c "import os; print(min(5, (os.cpu_count() or 1) + 3))")
test: lint
	$(BIN)/python -m pytest -n $(WORKERS) --dist loadfile --no-loadscope-reorder

lint: $(STAMP)
	$(BIN)/ruff check .

clean:
	rm -rf $(VENV) .pytest_cache
