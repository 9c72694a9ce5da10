#!/bin/bash
# Usage: run_pytest.sh SCP_ESTIMATORD_BINARY — the Python client's tests against that daemon.
# Debian's /usr/bin/python3 (its python3-pytest); a missing pytest skips (77), except under CI.
set -u
here=$(cd "$(dirname "$0")" && pwd)
if ! /usr/bin/python3 -c 'import pytest' 2>/dev/null; then
  echo "python3-pytest is not installed (scripts/setup installs it)"
  [[ ${CI:-} == true ]] && exit 1
  exit 77
fi
export SCP_ESTIMATORD=$1 PYTHONPATH=$here${PYTHONPATH:+:$PYTHONPATH} PYTHONDONTWRITEBYTECODE=1
exec /usr/bin/python3 -m pytest -q -p no:cacheprovider "$here/tests"
