#!/usr/bin/env bash
# Exit status 0 when the system HDF5 library (libhdf5-dev) is installed, so the `.mat` importer (cargo
# feature `mat`) can be built, and then prints the workspace cargo arguments that enable it. The one
# check used by tests/run.sh, fuzz/run.sh and .ci/run (whose CAN VM stage reuses the test build).
if pkg-config --exists hdf5 2>/dev/null || [ -e /usr/include/hdf5/serial/hdf5.h ] || [ -e /usr/include/hdf5.h ]; then
  echo "--features frictl/mat,frictionless-logs/mat"
else
  exit 1
fi
