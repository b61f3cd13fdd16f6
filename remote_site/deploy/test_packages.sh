#!/usr/bin/env bash
# Builds the two Debian packages from a build tree (cpack -G DEB, into a scratch
# folder) and checks them:
#   foresight-remote: the daemon, its units, /etc/foresight config, the CAN
#     bring-up, conffiles; its dependencies name no ground library (OpenCV, GL,
#     OSMesa, EGL) and the binary links none (ldd); the cabinet's remote.yaml
#     names SocketCAN interfaces.
#   foresight-ground: the CLI and its config; it depends on OpenCV.
#   both: `apt-get install --simulate ./x.deb` resolves on an empty system (when
#     apt has package lists): what `apt-get install ./x.deb` does on a fresh Debian 12.
#
#   bash remote_site/deploy/test_packages.sh BUILD_DIR     (prints "packages: ok")
# Needs foresight-remote and foresight built in BUILD_DIR, cpack, dpkg-deb,
# dpkg-shlibdeps. Run by test_check (Deploy.PackagesHoldWhatTheyShould).
set -euo pipefail
build=${1:?usage: test_packages.sh BUILD_DIR}
build=$(cd "$build" && pwd)
tmp=$(mktemp -d /tmp/foresight_pkg_XXXXXX)
trap 'rm -rf "$tmp"' EXIT
fail() { echo "test_packages: $*" >&2; exit 1; }

start=$(date +%s)
(cd "$build" && cpack -G DEB -B "$tmp" >"$tmp/cpack.log" 2>&1) || { cat "$tmp/cpack.log" >&2; fail "cpack failed"; }
remote=$(ls "$tmp"/foresight-remote_*.deb 2>/dev/null | head -1)
ground=$(ls "$tmp"/foresight-ground_*.deb 2>/dev/null | head -1)
[[ -n $remote ]] || fail "no foresight-remote_*.deb in $(ls "$tmp")"
[[ -n $ground ]] || fail "no foresight-ground_*.deb in $(ls "$tmp")"
echo "built $(basename "$remote") ($(stat -c %s "$remote") bytes), $(basename "$ground") ($(stat -c %s "$ground") bytes) in $(( $(date +%s) - start )) s"

# ---- foresight-remote -----------------------------------------------------------------
dpkg-deb -c "$remote" | awk '{print $NF}' | sed 's#^\./#/#' >"$tmp/remote.files"
for f in /usr/bin/foresight-remote \
         /lib/systemd/system/foresight-remote.service /lib/systemd/system/foresight-can.service \
         /etc/systemd/system/foresight-remote.service.d/cpu.conf /etc/default/foresight-remote \
         /etc/foresight/remote.yaml /etc/foresight/robot.urdf /etc/foresight/oru.yaml /etc/foresight/scene.yaml \
         /usr/lib/foresight/can-setup.sh \
         /usr/share/foresight-remote/can/80-foresight-can.network /usr/share/foresight-remote/can/80-foresight-can.link \
         /usr/share/foresight-remote/scripts/make_dds_security.sh \
         /usr/share/doc/foresight-remote/deploy.md /usr/share/doc/foresight-remote/journal.md; do
  grep -qx "$f" "$tmp/remote.files" || fail "foresight-remote lacks $f"
done
grep -qx /usr/bin/foresight "$tmp/remote.files" && fail "foresight-remote holds the ground CLI"
# The cabinet's configuration runs the link with DDS Security (issue 28).
dpkg-deb --fsys-tarfile "$remote" | tar -xO ./etc/foresight/remote.yaml | grep -q '^    security: dds-security ' ||
  fail "the installed remote.yaml does not run DDS Security (controller.link.security)"
depends=$(dpkg-deb -f "$remote" Depends)
echo "foresight-remote Depends: $depends"
grep -Eiq 'opencv|libgl|osmesa|libegl|mesa|ceres' <<<"$depends" && fail "foresight-remote depends on a ground library: $depends"
for d in libsystemd0 libddsc0debian libmodbus iproute2 systemd libsqlite3; do
  grep -q "$d" <<<"$depends" || fail "foresight-remote does not depend on $d: $depends"
done
dpkg-deb -x "$remote" "$tmp/remote"
linked=$(ldd "$tmp/remote/usr/bin/foresight-remote")
grep -Eiq 'GL|opencv' <<<"$linked" && fail "foresight-remote links a ground library: $(grep -Ei 'GL|opencv' <<<"$linked")"
grep -q 'not found' <<<"$linked" && fail "foresight-remote: unresolved libraries: $linked"
# Every drive SDO list remote.yaml names (relative to it) is in the package beside it.
sdo_files=$(sed 's/#.*//' "$tmp/remote/etc/foresight/remote.yaml" | grep -o 'sdo_file: *[^,} ]*' | awk '{print $2}' | sort -u)
[[ -n $sdo_files ]] || fail "/etc/foresight/remote.yaml names no sdo_file"
for f in $sdo_files; do
  [[ -f $tmp/remote/etc/foresight/$f ]] || fail "/etc/foresight/remote.yaml names sdo_file $f, which the package lacks"
done
grep -q 'interface: can0' "$tmp/remote/etc/foresight/remote.yaml" || fail "/etc/foresight/remote.yaml does not name can0"
grep -q 'interface: mock' "$tmp/remote/etc/foresight/remote.yaml" && fail "/etc/foresight/remote.yaml still has a mock bus"
[[ -x $tmp/remote/usr/lib/foresight/can-setup.sh ]] || fail "can-setup.sh is not executable"
dpkg-deb -e "$remote" "$tmp/remote.ctl"
grep -qx /etc/foresight/remote.yaml "$tmp/remote.ctl/conffiles" || fail "remote.yaml is not a conffile"
for f in $sdo_files; do
  grep -qx "/etc/foresight/$f" "$tmp/remote.ctl/conffiles" || fail "/etc/foresight/$f is not a conffile"
done
grep -q 'systemctl daemon-reload' "$tmp/remote.ctl/postinst" || fail "postinst does not reload systemd"
grep -Eq '^[[:space:]]*(deb-systemd-invoke|systemctl (start|enable|restart))' "$tmp/remote.ctl/postinst" &&
  fail "postinst starts or enables the daemon (the first start is the operator's, after the check)"

# ---- foresight-ground -----------------------------------------------------------------
dpkg-deb -c "$ground" | awk '{print $NF}' | sed 's#^\./#/#' >"$tmp/ground.files"
for f in /usr/bin/foresight /etc/foresight-ground/ground.yaml /etc/foresight-ground/robot.urdf /etc/foresight-ground/oru.yaml \
         /etc/foresight-ground/scene.yaml /etc/foresight-ground/scripts/oru_changeout.task \
         /etc/profile.d/foresight-ground.sh /usr/share/foresight-ground/scripts/make_dds_security.sh; do
  grep -qx "$f" "$tmp/ground.files" || fail "foresight-ground lacks $f"
done
grep -qx /usr/bin/foresight-remote "$tmp/ground.files" && fail "foresight-ground holds the daemon"
dpkg-deb --fsys-tarfile "$ground" | tar -xO ./etc/foresight-ground/ground.yaml | grep -q '^  security: dds-security ' ||
  fail "the installed ground.yaml does not run DDS Security (link.security)"
# No file in both packages (they install side by side).
common=$(comm -12 <(grep -v '/$' "$tmp/remote.files" | sort) <(grep -v '/$' "$tmp/ground.files" | sort))
[[ -z $common ]] || fail "both packages hold: $common"
gdepends=$(dpkg-deb -f "$ground" Depends)
echo "foresight-ground Depends: $gdepends"
grep -q 'libopencv' <<<"$gdepends" || fail "foresight-ground does not depend on OpenCV: $gdepends"

# ---- dependencies resolve on a fresh Debian 12 -------------------------------------------------
# apt-get's own solver against an empty dpkg status (a machine with nothing
# installed) and this machine's package lists; nothing is installed.
if command -v apt-get >/dev/null && [[ -n $(ls /var/lib/apt/lists/ 2>/dev/null | grep -v -e lock -e partial -e auxfiles) ]]; then
  : >"$tmp/empty_status"
  for deb in "$remote" "$ground"; do
    apt-get install --simulate -o Dir::State::status="$tmp/empty_status" "$deb" >"$tmp/apt.log" 2>&1 ||
      { tail -20 "$tmp/apt.log" >&2; fail "apt-get cannot install $(basename "$deb") on a fresh machine"; }
    echo "apt-get install --simulate $(basename "$deb") on an empty system: $(grep -c '^Inst' "$tmp/apt.log") packages"
  done
else
  echo "apt-get install --simulate: skipped (no apt lists)"
fi
echo "packages: ok ($(( $(date +%s) - start )) s)"
