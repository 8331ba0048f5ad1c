# rbe_ros: set-up, demo and tests. See README and docs/BUILD.md.
SHELL := /bin/bash
VENV := .venv
PY := $(VENV)/bin/python
# Each test run gets its own DDS domain (1..100) unless ROS_DOMAIN_ID is already set,
# and discovery stays on this host, so parallel runs and CI never cross-talk.
ifeq ($(strip $(ROS_DOMAIN_ID)),)
ROS_DOMAIN_ID := $(shell echo $$(( RANDOM % 100 + 1 )))
endif

.PHONY: setup demo test paper scaling bags lock clean

setup:
	bash scripts/setup.sh

demo: setup
	$(VENV)/bin/rbe-ros check examples/build_sequence.json --sequence --bag out/demo --force
	$(VENV)/bin/rbe-ros view out/demo -o out/demo/report.html
	@echo "[demo] open out/demo/report.html in a browser (3D view, step slider, table of steps)"

# The core tests on both cores (pytest-xdist), then the ROS tests (tests/ros): they start
# nodes and time their answers, so they do not run beside the core tests; on two workers,
# each in a DDS domain of its own (tests/ros/conftest.py), a test file on one worker (its
# module-scoped node started once).
test: setup browser ray
	@echo "[test] ROS_DOMAIN_ID=$(ROS_DOMAIN_ID) ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST"
	ROS_DOMAIN_ID=$(ROS_DOMAIN_ID) ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST \
		$(PY) -m pytest tests -q -m "not long" --ignore=tests/ros -n 2
	ROS_DOMAIN_ID=$(ROS_DOMAIN_ID) ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST \
		$(PY) -m pytest tests/ros -q -m "not long" -n 2 --dist loadfile

# The whole suite 5 times in a row with 2 busy processes beside it (one per core here):
# no timing assert may fail under load (scripts/suite_under_load.sh; 30-50 minutes).
.PHONY: test-under-load
test-under-load: setup browser ray
	bash scripts/suite_under_load.sh 5 2

# The long runs: the tests marked long (whole suites planned or checked against references,
# a real LMGC90 second opinion: hence make lmgc90)
# and the property tests at length, 10,000 random scenes (hypothesis profile "long", see
# tests/conftest.py; `make test` runs 500, derandomized). 15-30 minutes on 2 cores.
.PHONY: test-long
test-long: setup browser ray lmgc90
	ROS_DOMAIN_ID=$(ROS_DOMAIN_ID) ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST \
		$(PY) -m pytest tests -q -m long
	HYPOTHESIS_PROFILE=long $(PY) -m pytest tests/test_properties.py -q \
		--hypothesis-show-statistics

# Reproduce the paper's numbers and figures: docs/PAPER.md, docs/figures/ (about a minute).
paper: setup
	$(PY) benchmarks/paper.py

# Speed against accuracy against compas_cra, PyBullet, MuJoCo and LMGC90: docs/BENCHMARKS.md and
# docs/bench/ (30-40 minutes). The physics engines go into .venv (requirements/bench.txt,
# checked with pip check); compas-cra into a scratch venv (RBE_COMPAS_VENV, default
# .venv-compas, made by make setup). make bench BENCH_ARGS=--quick: a subset in under 3 minutes,
# written to out/bench-quick/.
.PHONY: bench bench-lmgc90
bench: setup
	$(PY) -m pip install --quiet --disable-pip-version-check -r requirements/bench.txt
	$(PY) -m pip check --disable-pip-version-check
	$(PY) benchmarks/bench.py $(BENCH_ARGS)
	$(MAKE) bench-margin
	$(MAKE) bench-insertion
	$(MAKE) bench-holds

# Cost of the robots' hold wrenches against holds as supports, in one run: docs/HOLD_WRENCH.md
# (about a minute; also run by make bench).
.PHONY: bench-holds
bench-holds: setup
	$(PY) benchmarks/hold_wrench.py

# LMGC90 (compas-lmgc90) in a venv of its own for check --second-opinion lmgc90 and the
# benchmarks: RBE_LMGC90_VENV, default .venv-lmgc90, about 1 GB, made from
# requirements/lmgc90.txt and pip check'ed (nothing to do when it is there and up to date).
.PHONY: lmgc90
lmgc90: setup
	$(PY) -c "from rbe_ros.io.lmgc90 import ensure_venv; print(ensure_venv())"

# LMGC90 alone (non-smooth contact dynamics, the accuracy reference; about 12 minutes): its
# verdicts on the near-limit suite, on compas_cra's samples (and the turned type-a..d) and on
# the squeeze suite, ours re-timed beside it, merged into the last full run's
# docs/bench/results.json; writes docs/BENCHMARKS.md (section 4), docs/lmgc90_verdicts.json
# and tests/data/squeeze/lmgc90_verdicts.json. make bench runs it too.
bench-lmgc90: setup lmgc90
	nice -n 10 $(PY) benchmarks/bench.py --only lmgc90

# Our verdicts alone, re-checked by this tree on every case of the last runs' results (each
# configuration, tilt capacities bisected again), on compas_cra's samples and on the squeeze
# suite; every other method's answer and every time kept: docs/BENCHMARKS.md,
# docs/lmgc90_verdicts.json and docs/bench/results.json after a change of the check, in
# minutes rather than the hours of make bench and make bench-lmgc90 on a shared machine.
.PHONY: bench-verdicts
bench-verdicts: setup
	nice -n 10 $(PY) benchmarks/bench.py --only ours

# As-built noise suite: perturbed poses under the declared uncertainty, the design rule with
# raised tolerances and today's defaults; docs/ASBUILT.md and docs/figures/asbuilt.png
# (about 15 minutes; make asbuilt ASBUILT_ARGS=--quick: 10 samples, out/asbuilt-quick/).
.PHONY: asbuilt
asbuilt: setup
	$(PY) benchmarks/asbuilt.py $(ASBUILT_ARGS)

# Mutation score of the core (rbe/, geometry/, the verdict) with a fast test selection:
# docs/MUTATION.md (scripts/mutation.py; mutmut into .venv from requirements/mutation.txt,
# checked with pip check; all 5,190 mutants take well over 1.5 hours on 2 cores, niced: the
# geometry mutants run ~150 tests each; reruns test only what is not run yet).
# make planted-bugs: the planted bugs of issue 17, each with the tests that catch it.
.PHONY: mutation planted-bugs
mutation: setup
	$(PY) -m pip install --quiet --disable-pip-version-check -r requirements/mutation.txt
	$(PY) -m pip check --disable-pip-version-check
	nice -n 19 $(PY) scripts/mutation.py $(MUTATION_ARGS)

planted-bugs: setup
	nice -n 19 $(PY) scripts/planted_bugs.py

# Re-record the regression bags of bags/ (deterministic: same code, same files; ~30 s).
bags: setup
	$(PY) scripts/make_bags.py

# Cost of a check against size, and of per-step sequence checks: docs/SCALING.md (minutes).
scaling: setup
	$(PY) benchmarks/scaling.py

# The planner at scale (issue 23): the 527-block dome planned with --pose-uncertainty
# 0.005,2.5 --max-held 2 (time, peak RSS, JSON size, ratio to its re-check), the 14 x 10
# dome against --full-candidates, --beam 2 against greedy: the planner section of
# docs/SCALING.md (minutes; run it nice'd on a shared machine). PLAN_BENCH_ARGS=--quick:
# without the 527-block dome.
.PHONY: plan-bench
plan-bench: setup
	nice -n 10 $(PY) benchmarks/plan_bench.py $(PLAN_BENCH_ARGS)

# The planner's search that backs up (issues 28, 31): outcomes, states and times of the
# capped 10 x 8 dome against its budget, an exhausted search, a greedy dead end:
# docs/SEARCH.md (a few minutes; run it nice'd on a shared machine).
.PHONY: plan-search-bench
plan-search-bench: setup
	nice -n 10 $(PY) benchmarks/plan_search.py

# Cost of the shape analysis of large meshes and the check time limit: docs/BOUNDED_CHECKS.md
# (about a minute).
.PHONY: bounded
bounded: setup
	$(PY) benchmarks/bounded_checks.py

# Regenerate requirements/ros.txt and requirements/py.txt from the .in files
# (resolves with pip, installs nothing; needs CPython 3.11 as python3).
lock:
	python3 scripts/lock.py

# Headless Chromium for the HTML view's browser test (Debian's chromium, chromium-driver;
# apt-get as root or with sudo; seconds when already installed).
# Cost of margin_g against a check, Monte Carlo throughput of 2 workers and of a local
# 2-CPU Ray against one process: docs/MARGIN.md (a few minutes; also run by make bench).
# Insertion check against the stability check per step, 140-block dome and 1,020-block wall:
# docs/INSERTION.md (about 5 minutes, most of it the wall's stability checks).
.PHONY: bench-insertion
bench-insertion: setup
	$(PY) benchmarks/insertion.py

# A 10-minute 10 Hz session of a 310-block wall recorded synthetically, then replayed with
# rbe-ros replay --compare: time against the recorded duration and peak RSS, written to
# docs/SESSIONS.md (about 15 minutes on 2 busy cores).
.PHONY: bench-replay
bench-replay: setup
	nice -n 10 $(PY) benchmarks/replay_session.py --doc docs/SESSIONS.md

# Repair time on the 140-block dome half-built, one block measured off, against re-planning
# the remainder from scratch (one run): docs/REPAIR.md (a few minutes).
.PHONY: bench-repair
bench-repair: setup
	nice -n 10 $(PY) benchmarks/repair.py

# the node's answer to a deviated block over DDS (bench-repair's plan): docs/REPAIR_NODE.md
.PHONY: bench-node-answer
bench-node-answer: setup
	ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST $(PY) benchmarks/node_answer.py

# plan --prefer margin against the default on the 7-voussoir arch and the 8 x 5 and 14 x 10
# domes (weakest step, hold-steps): docs/PREFER_MARGIN.md (many minutes: every candidate's
# margin).
.PHONY: bench-prefer
bench-prefer: setup
	nice -n 10 $(PY) benchmarks/prefer_margin.py

.PHONY: bench-margin
bench-margin: ray
	$(PY) benchmarks/margin.py

# p_stable against placement noise for near-limit families, rbe_ros beside PyBullet at 1 kHz
# on the same perturbed poses: docs/MARGIN_CHARTS.md, docs/figures/p_stable_near_limit.png.
.PHONY: bench-margin-charts
bench-margin-charts: setup
	$(PY) -m pip install --quiet --disable-pip-version-check -r requirements/bench.txt
	$(PY) -m pip check --disable-pip-version-check
	$(PY) benchmarks/margin_charts.py

# Ray for `rbe-ros robust --ray` and its test (tests/test_robust.py): the optional
# requirements/ray.txt, installed into .venv and checked beside the ROS wheels.
.PHONY: ray
ray: setup
	$(PY) -m pip install --quiet --disable-pip-version-check -r requirements/ray.txt
	$(PY) -m pip check --disable-pip-version-check

.PHONY: browser screenshot
browser:
	bash scripts/setup_browser.sh

# The README's screenshot of the HTML view, docs/view.png, taken in headless Chromium.
screenshot: setup browser
	$(PY) scripts/view_screenshot.py

clean:
	rm -rf build $(VENV) .venv-compas
