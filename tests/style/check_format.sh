#!/usr/bin/env bash
# Every C++ file git tracks must match .clang-format: formatting is part of the review, not a
# matter of taste per file. Fix with: git ls-files '*.cpp' '*.hpp' | xargs clang-format -i
set -euo pipefail
cd "$1"
command -v clang-format >/dev/null || { echo "clang-format is missing (apt-get install clang-format)"; exit 1; }
mapfile -t files < <(git ls-files '*.cpp' '*.hpp' 2>/dev/null || find . -name '*.[ch]pp' -not -path './build*')
if ((${#files[@]} == 0)); then echo "no sources found"; exit 1; fi
if ! clang-format --dry-run --Werror "${files[@]}" 2>/tmp/scp-format.$$; then
  grep -E "(warning|error):" /tmp/scp-format.$$ | cut -d: -f1 | sort -u | sed 's/^/not formatted: /'
  rm -f /tmp/scp-format.$$
  exit 1
fi
rm -f /tmp/scp-format.$$
echo "${#files[@]} files formatted as .clang-format says"
