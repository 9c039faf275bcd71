# The suite's commands. Every target sets up first (idempotent, fast when nothing changed).
SHELL := /bin/bash
.DEFAULT_GOAL := help
ENV := set -eo pipefail; . scripts/env.sh;

SCENARIO ?=
CONTROLLER ?=
CAMPAIGN ?=
SCHEDULER ?=
PYTEST_ARGS ?=
# make test: two pytest workers, the graph tests one after the other on one of them
# (tests/conftest.py), the unit tests on both
PYTEST_WORKERS ?= 2
# make test-stress: the integration tests one after the other beside this many busy processes
STRESS_LOAD ?= 2

.PHONY: help setup build demo compare campaign tune reproduce test test-unit test-integration test-stress lint docs docs-serve bench curves clean

help:
	@echo "make setup   create .venv with pinned packages and build ros_ws (idempotent)"
	@echo "make demo    run the full stack on the default scenario in lockstep with the PID baseline,"
	@echo "             print a summary and write the run's report.html (SCENARIO=name-or-file"
	@echo "             CONTROLLER=law to override)"
	@echo "make compare every applicable law on every built-in scenario, offline, in parallel:"
	@echo "             runs/compare/compare.md (tables, ranking) and plots (SCENARIO=name-or-file:"
	@echo "             one only); a campaign of one nominal draw"
	@echo "make campaign the default robustness campaign (laws under uncertainty, on Dask): rows in"
	@echo "             runs/campaigns/default/, report.md and plots beside them, the results page"
	@echo "             (CAMPAIGN=file for another, SCHEDULER=tcp://host:8786 for a running cluster)"
	@echo "make tune    the tuning procedure of the campaign's laws on Dask: the tuned gains"
	@echo "             (ato_controller_node/ato_controller_node/tuned/) and docs/results/tuning.md"
	@echo "             (SCHEDULER=tcp://host:8786 for a running cluster)"
	@echo "make reproduce run the papers' reproduction tests and write docs/results/reproduction.md"
	@echo "make test    lint, build the docs strictly, run every test (unit tests of the cores and"
	@echo "             integration tests over rclpy)"
	@echo "make test-stress the integration tests beside two busy processes (STRESS_LOAD=n), as on"
	@echo "             a loaded machine; a failure shows the end of every process log"
	@echo "make lint    ruff over the repository, mypy over the packages mypy.ini lists"
	@echo "make docs    build the documentation site into site/ (warnings are errors)"
	@echo "make bench   lockstep real-time factor through the ROS graph and controller step times"
	@echo "make curves  plot every built-in scenario's target curve and braking curves to runs/curves/"
	@echo "             (SCENARIO=name-or-file for one)"

setup:
	@bash scripts/setup.sh

build: setup

demo: setup
	@$(ENV) \
	python -m ato_bringup.run_scenario $(if $(SCENARIO),--scenario $(SCENARIO)) $(if $(CONTROLLER),--controller $(CONTROLLER))

compare: setup
	@$(ENV) python -m ato_campaigns.compare \
	  $(if $(SCENARIO),--scenario $(SCENARIO),--results-page docs/results/comparison.md)

campaign: setup
	@$(ENV) python -m ato_campaigns.campaign \
	  $(if $(CAMPAIGN),$(CAMPAIGN),--results-page docs/results/campaign.md --readme README.md) \
	  $(if $(SCHEDULER),--scheduler $(SCHEDULER))

tune: setup
	@$(ENV) python -m ato_campaigns.tuning --results-page docs/results/tuning.md \
	  $(if $(SCHEDULER),--scheduler $(SCHEDULER))

reproduce: setup
	@$(ENV) python -m ato_tools.reproduction

test: setup lint docs
	@$(ENV) python -m pytest -n $(PYTEST_WORKERS) --dist loadgroup $(PYTEST_ARGS)

lint: setup
	@$(ENV) ruff check .
	@$(ENV) mypy

docs: setup
	@$(ENV) mkdocs build --strict --site-dir site 2>&1 | { grep -v '^INFO' || true; }

docs-serve: setup
	@$(ENV) mkdocs serve

test-unit: setup
	@$(ENV) python -m pytest -m "not integration" $(PYTEST_ARGS)

test-integration: setup
	@$(ENV) python -m pytest -m integration $(PYTEST_ARGS)

test-stress: setup
	@$(ENV) python -m pytest -p no:xdist -m integration --stress-load $(STRESS_LOAD) tests \
	  $(PYTEST_ARGS)

bench: setup
	@$(ENV) python bench/bench.py \
	  $(if $(SCENARIO),--scenario $(SCENARIO),--results-page docs/results/benchmarks.md \
	  --readme README.md)

curves: setup
	@$(ENV) python -m profile_node.curves $(SCENARIO) -o runs/curves

clean:
	rm -rf ros_ws/build ros_ws/install ros_ws/log .pytest_cache site
