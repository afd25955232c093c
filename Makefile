# Two entry points on a fresh machine: `make demo` and `make test`.
# Each creates .venv when missing and installs the project into it.
PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: demo test clean

$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[test]'
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/posedyn data summary datasets
	@echo
	@echo "Seed 004, position 5: critical depth and chatter frequency at 2000 rpm, and a 0.5 mm cut"
	$(BIN)/posedyn chatter --modes datasets/seeds/hou2023_positions.csv --pose-id P5 --rpm 2000 \
		--teeth 3 --kt-mpa 796 --kn-mpa 169 --radial-immersion 0.5 --milling down --depth-mm 0.5

test: $(STAMP)
	$(BIN)/python -m pytest -q

clean:
	rm -rf $(VENV) build *.egg-info
