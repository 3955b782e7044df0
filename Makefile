# Two commands do everything on a fresh machine (README.md; the docs site: make docs):
#   make demo   -- virtual environment, install, run the main job end to end
#   make test   -- virtual environment with dev extras, lint, type check, tests, the docs site
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
PIP    := $(BIN)/python -m pip
DEMO   ?= build/demo

.PHONY: demo studies test lint typecheck pytest pytest-varied docs venv clean recordings help schemas

$(BIN)/python:
	$(PYTHON) -c 'import sys; assert sys.version_info >= (3, 11), "Python >= 3.11 required, found " + sys.version'
	$(PYTHON) -m venv $(VENV)
	$(PIP) install --quiet --upgrade pip

# torch comes from constraints.txt (2.13.0, local CPU build) *before* anything
# that depends on it is resolved, so no CUDA build is ever pulled.
$(VENV)/.installed: $(BIN)/python pyproject.toml constraints.txt
	$(PIP) install --quiet -c constraints.txt torch
	$(PIP) install --quiet -c constraints.txt -e .
	touch $@

$(VENV)/.installed-dev: $(VENV)/.installed
	$(PIP) install --quiet -c constraints.txt -e '.[dev]'
	touch $@

venv: $(VENV)/.installed

demo: $(VENV)/.installed
	@mkdir -p $(DEMO)
	$(BIN)/rocketroll tunnel --seed 0 --out $(DEMO)/tunnel-seed0.csv
	$(BIN)/rocketroll info $(DEMO)/tunnel-seed0.csv --plot $(DEMO)/tunnel-seed0.png
	$(BIN)/rocketroll identify identification/data/tunnel-paper-seed0.csv \
		--report $(DEMO)/identify-paper-seed0 --json $(DEMO)/identify-paper-seed0.json
	$(BIN)/rocketroll db build
	$(BIN)/rocketroll db list --kind identified --method paper
	$(BIN)/rocketroll db show 2d68d98ae09b-paper-theta-iaaft-0 --plot $(DEMO)/surrogate.png
	$(BIN)/rocketroll env rollout --policy zero --episodes 2 --frames $(DEMO)/env-zero.png
	$(BIN)/rocketroll env rollout --policy random --episodes 2 --frames $(DEMO)/env-random.png
	$(BIN)/rocketroll eval --env-id RocketRoll-v0 --episodes 20 --seed 0 --out $(DEMO)/eval-angle
	$(BIN)/rocketroll eval --env-id RocketRollRate-v0 --episodes 20 --seed 0 --out $(DEMO)/eval-rate
	$(BIN)/rocketroll seeds --env-id RocketRoll-v0 \
		$(foreach s,0 1 2 3 4,--run ppo:agents/policies/seeds/RocketRoll-v0/ppo/seed$(s)) \
		$(foreach s,0 1 2 3 4,--run ppo-zero=ppo:agents/policies/seeds/RocketRoll-v0/ppo-zero/seed$(s)) \
		$(foreach s,0 1 2 3 4,--run ppo-residual=ppo:agents/policies/seeds/RocketRoll-v0/ppo-residual/seed$(s)) \
		--run ppo-memory=ppo:agents/policies/RocketRoll-v0 \
		$(foreach s,1 2 3 4,--run ppo-memory=ppo:agents/policies/seeds/RocketRoll-v0/ppo-memory/seed$(s)) \
		--out $(DEMO)/seeds-angle
	$(BIN)/rocketroll seeds --env-id RocketRollRate-v0 --run ppo:agents/policies/RocketRollRate-v0 \
		$(foreach s,1 2 3 4,--run ppo:agents/policies/seeds/RocketRollRate-v0/ppo/seed$(s)) \
		$(foreach s,0 1 2 3 4,--run sac:agents/policies/seeds/RocketRollRate-v0/sac/seed$(s)) \
		--out $(DEMO)/seeds-rate
	$(BIN)/rocketroll env ascent --plot $(DEMO)/flight-profile.png
	$(BIN)/rocketroll eval --env-id RocketRollFlight-v0 --episodes 20 --seed 0 \
		--policy trim --policy pid --policy pid-tunnel --policy observer --policy mpc \
		--policy oracle --policy causal-oracle --out $(DEMO)/eval-flight
	$(BIN)/rocketroll record-flight --seed 0 --out $(DEMO)/flight-seed0.csv
	$(BIN)/rocketroll identify $(DEMO)/flight-seed0.csv --json $(DEMO)/flight-seed0.json \
		--report $(DEMO)/flight-seed0-report
	@echo "demo: wrote $(DEMO)/tunnel-seed0.csv, $(DEMO)/tunnel-seed0.png, the"
	@echo "      identification report $(DEMO)/identify-paper-seed0/report.md,"
	@echo "      $(DEMO)/surrogate.png, the RocketRoll-v0 frames $(DEMO)/env-zero.png,"
	@echo "      $(DEMO)/env-random.png and the evaluations of trim, PID, the observer, the MPC, PPO and the oracle"
	@echo "      on held-out episodes in $(DEMO)/eval-angle/ and $(DEMO)/eval-rate/, PPO, PPO trained"
	@echo "      at a zero setpoint, PPO as a residual on the observer, PPO with memory and SAC over"
	@echo "      five training seeds each in $(DEMO)/seeds-angle/"
	@echo "      and seeds-rate/, and in flight"
	@echo "      (RocketRollFlight-v0) the ascent $(DEMO)/flight-profile.png, the scheduled PID, observer and MPC"
	@echo "      against the tunnel's in $(DEMO)/eval-flight/ (tables above), and a virtual flight's"
	@echo "      log $(DEMO)/flight-seed0.csv identified back in $(DEMO)/flight-seed0.json"
	@echo "      and $(DEMO)/flight-seed0-report/"
	@echo "      (every controller under other worlds: make studies)"

# The heavier studies beside the demo (about two minutes of CPU): every controller designed
# on the nominal rocket, evaluated under other worlds (results/evaluation.md, Robustness).
studies: $(VENV)/.installed
	@mkdir -p $(DEMO)
	$(BIN)/rocketroll robustness --env-id RocketRoll-v0 --out $(DEMO)/robustness-angle
	$(BIN)/rocketroll robustness --env-id RocketRollRate-v0 --out $(DEMO)/robustness-rate

lint: $(VENV)/.installed-dev
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .

typecheck: $(VENV)/.installed-dev
	$(BIN)/mypy

# On every core (pytest-xdist); --dist loadfile keeps a module's tests, and the fixtures they
# share, on one worker; --no-loadscope-reorder hands the modules out in the order
# tests/conftest.py sorts them (the slowest first), not by their number of tests. The
# slowest 20 tests are listed at the end (reported, never asserted).
pytest: $(VENV)/.installed-dev
	$(BIN)/pytest -n auto --dist loadfile --no-loadscope-reorder --durations=20

# Another machine's numerics (docs/results/reproducibility.md): OpenBLAS's AVX kernel, numpy
# without its SIMD loops, numba compiling for a generic x86-64, torch's unvectorised
# kernels and MKL's compatible path, one thread each.  The site's tables must come out
# digit for digit, from a default database built anew under these settings.
VARIED := OPENBLAS_CORETYPE=Sandybridge \
	NPY_DISABLE_CPU_FEATURES="X86_V3 X86_V4 AVX512_ICL AVX512_SPR" \
	NUMBA_CPU_NAME=generic ATEN_CPU_CAPABILITY=default MKL_CBWR=COMPATIBLE \
	OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1 NUMBA_NUM_THREADS=1

# One module, so its tests are spread over the cores one by one (--dist load).
pytest-varied: $(VENV)/.installed-dev
	env $(VARIED) $(BIN)/pytest -p no:cacheprovider -n auto --dist load --durations=8 \
		tests/test_figures.py

# The documentation site into build/site, strict: a broken link or anchor, a page outside the
# navigation or a docstring the API reference cannot read fails the build. No network.
docs: $(VENV)/.installed-dev
	NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs build --strict --quiet

test: lint typecheck pytest pytest-varied docs

# Write rocketroll/help.json again (every command's --help, read without importing the
# command's module); a test fails while it is not current.
help: $(VENV)/.installed
	$(BIN)/python -c 'from rocketroll.cli import write_help; write_help()'

# Write docs/schemas/*.schema.json again (the JSON Schema of each spec model, for editors);
# a test fails while one is not current.
schemas: $(VENV)/.installed
	$(BIN)/python -c 'from rocketroll.cli import write_schemas; write_schemas()'

# Regenerate the bundled synthetic recordings from their recorded commands.
recordings: $(VENV)/.installed
	$(BIN)/python -m identification.instruments.bundled --regenerate

clean:
	rm -rf $(VENV) build .mypy_cache .pytest_cache .ruff_cache
