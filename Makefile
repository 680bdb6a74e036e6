# Two commands do all the setup on a fresh machine (python3 + make):
#   make bench  - create .venv, install, run check-bound --quick, speed --quick and the default
#                 matrix into results/, and write results/report.html
#   make test   - create .venv, install, run the test suite (all but the tests marked slow; < 5 min)
#   make test-slow - the long validation runs (tests marked slow: CLI end-to-end, replays against
#                 solve_ivp, Monte-Carlo statistics); .ci/run runs both
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed
OUT    ?= results

.PHONY: bench test test-slow quick benchmark check-bound speed clean

$(PY):
	$(PYTHON) -m venv $(VENV)

$(STAMP): pyproject.toml | $(PY)
	$(PY) -m pip install --quiet -e '.[test]'
	touch $(STAMP)

# The quick inequality check and speed comparison go into the same directory first, so the
# report that `run` builds carries every section.
bench: $(STAMP)
	$(VENV)/bin/solnic-bench check-bound --quick --out $(OUT)
	$(VENV)/bin/solnic-bench speed --quick --out $(OUT)
	$(VENV)/bin/solnic-bench run --out $(OUT)

quick: $(STAMP)
	$(VENV)/bin/solnic-bench run --quick --out $(OUT)-quick

# Two pytest workers, one test file each at a time (module fixtures are computed once).
test: $(STAMP)
	$(PY) -m pytest -q -n 2 --dist loadfile -m "not slow"

test-slow: $(STAMP)
	$(PY) -m pytest -q -n 2 --dist loadfile -m slow

benchmark: $(STAMP)
	$(PY) -m pytest benchmarks --benchmark-enable --benchmark-only -q

check-bound: $(STAMP)
	$(VENV)/bin/solnic-bench check-bound --out $(OUT)

speed: $(STAMP)
	$(VENV)/bin/solnic-bench speed --out $(OUT)

clean:
	rm -rf $(VENV) $(OUT) $(OUT)-quick *.egg-info
