#!/usr/bin/env bash
# Makes the DDS Security material for the link (OMG DDS Security 1.1, Cyclone's
# builtin plugins) into the folder given as argument. Nothing here is committed:
# the keys are made on the machine that uses them.
#
#   bash scripts/make_dds_security.sh DIR [MIN-MAX] [STATION[:observer] ...]
#
# DIR/
#   ca.pem, ca_key.pem             the project's CA (identity and permissions CA)
#   governance.xml/.p7s            domain rules: only authenticated participants
#                                  join; discovery, liveliness and every foresight
#                                  topic encrypted and access controlled
#   permissions.xml/.p7s           one grant per identity in identities/, by the
#                                  role in its `role` file, signed by the CA:
#                                    remote:    publishes what the robot reports
#                                               (acks, upload status, telemetry,
#                                               status, pongs, heartbeats, rt/*)
#                                    commander: publishes commands, trajectory
#                                               chunks, pings, heartbeats
#                                    observer:  publishes ABORTs (on foresight/abort),
#                                               pings and heartbeats only (watches
#                                               telemetry; may stop the arm; cannot
#                                               command or upload)
#                                  everyone subscribes to everything
#   identities/NAME/cert.pem, key.pem, role
#                                  remote (role remote), ground (commander) and
#                                  observer (observer) always; one more per STATION
#                                  argument: a commander, or an observer with
#                                  ":observer" (e.g. station-b station-c:observer)
#   foreign/                       a second, unrelated CA with the same layout and
#                                  one identity, "intruder" (tests: it must not join)
#
# One identity per ground station: the remote binds control to the identity
# (every process of one station shares it), so two stations with one identity
# could not keep each other out. Adding a station later: run the script again
# with its name; every identity already in DIR keeps its keys and its grant.
# Domain ids: MIN-MAX (default 0-230, Cyclone's largest id) limits the grants and
# the governance to those domains. Requires openssl. Idempotent: existing keys
# and certificates are kept (missing ones are made anew); the permissions are
# signed anew every time.
set -euo pipefail

if [[ $# -lt 1 ]]; then
  echo "usage: make_dds_security.sh DIR [MIN-MAX] [STATION[:observer] ...]" >&2
  exit 2
fi
out=$1
range=${2:-0-230}
stations=("${@:3}")
dmin=${range%-*}
dmax=${range#*-}
if ! [[ $dmin =~ ^[0-9]+$ && $dmax =~ ^[0-9]+$ ]] || ((dmin > dmax)); then
  echo "make_dds_security.sh: domain range '$range' is not MIN-MAX" >&2
  exit 2
fi
command -v openssl >/dev/null || { echo "make_dds_security.sh: openssl is not installed" >&2; exit 1; }

not_before=$(date -u -d '-1 day' +%Y-%m-%dT%H:%M:%S)
not_after=$(date -u -d '+10 years' +%Y-%m-%dT%H:%M:%S)

# make_ca DIR NAME
make_ca() {
  local dir=$1 name=$2
  mkdir -p "$dir"
  if [[ ! -s $dir/ca.pem || ! -s $dir/ca_key.pem ]]; then
    openssl ecparam -name prime256v1 -genkey -noout -out "$dir/ca_key.pem" 2>/dev/null
    chmod 600 "$dir/ca_key.pem"
    openssl req -x509 -new -key "$dir/ca_key.pem" -sha256 -days 3650 \
      -subj "/C=NL/O=$name/CN=$name CA" -out "$dir/ca.pem" 2>/dev/null
  fi
}

# make_identity DIR NAME ORG
make_identity() {
  local dir=$1 name=$2 org=$3 id=$1/identities/$2
  mkdir -p "$id"
  if [[ ! -s $id/cert.pem || ! -s $id/key.pem ]]; then
    openssl ecparam -name prime256v1 -genkey -noout -out "$id/key.pem" 2>/dev/null
    chmod 600 "$id/key.pem"
    openssl req -new -key "$id/key.pem" -subj "/C=NL/O=$org/CN=$name" -out "$id/req.csr" 2>/dev/null
    openssl x509 -req -in "$id/req.csr" -CA "$dir/ca.pem" -CAkey "$dir/ca_key.pem" -CAcreateserial \
      -sha256 -days 3650 -out "$id/cert.pem" 2>/dev/null
    rm -f "$id/req.csr"
  fi
}

# sign DIR FILE.xml -> FILE.p7s (S/MIME, signed by DIR's CA)
sign() {
  local dir=$1 xml=$2
  openssl smime -sign -in "$xml" -text -out "${xml%.xml}.p7s" -signer "$dir/ca.pem" -inkey "$dir/ca_key.pem"
}

governance() {
  cat <<EOF
<?xml version="1.0" encoding="UTF-8"?>
<dds xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance"
     xsi:noNamespaceSchemaLocation="http://www.omg.org/spec/DDS-Security/20170801/omg_shared_ca_governance.xsd">
  <domain_access_rules>
    <domain_rule>
      <domains><id_range><min>$dmin</min><max>$dmax</max></id_range></domains>
      <allow_unauthenticated_participants>false</allow_unauthenticated_participants>
      <enable_join_access_control>true</enable_join_access_control>
      <discovery_protection_kind>ENCRYPT</discovery_protection_kind>
      <liveliness_protection_kind>ENCRYPT</liveliness_protection_kind>
      <rtps_protection_kind>NONE</rtps_protection_kind>
      <topic_access_rules>
        <topic_rule>
          <topic_expression>*</topic_expression>
          <enable_discovery_protection>true</enable_discovery_protection>
          <enable_liveliness_protection>true</enable_liveliness_protection>
          <enable_read_access_control>true</enable_read_access_control>
          <enable_write_access_control>true</enable_write_access_control>
          <metadata_protection_kind>ENCRYPT</metadata_protection_kind>
          <data_protection_kind>ENCRYPT</data_protection_kind>
        </topic_rule>
      </topic_access_rules>
    </domain_rule>
  </domain_access_rules>
</dds>
EOF
}

# grant NAME ORG PUBLISH_TOPICS... (subscribe: everything)
grant() {
  local name=$1 org=$2
  shift 2
  cat <<EOF
    <grant name="${name}_grant">
      <subject_name>C=NL,O=$org,CN=$name</subject_name>
      <validity><not_before>$not_before</not_before><not_after>$not_after</not_after></validity>
      <allow_rule>
        <domains><id_range><min>$dmin</min><max>$dmax</max></id_range></domains>
        <publish><topics>
EOF
  for t in "$@"; do echo "          <topic>$t</topic>"; done
  cat <<EOF
        </topics></publish>
        <subscribe><topics><topic>*</topic></topics></subscribe>
      </allow_rule>
      <default>DENY</default>
    </grant>
EOF
}

permissions_head='<?xml version="1.0" encoding="UTF-8"?>
<dds xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance"
     xsi:noNamespaceSchemaLocation="http://www.omg.org/spec/DDS-Security/20170801/omg_shared_ca_permissions.xsd">
  <permissions>'
permissions_tail='  </permissions>
</dds>'

# The project's CA and identities, each with its role.
# make_role_identity NAME ROLE
make_role_identity() {
  local name=$1 role=$2
  make_identity "$out" "$name" Foresight
  echo "$role" >"$out/identities/$name/role"
}
for st in "${stations[@]}"; do  # every name checked before anything is made
  name=${st%:*}
  if ! [[ $name =~ ^[A-Za-z0-9][A-Za-z0-9_.-]*$ && ($st == "$name" || ${st#*:} =~ ^(observer|commander)$) ]]; then
    echo "make_dds_security.sh: '$st' is not STATION or STATION:observer / STATION:commander (a name of letters, digits, '_', '.', '-')" >&2
    exit 2
  fi
done
make_ca "$out" Foresight
make_role_identity remote remote
make_role_identity ground commander
make_role_identity observer observer
for st in "${stations[@]}"; do
  case $st in
    *:observer) make_role_identity "${st%:observer}" observer ;;
    *:commander) make_role_identity "${st%:commander}" commander ;;
    *) make_role_identity "$st" commander ;;
  esac
done
governance >"$out/governance.xml"
{
  echo "$permissions_head"
  for id in "$out"/identities/*/; do
    name=$(basename "$id")
    role=$(cat "$id/role" 2>/dev/null || echo observer)
    case $role in
      remote)
        grant "$name" Foresight foresight/command/ack foresight/trajectory/status 'foresight/telemetry/*' \
          foresight/status foresight/pong foresight/heartbeat 'rt/*' ;;
      commander)
        grant "$name" Foresight foresight/command foresight/trajectory/chunk foresight/ping foresight/heartbeat ;;
      *)
        grant "$name" Foresight foresight/abort foresight/ping foresight/heartbeat ;;
    esac
  done
  echo "$permissions_tail"
} >"$out/permissions.xml"
sign "$out" "$out/governance.xml"
sign "$out" "$out/permissions.xml"

# A foreign CA with a complete, self-consistent set: its intruder must still not join.
make_ca "$out/foreign" Intruders
make_identity "$out/foreign" intruder Intruders
governance >"$out/foreign/governance.xml"
{
  echo "$permissions_head"
  grant intruder Intruders '*'
  echo "$permissions_tail"
} >"$out/foreign/permissions.xml"
sign "$out/foreign" "$out/foreign/governance.xml"
sign "$out/foreign" "$out/foreign/permissions.xml"

echo "DDS Security material in $out (identities: $(cd "$out/identities" && echo *); foreign/: intruder)"
