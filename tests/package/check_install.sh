#!/bin/bash
# Usage: check_install.sh BUILD_DIR SCRATCH_DIR
# `cmake --install` with prefix /usr into a DESTDIR: the Debian layout, and a second install after
# the operator edited the config keeps the edit (issue 11: it used to overwrite it).
set -u
build=$1 work=$2
status=0
fail() { echo "FAIL: $*"; status=1; }
rm -rf "$work" && mkdir -p "$work" || exit 1
root=$work/root
install() { DESTDIR=$root cmake --install "$build" --prefix /usr >"$work/install.log" 2>&1 || { cat "$work/install.log"; fail "cmake --install"; }; }

install
config=$root/etc/scp-estimator/scp-estimator.yaml
for f in usr/sbin/scp-estimatord usr/bin/scp-estimatorctl usr/bin/scp-simdaq \
         lib/systemd/system/scp-estimatord.service usr/lib/sysusers.d/scp-estimator.conf \
         usr/lib/tmpfiles.d/scp-estimator.conf etc/scp-estimator/scp-estimator.yaml \
         usr/share/man/man8/scp-estimatord.8.gz usr/share/man/man5/scp-estimator.yaml.5.gz \
         usr/share/man/man1/scp-estimatorctl.1.gz usr/share/man/man1/scp-simdaq.1.gz \
         usr/share/bash-completion/completions/scp-estimatorctl \
         usr/share/doc/scp-estimator/protocol.md usr/share/doc/scp-estimator/copyright \
         usr/share/doc/scp-estimator/changelog.Debian.gz usr/share/doc/scp-estimator/examples/paper.yaml \
         usr/lib/python3/dist-packages/scp_estimator/client.py; do
  [[ -e $root/$f ]] || fail "not installed: /$f"
done
grep -qx 'ExecStart=/usr/sbin/scp-estimatord --config /etc/scp-estimator/scp-estimator.yaml' \
  "$root/lib/systemd/system/scp-estimatord.service" ||
  fail "unit's ExecStart= does not name /usr/sbin and /etc: $(grep ExecStart "$root/lib/systemd/system/scp-estimatord.service")"
find "$root" -name __pycache__ | grep -q . && fail "__pycache__ installed"
doc=$root/usr/share/doc/scp-estimator
[[ -e $doc/index.md && -e $doc/operations.md ]] || fail "the documents' index or operations.md not installed"
head -n 1 "$doc/README.md" | grep -qx '# scp-estimator' ||
  fail "/usr/share/doc/scp-estimator/README.md is not the top-level README: $(head -n 1 "$doc/README.md")"

echo "# edited by the operator" >>"$config"
install
grep -q "# edited by the operator" "$config" || fail "a second cmake --install overwrote the edited config"
grep -q "Kept (not overwritten)" "$work/install.log" || fail "the install did not say it kept the config"
[[ $status -eq 0 ]] && echo PASS
exit $status
