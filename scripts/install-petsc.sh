#!/usr/bin/env bash
# PETSc and MPI for `--linalg petsc` (docs/cluster.md).
#
# Debian/Ubuntu: PETSc 3.18 from the distribution (with hypre, GAMG, OpenMPI), petsc4py built
# against it (Debian's own python3-petsc4py works only with Debian's numpy 1.x), and mpi4py.
# Elsewhere (a cluster's module system): set PETSC_DIR (and PETSC_ARCH) to your PETSc and
# run the last two commands with a petsc4py version matching it.
#
#   bash scripts/install-petsc.sh              # into .venv (or PYTHON=/path/to/python)
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-.venv/bin/python}
if "$PY" -c "from petsc4py import PETSc; from mpi4py import MPI" 2> /dev/null; then
  echo "petsc4py and mpi4py are installed"; exit 0
fi
if [ -z "${PETSC_DIR:-}" ]; then
  if ! compgen -G "/usr/lib/petscdir/petsc3.18/*-real" > /dev/null; then
    if [ "$(id -u)" -ne 0 ]; then SUDO=sudo; else SUDO=; fi
    $SUDO apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends \
      petsc-dev libopenmpi-dev openmpi-bin > /dev/null
  fi
  PETSC_DIR=$(compgen -G "/usr/lib/petscdir/petsc3.18/*-real" | head -n 1)
  export PETSC_DIR
fi
echo "PETSC_DIR=$PETSC_DIR"
"$PY" -m pip install --quiet "cython<3" setuptools wheel numpy
"$PY" -m pip install --quiet --no-build-isolation "petsc4py==3.18.5" "mpi4py>=3.1"
"$PY" -c "from petsc4py import PETSc; from mpi4py import MPI; \
print('petsc4py', PETSc.Sys.getVersion(), 'with', MPI.Get_library_version().splitlines()[0])"
