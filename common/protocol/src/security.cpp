#include "foresight/protocol/security.hpp"

#include <filesystem>

#include "foresight/protocol/error.hpp"

#ifndef FORESIGHT_DDS_SECURITY_PLUGIN_DIR
#define FORESIGHT_DDS_SECURITY_PLUGIN_DIR ""
#endif

namespace foresight::protocol {

std::string security_plugin_dir() { return FORESIGHT_DDS_SECURITY_PLUGIN_DIR; }

Qos security_qos(const std::string& dir, const std::string& identity) {
  namespace fs = std::filesystem;
  const fs::path base(dir);
  const fs::path id = base / "identities" / identity;
  const fs::path files[] = {base / "ca.pem", base / "governance.p7s", base / "permissions.p7s", id / "cert.pem",
                            id / "key.pem"};
  for (const auto& f : files) {
    if (!fs::exists(f)) {
      throw ProtocolError("DDS Security: " + f.string() + " is missing (make it with scripts/make_dds_security.sh " +
                          dir + ")");
    }
  }
  const auto uri = [](const fs::path& p) { return "file:" + fs::absolute(p).string(); };
  const std::string plugins = security_plugin_dir();
  const auto lib = [&](const char* name) {
    return plugins.empty() ? std::string(name) : (fs::path(plugins) / ("lib" + std::string(name) + ".so")).string();
  };
  Qos qos;
  dds_qos_t* q = qos.get();
  dds_qset_prop(q, "dds.sec.auth.library.path", lib("dds_security_auth").c_str());
  dds_qset_prop(q, "dds.sec.auth.library.init", "init_authentication");
  dds_qset_prop(q, "dds.sec.auth.library.finalize", "finalize_authentication");
  dds_qset_prop(q, "dds.sec.crypto.library.path", lib("dds_security_crypto").c_str());
  dds_qset_prop(q, "dds.sec.crypto.library.init", "init_crypto");
  dds_qset_prop(q, "dds.sec.crypto.library.finalize", "finalize_crypto");
  dds_qset_prop(q, "dds.sec.access.library.path", lib("dds_security_ac").c_str());
  dds_qset_prop(q, "dds.sec.access.library.init", "init_access_control");
  dds_qset_prop(q, "dds.sec.access.library.finalize", "finalize_access_control");
  dds_qset_prop(q, "dds.sec.auth.identity_ca", uri(base / "ca.pem").c_str());
  dds_qset_prop(q, "dds.sec.auth.identity_certificate", uri(id / "cert.pem").c_str());
  dds_qset_prop(q, "dds.sec.auth.private_key", uri(id / "key.pem").c_str());
  dds_qset_prop(q, "dds.sec.access.permissions_ca", uri(base / "ca.pem").c_str());
  dds_qset_prop(q, "dds.sec.access.governance", uri(base / "governance.p7s").c_str());
  dds_qset_prop(q, "dds.sec.access.permissions", uri(base / "permissions.p7s").c_str());
  return qos;
}

Participant make_participant(dds_domainid_t domain, const std::string& security_dir, const std::string& identity) {
  if (security_dir.empty()) return Participant(domain);
  return Participant(domain, security_qos(security_dir, identity));
}

}  // namespace foresight::protocol
