# Two commands do all the set-up on a fresh machine:
#   make demo   run the default scene (a window with a display, else headless to out/)
#   make test   run the test suite (make test-quick: the fast subset)
# Both create .venv and install the pinned requirements on first use.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed

.PHONY: demo test test-quick vulkan clean

$(STAMP): requirements.txt requirements-cholmod.txt
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -r requirements.txt
	bash scripts/ensure_cholmod.sh $(PY)
	touch $(STAMP)

vulkan:
	@bash scripts/ensure_vulkan.sh

demo: $(STAMP) vulkan
	$(PY) main.py $(ARGS)

# --dist loadgroup: the exact strain solve's tests share one worker (xdist_group "exact_solve"),
# which compiles its kernels once instead of once per worker.
test: $(STAMP) vulkan
	$(PY) -m pytest -n auto --dist loadgroup $(ARGS)

# The fast subset (no sweeps, windows or long scenes), for a check before each commit.
test-quick: $(STAMP) vulkan
	$(PY) -m pytest -n auto --dist loadgroup -m "not slow" $(ARGS)

clean:
	rm -rf $(VENV) out
