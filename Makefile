# mv3dpose_ros: two commands on a fresh machine.
#   make demo   set up on first run, then run the live pipeline on the embedded default scene
#   make test   set up on first run, then run the whole test suite
SHELL := /bin/bash
.DEFAULT_GOAL := help
ENV := source ./env.sh &&

.PHONY: help setup test demo lint bench freeze clean

help:
	@echo 'make demo   run the live pipeline on the embedded synthetic rig (sets up first)'
	@echo 'make test   run unit, lint and ROS integration tests (sets up first)'
	@echo 'make setup  create .venv, install pinned wheels, build the packages, write env.sh'
	@echo 'make lint   ament flake8 + pep257 only'
	@echo 'make bench  print the benchmarks under bench/'

setup:
	@bash scripts/setup.sh

test: setup
	@$(ENV) bash scripts/run_tests.sh $(PYTEST_ARGS)

lint: setup
	@$(ENV) python -m pytest -q test/test_flake8.py test/test_pep257.py

demo: setup
	@$(ENV) mv3dpose demo $(if $(IMAGES),--images $(IMAGES),) $(DEMO_ARGS)

bench: setup
	@$(ENV) for b in bench/bench_*.py; do echo "== $$b"; python $$b || exit 1; done

freeze:
	@.venv/bin/python scripts/freeze.py > requirements.txt

clean:
	rm -rf build install log env.sh
