#!/bin/bash
# Usage: check_deb.sh BUILD_DIR SCRATCH_DIR
# Builds the .deb with CPack from BUILD_DIR, runs lintian on it (no errors allowed), and uses it
# as a Debian user would, in a fresh root: install, check the config, read the man page, import
# the Python client, upgrade over an edited config (the edit is kept), remove, purge (config,
# state and the scp-estimator account are gone).
#
# The fresh root: an overlayfs whose lower layer is this machine's / (read-only) and whose upper
# layer is a scratch directory, entered with chroot. Nothing is downloaded (no debootstrap) and
# the host is never written to; the package's dependencies resolve against the host's dpkg
# database, as on a machine that has them installed. Needs root (mount, chroot); without root,
# or without lintian/cpack, it skips (77), except under CI=true where it fails.
set -u
build=$1 work=$2
status=0
fail() { echo "FAIL: $*"; status=1; }
unavailable() {
  echo "cannot run: $*"
  [[ ${CI:-} == true ]] && exit 1
  exit 77
}
for tool in cpack lintian dpkg-deb chroot mount; do
  command -v "$tool" >/dev/null || unavailable "$tool is missing (scripts/setup installs it)"
done
[[ $(id -u) -eq 0 ]] || unavailable "not root (mount and chroot are needed for the fresh root)"

root=$work/root
cleanup() {
  umount "$root/dev" 2>/dev/null
  umount "$root/proc" 2>/dev/null
  umount "$root" 2>/dev/null
}
# A run killed half-way (ctest's timeout) may have left the fresh root mounted: unmount it before
# removing anything, and never let rm cross into another file system (/dev is bound in there).
cleanup
if mountpoint -q "$root" || mountpoint -q "$root/dev" || mountpoint -q "$root/proc"; then
  echo "FAIL: $root is still mounted; unmount it by hand"
  exit 1
fi
rm -rf --one-file-system "$work" && mkdir -p "$work" || exit 1
trap cleanup EXIT
trap 'cleanup; exit 1' INT TERM

# 1. The package, from what the install rules put in place.
if ! cpack --config "$build/CPackConfig.cmake" -B "$work/cpack" >"$work/cpack.log" 2>&1; then
  cat "$work/cpack.log"
  echo "FAIL: cpack"
  exit 1
fi
deb=$(ls "$work"/cpack/scp-estimator_*.deb 2>/dev/null | head -1)
[[ -f $deb ]] || { cat "$work/cpack.log"; echo "FAIL: cpack made no .deb"; exit 1; }
echo "package: $(basename "$deb")"
dpkg-deb --field "$deb" Package Version Depends Recommends Conffiles 2>/dev/null || dpkg-deb --info "$deb"
contents=$(dpkg-deb --contents "$deb")
for f in ./usr/sbin/scp-estimatord ./usr/bin/scp-estimatorctl ./usr/bin/scp-simdaq \
         ./lib/systemd/system/scp-estimatord.service ./etc/scp-estimator/scp-estimator.yaml \
         ./usr/share/man/man1/scp-estimatorctl.1.gz ./usr/share/doc/scp-estimator/copyright \
         ./usr/share/doc/scp-estimator/changelog.Debian.gz \
         ./usr/lib/python3/dist-packages/scp_estimator/__init__.py; do
  grep -q " $f\$" <<<"$contents" || fail "$f is not in the package"
done
dpkg-deb --ctrl-tarfile "$deb" | tar -tf - | grep -q '^./conffiles$' || fail "no conffiles"

# 2. lintian: errors fail, warnings are printed.
lintian --tag-display-limit 0 "$deb" >"$work/lintian.log" 2>&1
cat "$work/lintian.log"
grep -q '^E: ' "$work/lintian.log" && fail "lintian reports errors"
echo "lintian: $(grep -c '^E: ' "$work/lintian.log") errors, $(grep -c '^W: ' "$work/lintian.log") warnings"

# 3. The fresh root.
mkdir -p "$work/upper" "$work/overlay-work" "$root"
mount -t overlay overlay -o "lowerdir=/,upperdir=$work/upper,workdir=$work/overlay-work" "$root" ||
  unavailable "overlayfs cannot be mounted here"
mount --bind /dev "$root/dev" && mount -t proc proc "$root/proc" || unavailable "cannot mount /dev, /proc in the root"
in_root() { chroot "$root" /usr/bin/env -i PATH=/usr/sbin:/usr/bin:/sbin:/bin LANG=C.UTF-8 "$@"; }
if in_root dpkg-query -W scp-estimator >/dev/null 2>&1; then
  in_root dpkg --purge scp-estimator >/dev/null 2>&1  # the host has it: start from nothing
fi
cp "$deb" "$root/tmp/scp-estimator.deb"

out=$(in_root dpkg -i /tmp/scp-estimator.deb 2>&1) || fail "dpkg -i: $out"
out=$(in_root scp-estimatord --check-config /etc/scp-estimator/scp-estimator.yaml 2>&1) ||
  fail "--check-config of the installed config: $out"
echo "check-config: $out"
page=$(in_root man -w scp-estimatorctl 2>&1) || fail "man -w scp-estimatorctl: $page"
[[ $page == /usr/share/man/man1/scp-estimatorctl.1.gz ]] || fail "man -w scp-estimatorctl: $page"
for p in "8 scp-estimatord" "5 scp-estimator.yaml" "1 scp-simdaq"; do
  in_root man -w $p >/dev/null 2>&1 || fail "man -w $p"
done
out=$(in_root python3 -c 'import scp_estimator; print(scp_estimator.__version__)' 2>&1) ||
  fail "import scp_estimator: $out"
in_root getent passwd scp-estimator >/dev/null || fail "postinst did not create the scp-estimator user"
[[ -d $root/var/lib/scp-estimator ]] || fail "postinst did not create /var/lib/scp-estimator"
out=$(in_root scp-estimatord --version) && [[ $out == "scp-estimatord "* ]] || fail "--version: $out"

# 4. Upgrade (the same package as version -2) over an edited config: the edit stays.
config=/etc/scp-estimator/scp-estimator.yaml
sed -i 's/^log_level: info$/log_level: debug  # edited by the operator/' "$root$config"
grep -q "edited by the operator" "$root$config" || fail "could not edit the config"
mkdir -p "$work/v2"
dpkg-deb -R "$deb" "$work/v2/tree"
version=$(sed -n 's/^Version: //p' "$work/v2/tree/DEBIAN/control")
sed -i "s/^Version: .*/Version: ${version%-*}-99/" "$work/v2/tree/DEBIAN/control"
dpkg-deb -b --root-owner-group "$work/v2/tree" "$root/tmp/scp-estimator-v2.deb" >/dev/null ||
  fail "could not build the upgrade"
out=$(in_root dpkg -i /tmp/scp-estimator-v2.deb 2>&1) || fail "upgrade: $out"
[[ $(in_root dpkg-query -W -f='${Version}' scp-estimator) == "${version%-*}-99" ]] || fail "not upgraded"
grep -q "edited by the operator" "$root$config" || fail "the upgrade lost the edited config"
in_root scp-estimatord --check-config "$config" >/dev/null 2>&1 || fail "edited config invalid after upgrade"

# 5. remove keeps the config (a conffile); purge removes it, the state and the account.
echo "checkpoint" >"$root/var/lib/scp-estimator/estimator.state"
out=$(in_root dpkg -r scp-estimator 2>&1) || fail "dpkg -r: $out"
[[ -e $root/usr/sbin/scp-estimatord ]] && fail "remove left the daemon"
[[ -f $root$config ]] || fail "remove deleted the config (it must stay until purge)"
out=$(in_root dpkg --purge scp-estimator 2>&1) || fail "dpkg --purge: $out"
[[ -e $root$config ]] && fail "purge left $config"
[[ -e $root/etc/scp-estimator ]] && fail "purge left /etc/scp-estimator"
[[ -e $root/var/lib/scp-estimator ]] && fail "purge left /var/lib/scp-estimator"
in_root getent passwd scp-estimator >/dev/null && fail "purge left the scp-estimator user"
in_root getent group scp-estimator >/dev/null && fail "purge left the scp-estimator group"

[[ $status -eq 0 ]] && echo PASS
exit $status
