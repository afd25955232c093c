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
	mkdir -p build/demo
	$(BIN)/posedyn data summary datasets
	@echo
	@echo "Seed 004, position 5: critical depth and chatter frequency at 2000 rpm, and a 0.5 mm cut"
	$(BIN)/posedyn chatter --modes datasets/seeds/hou2023_positions.csv --pose-id P5 --rpm 2000 \
		--teeth 3 --kt-mpa 796 --kn-mpa 169 --radial-immersion 0.5 --milling down --depth-mm 0.5
	@echo
	@echo "Train the physics-prior pose model on the shipped 112-pose campaign, predict two new poses"
	$(BIN)/posedyn train datasets/campaigns/seed003_twin_s1.csv --method physics --cv 0 --out build/demo/model
	printf 'pose_id,x_mm,y_mm,z_mm,beta_deg\nnear,1400,-200,600,-30\nfar,1850,250,600,50\n' > build/demo/poses.csv
	$(BIN)/posedyn predict build/demo/model --poses build/demo/poses.csv --out build/demo/predicted.csv
	@echo
	@echo "Absorber schedule (seed 004's MRF absorber and cut) at seed 004's positions 3, 5 and 7 and at x = 2000 mm,"
	@echo "with the depths the model's uncertainty guarantees and the robust field"
	printf 'pose_id,x_mm,y_mm,z_mm,beta_deg\nP3,1600,0,800,0\nP5,1400,0,800,0\nP7,1200,0,800,0\nx2000,2000,0,800,0\n' > build/demo/hou2023_poses.csv
	$(BIN)/posedyn train datasets/seeds/hou2023_positions.csv --cv 0 --cut datasets/seeds/hou2023_cut.toml --out build/demo/hou2023_model
	$(BIN)/posedyn schedule build/demo/hou2023_model --poses build/demo/hou2023_poses.csv \
		--cut datasets/seeds/hou2023_cut.toml --policy match --robust --out build/demo/schedule.json
	@echo
	@echo "Chatter at the far pose from the predicted modes (spindle 10,700 rpm, 3-flute 12.7 mm end mill, Al)"
	$(BIN)/posedyn chatter --modes build/demo/predicted.csv --pose-id far --rpm 10700 --teeth 3 \
		--kt-mpa 597.3 --kn-mpa 59.8 --radial-immersion 0.16 --milling down
	@echo
	@echo "Where simulation and measurement disagree: 32 measured walls (surface location error) against the twin"
	$(BIN)/posedyn gap --measured datasets/campaigns/sle_walls.csv --twin --cut datasets/cuts/walls_geometric_cut.toml --out build/demo/gap_sle
	@echo
	@echo "Sweep the seed 003 workspace (112 poses) with the trained model on 2 Dask workers: maps, lobes, worst poses"
	rm -rf build/demo/sweep
	$(BIN)/posedyn sweep build/demo/model --grid datasets/campaigns/seed003_grid.toml \
		--cut datasets/cuts/sweep_demo_cut.toml --out build/demo/sweep --workers 2 --chunk-size 28
	@echo "open build/demo/sweep/report.html in a browser"
	@echo
	@echo "Serve schedules (with the guaranteed depths) over Zenoh (embedded peer on 127.0.0.1:17447), ask for position 5's schedule, stop"
	$(BIN)/posedyn serve --model build/demo/hou2023_model --cell demo --robust-samples 32 \
		--listen tcp/127.0.0.1:17447 --state-dir build/demo/service > build/demo/service.log 2>&1 & pid=$$!; \
	for i in $$(seq 1 150); do grep -q serving build/demo/service.log && break; sleep 0.2; done; \
	$(BIN)/posedyn query --cell demo --connect tcp/127.0.0.1:17447 --timeout-s 60 \
		--pose-json '{"pose_id": "P5", "x_mm": 1400, "y_mm": 0, "z_mm": 800, "beta_deg": 0}'; status=$$?; \
	kill -TERM $$pid; wait $$pid; cat build/demo/service.log; exit $$status

# two workers (the CI machine has two cores), each test file on one worker (module fixtures once)
PYTEST_ARGS ?= -n 2 --dist loadfile --no-loadscope-reorder

test: $(STAMP)
	OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1 $(BIN)/python -m pytest -q --durations=15 $(PYTEST_ARGS)

clean:
	rm -rf $(VENV) build *.egg-info
