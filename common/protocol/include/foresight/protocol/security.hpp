#pragma once
// DDS Security (OMG DDS Security 1.1: authentication, access control,
// encryption) with Cyclone's builtin plugins, configured per participant
// through its QoS properties. The material comes from
// scripts/make_dds_security.sh DIR (never committed):
//
//   security_qos(DIR, "ground")   the ground station
//   security_qos(DIR, "remote")   the robot cabinet
//   security_qos(DIR, "observer") reads telemetry, cannot command
//   security_qos(DIR + "/foreign", "intruder")  another CA (tests)
//
// Set-up only (allocates, may throw).

#include <string>
#include <utility>
#include <vector>

#include "foresight/protocol/dds.hpp"
#include "foresight/protocol/qos.hpp"

namespace foresight::protocol {

/// Where Cyclone's security plugins were found at build time ("" = let the
/// dynamic loader search for libdds_security_*.so).
std::string security_plugin_dir();

/// What verify_security_files found: the identity's certificate and how long it has left.
struct SecurityFacts {
  std::string identity;
  std::string dir;
  int days_left = 0;    ///< until the identity certificate's notAfter (negative: expired)
  std::string subject;  ///< the certificate's subject, one line
  /// "identity 'remote' in DIR: certificate signed by the CA, matches its key, 3649 days left; governance and
  /// permissions signed by the CA"
  std::string describe() const;
};

/// Reads and checks every file Cyclone's security plugins will read, as they
/// will (so that a participant is never refused with only "Error"): ca.pem a
/// certificate; cert.pem a certificate signed by it, in its validity period,
/// whose key is key.pem; governance.p7s and permissions.p7s S/MIME documents
/// signed by the CA whose content is a DDS Security XML document. Throws
/// ProtocolError "DDS Security: <file>: <what is wrong>" for the first problem.
SecurityFacts verify_security_files(const std::string& dir, const std::string& identity);

/// A participant QoS carrying the dds.sec.* properties for `identity` in
/// `dir` (dir/ca.pem, dir/governance.p7s, dir/permissions.p7s,
/// dir/identities/<identity>/{cert,key}.pem). Throws ProtocolError naming
/// the first file that is missing.
Qos security_qos(const std::string& dir, const std::string& identity);

/// The identity part of an authenticated participant's GUID (DDS Security
/// 1.1, 9.3.3): its first 48 bits are derived from its certificate's
/// subject, 0x80 | SHA-256(subject, DER) >> 1, and the handshake refuses a
/// participant whose GUID does not match its certificate. Every process of
/// one identity (one ground station) shares them; nobody else can have
/// them. Returns `guid` with bytes 6..15 zeroed (unknown stays unknown).
ParticipantGuid identity_of(const ParticipantGuid& guid);

/// The same 48 bits computed from a certificate (PEM): the identity_of() of
/// every participant authenticated with it. Throws ProtocolError naming the
/// file when it is not a certificate.
ParticipantGuid identity_of_certificate(const std::string& cert_pem_path);

/// Every identity in `dir`/identities/*/cert.pem: its identity_of_certificate()
/// and its name (the folder's), to name the writers in messages. Files that
/// are not certificates are skipped.
std::vector<std::pair<ParticipantGuid, std::string>> known_identities(const std::string& dir);

/// The one way both links make their participant: on `domain`, secured as
/// `identity` with the material in `security_dir` (verify_security_files
/// first: a damaged file is named), or plain when that is "".
Participant make_participant(dds_domainid_t domain, const std::string& security_dir, const std::string& identity);

}  // namespace foresight::protocol
