#!/bin/bash
# Usage: check_man_pages.sh GENERATED_DIR SOURCE_DIR
# The generated man pages render without a groff warning (what lintian checks), and say what the
# programs and the config declarations say: every key of docs/configuration.md (itself checked
# against --print-config-reference) is in scp-estimator.yaml(5), every command and exit code in
# scp-estimatorctl(1). The bash completion is valid bash and completes commands and options.
set -u
gen=$1 src=$2
status=0
fail() { echo "FAIL: $*"; status=1; }
if ! command -v man >/dev/null; then
  echo "man (man-db) is missing; scripts/setup installs it"
  [[ ${CI:-} == true ]] && exit 1
  exit 77
fi
for page in scp-estimatord.8 scp-estimator.yaml.5 scp-estimatorctl.1 scp-simdaq.1; do
  [[ -s $gen/$page ]] || { fail "$page was not generated"; continue; }
  warnings=$(LC_ALL=C.UTF-8 MANROFFSEQ='' MANWIDTH=80 man --warnings -E UTF-8 -l -Tutf8 -Z "$gen/$page" 2>&1 >/dev/null)
  [[ -z $warnings ]] || fail "$page: groff warnings: $warnings"
  text=$(LC_ALL=C.UTF-8 MANWIDTH=200 man -l "$gen/$page" 2>/dev/null)
  for section in NAME SYNOPSIS DESCRIPTION "SEE ALSO"; do
    grep -q "^$section" <<<"$text" || fail "$page has no $section section"
  done
done

yaml=$(LC_ALL=C.UTF-8 MANWIDTH=250 man -l "$gen/scp-estimator.yaml.5" 2>/dev/null)
keys=$(sed -n 's/^| `\([^`]*\)` |.*/\1/p' "$src/docs/configuration.md")
[[ $(wc -l <<<"$keys") -gt 100 ]] || fail "could not read the keys of docs/configuration.md"
missing=0
while read -r key; do
  grep -qF -- "$key (" <<<"$yaml" || { ((missing++)); [[ $missing -le 5 ]] && fail "scp-estimator.yaml(5) lacks $key"; }
done <<<"$keys"

ctl=$(LC_ALL=C.UTF-8 MANWIDTH=200 man -l "$gen/scp-estimatorctl.1" 2>/dev/null)
for word in status get watch wait reset excitation clear-fault --socket --json --timeout --state \
            --rate --count SCP_ESTIMATOR_SOCKET; do
  grep -qw -- "$word" <<<"$ctl" || fail "scp-estimatorctl(1) does not mention $word"
done
for code in 0 1 2 3 64; do
  grep -qE "^ +$code +[a-z]" <<<"$ctl" || fail "scp-estimatorctl(1) does not document exit status $code"
done
daemon=$(LC_ALL=C.UTF-8 MANWIDTH=200 man -l "$gen/scp-estimatord.8" 2>/dev/null)
for word in --check-config --offline --json --version 78 64; do
  grep -qw -- "$word" <<<"$daemon" || fail "scp-estimatord(8) does not mention $word"
done

# Completion: source it and ask for what a user would type.
complete_words() {  # program, words typed so far (the last one is being completed)
  bash -c '
    source "$1"; shift
    COMP_WORDS=("$@"); COMP_CWORD=$((${#COMP_WORDS[@]} - 1))
    fn=$(complete -p "$1" | sed "s/.*-F \([^ ]*\) .*/\1/")
    $fn; echo "${COMPREPLY[*]}"' _ "$gen/$1.bash" "$@"
}
for p in scp-estimatord scp-estimatorctl scp-simdaq; do
  bash -n "$gen/$p.bash" || fail "$p.bash is not valid bash"
done
[[ $(complete_words scp-estimatorctl st) == status ]] || fail "completion of 'st': $(complete_words scp-estimatorctl st)"
[[ $(complete_words scp-estimatorctl watch --r) == --rate ]] || fail "completion of 'watch --r'"
[[ $(complete_words scp-estimatorctl excitation o) == "on off" ]] || fail "completion of 'excitation o'"
[[ $(complete_words scp-estimatord --check) == --check-config ]] || fail "completion of '--check'"

[[ $status -eq 0 ]] && echo PASS
exit $status
