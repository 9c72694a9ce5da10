#!/usr/bin/env bash
# Checks contrib/prometheus/scp-estimator.rules.yml with Prometheus' own tool: the rules parse
# (promtool check rules) and behave as their unit tests say (promtool test rules). promtool comes
# with Debian's `prometheus` package (scripts/setup installs it); without it this test skips on a
# developer's machine and fails under CI=true.
set -euo pipefail
rules_dir=$1
if ! command -v promtool >/dev/null; then
  if [[ ${CI:-} == true ]]; then
    echo "FAIL: CI=true and promtool is missing (apt-get install prometheus; scripts/setup does)" >&2
    exit 1
  fi
  echo "SKIP: promtool not found (apt-get install prometheus)"
  exit 77
fi
cd "$rules_dir"
promtool check rules scp-estimator.rules.yml
promtool test rules scp-estimator.rules.test.yml
