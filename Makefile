# petsc_htp: two commands, `make demo` and `make test`; both set up on first use.
SHELL := /bin/bash
PYTHON ?= python3
VENV := .venv
VPY := $(VENV)/bin/python
PIP := $(VPY) -m pip
STAMP := $(VENV)/.petsc_htp-setup
PETSC_VERSION := 3.26.1
TORCH_VERSION := 2.13.0
SYS_PKGS := build-essential mpich libmpich-dev libopenblas-dev libboost-dev
PETSC_CONFIGURE_OPTIONS ?= --with-fc=0 --with-x=0 --with-cuda=0 --with-debugging=0
export PETSC_CONFIGURE_OPTIONS

.PHONY: setup bytecode demo test bench-quick clean-venv system

setup: $(STAMP)

# System prerequisites: C compiler, MPICH, BLAS/LAPACK from Debian; the Boost headers (for AMGCL's binding, a
# benchmark baseline) are optional: without root they only earn a note.
system:
	@missing=""; \
	command -v cc >/dev/null || missing="$$missing build-essential"; \
	command -v mpicc >/dev/null || missing="$$missing mpich libmpich-dev"; \
	ldconfig -p | grep -q libopenblas || missing="$$missing libopenblas-dev"; \
	optional=""; test -d /usr/include/boost || optional=" libboost-dev"; \
	if [ -n "$$missing$$optional" ] && [ "$$(id -u)" = 0 ]; then \
	  echo "[setup] installing system packages:$$missing$$optional"; \
	  apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $(SYS_PKGS); \
	elif [ -n "$$missing" ]; then \
	  echo "[setup] missing system packages. Run:"; \
	  echo "    sudo apt-get install -y $(SYS_PKGS)"; \
	  exit 1; \
	elif [ -n "$$optional" ]; then \
	  echo "[setup] no Boost headers: the benchmark will skip AMGCL (sudo apt-get install -y libboost-dev)"; \
	fi

$(STAMP): pyproject.toml | system
	@test -x $(VPY) || $(PYTHON) -m venv $(VENV)
	$(PIP) install -q --upgrade pip setuptools wheel numpy cython
	@if [ -n "$$PETSC_DIR" ]; then \
	  echo "[setup] using existing PETSc at PETSC_DIR=$$PETSC_DIR PETSC_ARCH=$$PETSC_ARCH"; \
	else \
	  echo "[setup] building PETSc $(PETSC_VERSION) from source (first time about 8 min)"; \
	  $(PIP) install -q petsc==$(PETSC_VERSION); \
	fi
	$(PIP) install -q --no-build-isolation petsc4py==$(PETSC_VERSION)
	$(PIP) install -q --no-binary mpi4py mpi4py
	$(PIP) install -q torch==$(TORCH_VERSION)
	@$(PIP) install -q pybind11 && $(PIP) install -q --no-build-isolation pyamgcl \
	  || echo "[setup] pyamgcl (AMGCL) did not build: the benchmark names it and skips its rows"
	$(PIP) install -q -e '.[bench,dev,learned]'
	@touch $(STAMP)
	@echo "[setup] done"

# The package's bytecode, as a regular pip install writes it: an editable install leaves it to the first import,
# which writes none under PYTHONDONTWRITEBYTECODE, so every process (each mpiexec rank of the tests, a user's first
# solve) would compile the modules it loads anew: a fresh process's first HTPPC setup of a 65 536-row 5-point matrix
# took 129-130 ms without the bytecode, 100-104 with it (2026-11-27, this 2-core machine).
bytecode: setup
	@$(VPY) -m compileall -q petsc_htp

demo: bytecode
	$(VPY) examples/poisson_multiphase.py -n 4096 -compare -plot results/demo.png

test: bytecode
	$(VPY) -m pytest -q tests

bench-quick: bytecode
	$(VPY) -m petsc_htp.bench --quick

clean-venv:
	rm -rf $(VENV)
