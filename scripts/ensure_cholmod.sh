#!/usr/bin/env bash
# CHOLMOD (SuiteSparse) for the strain solver's sparse Cholesky Newton steps
# (strain.linear_solver = "cholesky", cloth/linalg.py). scikit-sparse 0.4.x builds against
# Debian 12's libsuitesparse-dev (0.5 does not). Install the headers where they are missing and
# we may, then the pinned wheel. Never fails the caller: without CHOLMOD, cloth/linalg.py falls
# back to SciPy's SuperLU (slower) and says so.
set -u
PY="${1:-.venv/bin/python}"
"$PY" -c "import sksparse.cholmod" 2>/dev/null && exit 0
if [ ! -e /usr/include/suitesparse/cholmod.h ]; then
  if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
    echo "loom: installing libsuitesparse-dev (apt) for CHOLMOD" >&2
    export DEBIAN_FRONTEND=noninteractive
    (apt-get install -y -qq libsuitesparse-dev >/dev/null 2>&1 || \
      (apt-get update -qq >/dev/null && apt-get install -y -qq libsuitesparse-dev >/dev/null)) || true
  fi
fi
if [ -e /usr/include/suitesparse/cholmod.h ]; then
  "$PY" -m pip install -q -r requirements-cholmod.txt && exit 0
fi
echo "loom: CHOLMOD not available (needs: sudo apt-get install libsuitesparse-dev, then" \
     "make); the sparse Cholesky falls back to SciPy's SuperLU" >&2
exit 0
