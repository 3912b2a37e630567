# Two entry points (see README): `make demo` and `make test`. Each builds .venv if needed.
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV   ?= .venv
BIN    := $(VENV)/bin
# pytest-xdist workers for `make test` (auto: one a core; tests/conftest.py shares the cores out)
TEST_WORKERS ?= auto
STAMP  := $(VENV)/.installed

.PHONY: demo test lint format bench clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	# The local CPU build of torch first: a plain `torch` requirement would fetch a CUDA build.
	$(BIN)/pip install --quiet torch==2.13.0
	$(BIN)/pip install --quiet -e '.[rl,dev,export,sweep]'
	touch $(STAMP)

demo: $(STAMP)
	mkdir -p runs/demo
	$(BIN)/wsp-env simulate --json runs/demo/simulate.json --plot runs/demo/simulate.png --trace runs/demo/trace
	$(BIN)/wsp-env simulate --policy classical --json runs/demo/simulate_classical.json \
		--plot runs/demo/simulate_classical.png --trace runs/demo/trace_classical
	$(BIN)/wsp-env calibrate runs/demo/trace_classical.csv --json runs/demo/calibrate.json \
		--report runs/demo/calibration --export runs/demo/calibrated.yaml
	$(BIN)/wsp-env evaluate --policy classical --policy bc_slip_target_accel_uic_z1 \
		--policy ppo_bc_uic_z1 --policy none --policy oracle \
		--suite quick --json runs/demo/evaluate.json --report runs/demo/report
	$(BIN)/wsp-env benchmark --policy classical --policy bc_slip_target_accel_uic_z1 \
		--policy ppo_bc_uic_z1 --tier wheels+accel \
		--runs 30 --json runs/demo/benchmark.json --report runs/demo/benchmark
	$(BIN)/wsp-env rig --policy classical --rail soap --mu-contaminated 0.08 --pattern uniform \
		--speed-kmh 120 --json runs/demo/rig.json --plot runs/demo/rig.png
	$(BIN)/wsp-env traction --json runs/demo/traction.json --plot runs/demo/traction.png
	$(BIN)/wsp-env validate --json runs/demo/validate.json --report runs/demo/validate

test: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .
	$(BIN)/python scripts/check_imports.py
	$(BIN)/pytest -q -n $(TEST_WORKERS) --dist loadfile --no-loadscope-reorder

format: $(STAMP)
	$(BIN)/ruff check --fix .
	$(BIN)/ruff format .

bench: $(STAMP)
	mkdir -p runs
	$(BIN)/wsp-env bench --json runs/bench.json

clean:
	rm -rf $(VENV) runs .pytest_cache .ruff_cache .hypothesis
