#!/bin/bash
# Usage: check_systemd_files.sh <systemd-source-dir> <scratch-dir> <daemon-binary-or-empty> <max-exposure>
# Fails (exit 1) with a message per problem; exit 77 = skipped.
set -u
src=$1 work=$2 binary=$3 max_exposure=$4
status=0
fail() { echo "FAIL: $*"; status=1; }

rm -rf "$work" && mkdir -p "$work/system" || exit 1

# 1. A test copy of the unit. ExecStart= points at the built daemon when it exists, so verify also
# checks that the command is an executable; otherwise at /bin/true, so every directive is still
# checked and only the executable check is vacuous.
if [[ -n "$binary" && -x "$binary" ]]; then
  exe=$binary
else
  echo "NOTE: daemon binary '${binary}' not built; verifying with ExecStart=/bin/true"
  exe=/bin/true
fi
unit="$work/system/scp-estimatord.service"
sed -e "s|@SCP_SBINDIR@/scp-estimatord|$exe|" -e "s|@SCP_SYSCONFDIR@|/etc|" \
    "$src/scp-estimatord.service.in" >"$unit"
if grep -n '@[A-Z_]*@' "$unit"; then fail "unsubstituted @VARIABLE@ left in the unit"; fi

# 2. systemd-analyze verify exits 0 even for unknown keys or bad values ("..., ignoring"), so any
# output at all is a failure.
out=$(systemd-analyze verify --man=no "$unit" 2>&1)
rc=$?
if [[ $rc -ne 0 || -n "$out" ]]; then
  fail "systemd-analyze verify (rc=$rc):"
  echo "$out"
fi

# 3. Directives the daemon depends on (a regression here breaks real-time operation or devices).
need() { grep -qE "^$1" "$unit" || fail "unit lacks '$1'"; }
need 'Type=notify$'
need 'Documentation=man:scp-estimatord\(8\)'
need 'WatchdogSec=2s$'
need 'LimitRTPRIO=[1-9]'
need 'LimitMEMLOCK=infinity$'
need 'RestrictRealtime=no$'
need 'RestartPreventExitStatus=78 69$'  # a config error (78), a device absent past driver.start_timeout_s (69): no restart loop
need 'RestrictAddressFamilies=.*AF_CAN'
need 'RestrictAddressFamilies=.*AF_INET6'
need 'DeviceAllow=char-ttyUSB rw$'
need 'SupplementaryGroups=dialout$'
need 'StateDirectory=scp-estimator$'
need 'RuntimeDirectory=scp-estimator$'
# The syscalls the loop thread makes must survive SystemCallFilter=.
for deny in $(grep -E '^SystemCallFilter=~' "$unit" | sed 's/^SystemCallFilter=~//'); do
  for call in sched_setscheduler sched_setaffinity mlockall clock_nanosleep sendto; do
    if systemd-analyze syscall-filter "$deny" 2>/dev/null | grep -qE "^\s+$call\$"; then
      fail "SystemCallFilter=~$deny blocks $call, which the daemon needs"
    fi
  done
done

# 4. Exposure score.
sec=$(systemd-analyze security --offline=yes "$unit" 2>&1)
score=$(echo "$sec" | sed -n 's/.*Overall exposure level for [^:]*: \([0-9.]*\).*/\1/p')
if [[ -z "$score" ]]; then
  fail "could not read the exposure level from systemd-analyze security:"
  echo "$sec" | tail -5
else
  echo "systemd-analyze security exposure: $score (limit $max_exposure)"
  if awk -v s="$score" -v m="$max_exposure" 'BEGIN { exit !(s > m) }'; then
    fail "exposure $score is above $max_exposure; the remaining findings:"
    echo "$sec" | grep '✗'
  fi
fi

# 6. The template for several actuators (scp-estimatord@NAME.service): verified as an instance,
# the same directives, per-instance config/socket/state, and an exposure no higher than the plain
# unit's.
template="$work/system/scp-estimatord@.service"
sed -e "s|@SCP_SBINDIR@/scp-estimatord|$exe|" -e "s|@SCP_SYSCONFDIR@|/etc|" \
    "$src/scp-estimatord@.service.in" >"$template"
if grep -n '@[A-Z_]*@' "$template"; then fail "unsubstituted @VARIABLE@ left in the template"; fi
instance="$work/system/scp-estimatord@bench-a.service"
ln -sf "scp-estimatord@.service" "$instance"
out=$(systemd-analyze verify --man=no "$instance" 2>&1)
rc=$?
if [[ $rc -ne 0 || -n "$out" ]]; then
  fail "systemd-analyze verify of the template instance (rc=$rc):"
  echo "$out"
fi
tneed() { grep -qE "^$1" "$template" || fail "template lacks '$1'"; }
tneed 'ExecStart=.* --config /etc/scp-estimator/%i\.yaml --instance %i$'
tneed 'StateDirectory=scp-estimator/%i$'
tneed 'RuntimeDirectoryPreserve=yes$'  # one instance stopping must not remove the others' sockets
tneed 'Type=notify$'
tneed 'WatchdogSec=2s$'
tneed 'LimitMEMLOCK=infinity$'
tneed 'RestartPreventExitStatus=78 69$'
# Everything but the instance lines is the plain unit's: hardening cannot drift between them.
strip() { grep -vE '^(#|Description=|ExecStart=|StateDirectory=|RuntimeDirectoryPreserve=)' "$1"; }
if ! diff <(strip "$unit") <(strip "$template") >/dev/null; then
  fail "the template's directives differ from the plain unit's:"
  diff <(strip "$unit") <(strip "$template")
fi
tsec=$(systemd-analyze security --offline=yes "$instance" 2>&1)
tscore=$(echo "$tsec" | sed -n 's/.*Overall exposure level for [^:]*: \([0-9.]*\).*/\1/p')
if [[ -z "$tscore" || -z "${score:-}" ]]; then
  fail "could not read the template's exposure level:"
  echo "$tsec" | tail -5
else
  echo "template instance exposure: $tscore (plain unit $score)"
  if awk -v s="$tscore" -v m="$score" 'BEGIN { exit !(s > m) }'; then
    fail "the template's exposure $tscore is above the plain unit's $score"
  fi
fi

# 5. sysusers.d and tmpfiles.d in a scratch root (the tools resolve config names inside it).
root="$work/root"
mkdir -p "$root/etc" "$root/usr/lib/sysusers.d" "$root/usr/lib/tmpfiles.d"
cp "$src/scp-estimator.sysusers" "$root/usr/lib/sysusers.d/scp-estimator.conf"
cp "$src/scp-estimator.tmpfiles" "$root/usr/lib/tmpfiles.d/scp-estimator.conf"
if command -v systemd-sysusers >/dev/null; then
  if out=$(systemd-sysusers --root="$root" scp-estimator.conf 2>&1); then
    grep -q '^scp-estimator:x:[0-9]*:[0-9]*:.*:/usr/sbin/nologin$' "$root/etc/passwd" ||
      fail "sysusers did not create the scp-estimator user: $(cat "$root/etc/passwd" 2>&1)"
    grep -q '^scp-estimator:' "$root/etc/group" || fail "sysusers did not create the scp-estimator group"
    if [[ $(id -u) -eq 0 ]] && command -v systemd-tmpfiles >/dev/null; then
      out=$(systemd-tmpfiles --root="$root" --create scp-estimator.conf 2>&1) || fail "systemd-tmpfiles: $out"
      uid=$(sed -n 's/^scp-estimator:x:\([0-9]*\):.*/\1/p' "$root/etc/passwd")
      for d in var/lib/scp-estimator run/scp-estimator; do
        [[ $(stat -c '%u %a' "$root/$d" 2>/dev/null) == "$uid 750" ]] ||
          fail "tmpfiles: $d is not owned by scp-estimator with mode 0750: $(stat -c '%u %a' "$root/$d" 2>&1)"
      done
    else
      echo "NOTE: not root; tmpfiles ownership not checked"
    fi
  else
    fail "systemd-sysusers: $out"
  fi
fi

[[ $status -eq 0 ]] && echo "PASS"
exit $status
