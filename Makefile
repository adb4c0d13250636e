SHELL := /bin/bash
ENV := source scripts/env.sh
ARGS ?=

.PHONY: setup demo test lint bench-perf bench-seg bench-recon bench-manip bench-robustness bench-camera-pose bench-real bench-demo bench-behaviours clean

setup:
	@scripts/bootstrap.sh

demo: setup
	@$(ENV) && demo $(ARGS)

test: setup
	@$(ENV) && python -m pytest -q -p no:cacheprovider src lab tests $(ARGS)

lint: setup
	@$(ENV) && ruff check src lab tests scripts

bench-perf: setup
	@$(ENV) && bench_perf $(ARGS)

bench-seg: setup
	@$(ENV) && bench_seg $(ARGS)

bench-recon: setup
	@$(ENV) && bench_recon $(ARGS)

bench-manip: setup
	@$(ENV) && bench_manip $(ARGS)

bench-robustness: setup
	@$(ENV) && bench_robustness $(ARGS)

bench-camera-pose: setup
	@$(ENV) && bench_camera_pose $(ARGS)

REAL ?= ../shared/real/osd_learn ../shared/real/osd_learn_uncropped ../shared/real/ycb_tables
bench-real: setup
	@$(ENV) && bench_real $(REAL) $(ARGS)

bench-demo: setup
	@$(ENV) && bench_demo $(ARGS)

bench-behaviours: setup
	@$(ENV) && bench_behaviours $(ARGS)

clean:
	rm -rf build install log
