# eigs: two commands for users — `make reproduce` (the built-in default suite) and `make test` (the whole suite).
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
CORES  ?= 2
CONFIG ?= config/config.yaml
PYTEST_WORKERS ?= 2

.PHONY: venv reproduce toy cluster test test-cluster lint bench clean-results

# Bootstrap .venv with pinned dependencies. torch is installed first and pinned (2.13.0 CPU on our machines):
# an unpinned torch pulls a multi-GB CUDA build. The package is installed editable without build isolation
# so the build uses the same pinned torch.
venv: $(VENV)/.installed
$(VENV)/.installed: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet "setuptools>=77" wheel
	$(BIN)/pip install --quiet torch==2.13.0
	$(BIN)/pip install --quiet --no-build-isolation -e ".[dev,slurm]"
	touch $@

reproduce: venv
	$(BIN)/snakemake all --cores $(CORES) --configfile=$(CONFIG)

toy: venv
	$(BIN)/snakemake all --cores $(CORES) --configfile=config/toy.yaml

# On a SLURM cluster's login node: every job through sbatch with the SLURM workflow profile (docs/cluster.md).
# Site options go in SNAKEMAKE_ARGS, e.g. SNAKEMAKE_ARGS="--profile ~/.config/snakemake/mysite".
cluster: venv
	$(BIN)/snakemake all --workflow-profile workflow/profiles/slurm --configfile=$(CONFIG) $(SNAKEMAKE_ARGS)

lint: venv
	$(BIN)/ruff check src tests bench
	$(BIN)/snakemake --lint

test: venv lint
	$(BIN)/pytest -n $(PYTEST_WORKERS) --dist loadfile

# The live SLURM test (root: installs SLURM + munge, starts a one-node cluster; docs/cluster.md). CI runs it.
test-cluster: venv
	$(BIN)/pytest -p no:xdist -m cluster tests/cluster

# The benchmarks as a workflow target (rules/bench.smk): regenerates docs/benchmarks.md; QUICK=1 for a first look in
# minutes (few scenes, sizes and repeats; writes results/bench/benchmarks.md instead).
bench: venv
	$(BIN)/snakemake bench --cores $(CORES) --configfile=$(CONFIG) $(if $(QUICK),--config bench_quick=1)

clean-results:
	rm -rf results logs benchmarks .snakemake
