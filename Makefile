# eigs: for users `make demo` (one scene, the four runs that tell the story: table, grid, orbit video), `make toy`
# (the CI-sized scene), `make reproduce` (the built-in default suite) and `make test` (the whole test suite).
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
CORES  ?= 2
CONFIG ?= config/config.yaml
PYTEST_WORKERS ?= 2

.PHONY: venv demo reproduce toy cluster test test-cluster kill-sweep lint bench gpu-bundle gpu-wheels clean-results

# Bootstrap .venv with pinned dependencies. torch is installed first, by pip and pinned (2.13.0 CPU on our
# machines, pip takes it from the machine's local wheel): an unpinned torch pulls a multi-GB CUDA build. No bytecode
# is compiled at install (Python compiles what it imports, once). The package and the rest of its dependencies are
# installed by uv (pinned in pyproject.toml; 7 s against pip's 93 s here), editable without build isolation so the
# build uses the same pinned torch. Then the one-time work of a first run, done here instead of inside the first
# job or test: the C++ rasterizer is built into the cache (eigs.render._backend; it rebuilds itself when its sources
# change) in the background while the LPIPS/BRISQUE model files are fetched into resources/ (`eigs resources`;
# offline, a warning: the workflow's rule fetches them when it first needs them).
venv: $(VENV)/.installed
$(VENV)/.installed: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet "setuptools>=77" wheel uv==0.13.9
	$(BIN)/pip install --quiet --no-compile torch==2.13.0
	$(BIN)/uv pip install --python $(BIN)/python --quiet --no-build-isolation -e ".[dev,slurm]"
	$(BIN)/python -c "from eigs.render._backend import load; print('C++ rasterizer:', load().__file__)" & build=$$!; \
	  $(BIN)/eigs resources || echo "make venv: eigs resources failed (offline?); the workflow's resources rule fetches them later"; \
	  wait $$build
	touch $@

# One built-in scene (chair) at the suite's size, blur, poses and budgets: 3dgs, edi-3dgs, eigs+ and the oracle,
# evaluated, then Table I, the qualitative grid and the orbit video (config/demo.yaml). eigs+ (the longest run) is
# scheduled first, so the other three share the second core with it.
DEMO_CONFIG ?= config/demo.yaml
demo: venv
	$(BIN)/snakemake all --cores $(CORES) --prioritize results/chair/b4/eigs+/model.ply --configfile=$(DEMO_CONFIG)
	@echo
	@cat results/tables/table1.md
	@echo
	@echo "table: results/tables/table1.md   grid: results/figures/qualitative_chair.png   video: results/videos/chair.mp4"

reproduce: venv
	$(BIN)/snakemake all --cores $(CORES) --configfile=$(CONFIG)

toy: venv
	$(BIN)/snakemake all --cores $(CORES) --configfile=config/toy.yaml

# The default suite plus the ladder from the paper's EiGS to eigs+ (config/ladder.yaml; its own table, outside `all`
# of the default config alone): trains only the ladder's runs once the suite has run.
ladder: venv
	$(BIN)/snakemake --cores $(CORES) --configfile config/config.yaml config/ladder.yaml -- all

# On a SLURM cluster's login node: every job through sbatch with the SLURM workflow profile (docs/cluster.md).
# Site options go in SNAKEMAKE_ARGS, e.g. SNAKEMAKE_ARGS="--profile ~/.config/snakemake/mysite".
cluster: venv
	$(BIN)/snakemake all --workflow-profile workflow/profiles/slurm --configfile=$(CONFIG) $(SNAKEMAKE_ARGS)

lint: venv
	$(BIN)/ruff check src tests bench
	$(BIN)/snakemake --lint

test: venv lint
	$(BIN)/pytest -n $(PYTEST_WORKERS) --dist loadfile

# The kill sweep (tests/faults/test_kill.py): the kill config's workflow killed with SIGKILL at 21 seeded instants
# that hit every rule, recovered each time as README.md says, ending with the uninterrupted run's tables. `make test`
# runs four instants.
kill-sweep: venv
	EIGS_KILL_INSTANTS=21 $(BIN)/pytest -p no:xdist -s tests/faults/test_kill.py

# The live SLURM test (root: installs SLURM + munge, starts a one-node cluster; docs/cluster.md). CI runs it.
test-cluster: venv
	$(BIN)/pytest -p no:xdist -m cluster tests/cluster

# The benchmarks as a workflow target (rules/bench.smk): regenerates docs/benchmarks.md; QUICK=1 for a first look in
# minutes (few scenes, sizes and repeats; writes results/bench/benchmarks.md instead).
bench: venv
	$(BIN)/snakemake bench --cores $(CORES) --configfile=$(CONFIG) $(if $(QUICK),--config bench_quick=1)

# The GPU check's inputs (issue 34; bench/gpu_check.sh, docs/benchmarks.md "GPU path"), both in folders that
# .git/info/exclude ignores: .gpu_bundle (chair's scene, EDI, SfM poses, init.ply and the LPIPS-alex weights, made by
# the workflow in a scratch worktree at HEAD so this checkout's results/ and Snakemake lock stay untouched) and .whl
# (the wheels the GPU machine lacks: gsplat of the `gpu` extra and plyfile; the rest is there already).
GPU_WORKTREE ?= /tmp/eigs-gpu-bundle
GPU_SCENE ?= chair
GPU_BINS ?= 4
EXCLUDE = $(shell git rev-parse --git-path info/exclude)
gpu-bundle: venv
	grep -qx '/.gpu_bundle/' $(EXCLUDE) 2>/dev/null || echo '/.gpu_bundle/' >> $(EXCLUDE)
	test -d $(GPU_WORKTREE) || git worktree add --detach $(GPU_WORKTREE) HEAD
	cd $(GPU_WORKTREE) && PATH=$(CURDIR)/$(BIN):$$PATH PYTHONPATH=$(GPU_WORKTREE)/src $(CURDIR)/$(BIN)/snakemake \
		--cores 1 --configfile config/config.yaml results/$(GPU_SCENE)/scene.h5 results/$(GPU_SCENE)/b$(GPU_BINS)/edi.h5 \
		results/$(GPU_SCENE)/b$(GPU_BINS)/sfm results/$(GPU_SCENE)/b$(GPU_BINS)/init.ply resources/lpips/MANIFEST.json
	$(BIN)/python bench/gpu_check.py bundle --directory $(GPU_WORKTREE) --scene $(GPU_SCENE) -o .gpu_bundle

gpu-wheels: venv
	grep -qx '/.whl/' $(EXCLUDE) 2>/dev/null || echo '/.whl/' >> $(EXCLUDE)
	$(BIN)/pip download --quiet --no-deps --only-binary=:all: --python-version 3.12 --implementation cp \
		--platform manylinux_2_28_x86_64 --platform manylinux_2_17_x86_64 --platform manylinux2014_x86_64 \
		-d .whl gsplat==1.5.3 plyfile==1.1.5

clean-results:
	rm -rf results logs benchmarks .snakemake
