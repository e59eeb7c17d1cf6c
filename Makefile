# Quick start (fresh Debian, as root):  make demo   |   make test
PY ?= python3

.PHONY: setup demo test test-all reports subckts

setup:  ## install ngspice, Icarus Verilog and Berkeley ABC (Debian) and the package with its Python dependencies
	@dpkg -s ngspice libngspice0 iverilog berkeley-abc >/dev/null 2>&1 || sh scripts/apt_install.sh ngspice libngspice0 iverilog berkeley-abc
	@echo "make setup: pip install -e '.[test,vacask,mc]' (quiet: prints nothing until it ends)"
	$(PY) -m pip install -q --root-user-action=ignore -e '.[test,vacask,mc]'

# the demo's reports: untracked, so a demo never rewrites the committed reports/
DEMO_OUT ?= build/demo

demo: setup  ## the main job end to end: gate, adder from Verilog on RK4, sqrt(2809), the sieve on 6486 oscillators
	@mkdir -p $(DEMO_OUT)
	mech2spice gate --report $(DEMO_OUT)
	mech2spice synth verilog/adder2.v
	mech2spice simulate verilog/adder2.v --set a=3 --set b=2 --backend logic
	mech2spice simulate verilog/adder2.v --set a=3 --set b=2 --backend rk4
	mech2spice report adder --out $(DEMO_OUT)
	mech2spice simulate verilog/sqrt.v --stimulus verilog/sqrt_2809.json --backend envelope
	mech2spice cpu run programs/sieve.asm --backend envelope

# one pytest worker per core, a test file per worker (its module fixtures built once), one BLAS thread each
PYTEST ?= OMP_NUM_THREADS=1 $(PY) -m pytest -q -n auto --dist loadfile

test: setup  ## the CI suite (long physical runs marked slow are left out)
	$(PYTEST) -m "not slow"

test-all: setup
	$(PYTEST)

reports: setup  ## regenerate every report in reports/ (hours; `mech2spice report --list` gives each one's cost)
	mech2spice report all
