#include "foresight/protocol/security.hpp"

#include <openssl/bio.h>
#include <openssl/err.h>
#include <openssl/evp.h>
#include <openssl/pem.h>
#include <openssl/pkcs7.h>
#include <openssl/x509.h>
#include <openssl/x509_vfy.h>

#include <algorithm>
#include <array>
#include <filesystem>
#include <memory>

#include "foresight/protocol/error.hpp"

#ifndef FORESIGHT_DDS_SECURITY_PLUGIN_DIR
#define FORESIGHT_DDS_SECURITY_PLUGIN_DIR ""
#endif

namespace foresight::protocol {

std::string security_plugin_dir() { return FORESIGHT_DDS_SECURITY_PLUGIN_DIR; }

namespace {

namespace fs = std::filesystem;

template <auto Free>
struct Deleter {
  template <typename T>
  void operator()(T* p) const noexcept {
    Free(p);
  }
};
using X509Ptr = std::unique_ptr<X509, Deleter<X509_free>>;
using KeyPtr = std::unique_ptr<EVP_PKEY, Deleter<EVP_PKEY_free>>;
using StorePtr = std::unique_ptr<X509_STORE, Deleter<X509_STORE_free>>;
using StoreCtxPtr = std::unique_ptr<X509_STORE_CTX, Deleter<X509_STORE_CTX_free>>;
using BioPtr = std::unique_ptr<BIO, Deleter<BIO_free_all>>;
using Pkcs7Ptr = std::unique_ptr<PKCS7, Deleter<PKCS7_free>>;

/// Every file of the folder's layout present, or the first missing one named.
void require_security_files(const std::string& dir, const std::string& identity) {
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
}

[[noreturn]] void refuse(const fs::path& file, const std::string& what) {
  ERR_clear_error();
  throw ProtocolError("DDS Security: " + file.string() + ": " + what);
}

/// OpenSSL's first queued reason, for a message ("" when none).
std::string openssl_reason() {
  const unsigned long e = ERR_get_error();
  ERR_clear_error();
  if (e == 0) return "";
  std::array<char, 256> buf{};
  ERR_error_string_n(e, buf.data(), buf.size());
  return std::string(" (") + buf.data() + ")";
}

BioPtr open_file(const fs::path& p) {
  std::error_code ec;
  if (!fs::is_regular_file(p, ec)) refuse(p, fs::exists(p, ec) ? "is not a regular file" : "is missing");
  BioPtr b(BIO_new_file(p.c_str(), "r"));
  if (!b) refuse(p, "cannot be read" + openssl_reason());
  return b;
}

X509Ptr read_certificate(const fs::path& p) {
  BioPtr b = open_file(p);
  X509Ptr x(PEM_read_bio_X509(b.get(), nullptr, nullptr, nullptr));
  if (!x) refuse(p, "is not a PEM certificate" + openssl_reason());
  return x;
}

std::string one_line(X509_NAME* name) {
  std::array<char, 512> buf{};
  X509_NAME_oneline(name, buf.data(), static_cast<int>(buf.size()));
  return buf.data();
}

/// An S/MIME document signed by `ca`, its content returned.
std::string signed_content(const fs::path& p, X509* ca, const char* kind) {
  BioPtr b = open_file(p);
  BIO* content_raw = nullptr;
  Pkcs7Ptr p7(SMIME_read_PKCS7(b.get(), &content_raw));
  BioPtr content(content_raw);
  if (!p7) refuse(p, std::string("is not an S/MIME signed ") + kind + " document" + openssl_reason());
  StorePtr store(X509_STORE_new());
  if (!store || X509_STORE_add_cert(store.get(), ca) != 1) refuse(p, "OpenSSL could not set up the verification");
  BioPtr out(BIO_new(BIO_s_mem()));
  if (PKCS7_verify(p7.get(), nullptr, store.get(), content.get(), out.get(), PKCS7_TEXT) != 1)
    refuse(p, std::string("the ") + kind + " document's signature does not verify against the CA" + openssl_reason());
  char* data = nullptr;
  const long n = BIO_get_mem_data(out.get(), &data);
  std::string text(data != nullptr && n > 0 ? data : "", n > 0 ? static_cast<std::size_t>(n) : 0u);
  if (text.find("<dds") == std::string::npos)
    refuse(p, std::string("the signed content is not a DDS Security ") + kind + " document (no <dds> element)");
  return text;
}

}  // namespace

std::string SecurityFacts::describe() const {
  return "identity '" + identity + "' in " + dir + ": certificate signed by the CA, matches its key, " +
         std::to_string(days_left) + " days left; governance and permissions signed by the CA";
}

SecurityFacts verify_security_files(const std::string& dir, const std::string& identity) {
  const fs::path base(dir);
  const fs::path id = base / "identities" / identity;
  const fs::path ca_path = base / "ca.pem", cert_path = id / "cert.pem", key_path = id / "key.pem";
  require_security_files(dir, identity);
  ERR_clear_error();
  const X509Ptr ca = read_certificate(ca_path);
  const X509Ptr cert = read_certificate(cert_path);
  KeyPtr key;
  {
    BioPtr b = open_file(key_path);
    key.reset(PEM_read_bio_PrivateKey(b.get(), nullptr, nullptr, nullptr));
    if (!key) refuse(key_path, "is not a PEM private key (or it is encrypted)" + openssl_reason());
  }
  if (X509_check_private_key(cert.get(), key.get()) != 1) refuse(cert_path, "does not match its key.pem");
  StorePtr store(X509_STORE_new());
  StoreCtxPtr ctx(X509_STORE_CTX_new());
  if (!store || !ctx || X509_STORE_add_cert(store.get(), ca.get()) != 1 ||
      X509_STORE_CTX_init(ctx.get(), store.get(), cert.get(), nullptr) != 1)
    refuse(cert_path, "OpenSSL could not set up the verification");
  if (X509_verify_cert(ctx.get()) != 1) {
    const int err = X509_STORE_CTX_get_error(ctx.get());
    refuse(cert_path, "does not verify against " + ca_path.string() + ": " + X509_verify_cert_error_string(err));
  }
  (void)signed_content(base / "governance.p7s", ca.get(), "governance");
  (void)signed_content(base / "permissions.p7s", ca.get(), "permissions");
  SecurityFacts f;
  f.identity = identity;
  f.dir = dir;
  f.subject = one_line(X509_get_subject_name(cert.get()));
  int days = 0, secs = 0;
  ASN1_TIME_diff(&days, &secs, nullptr, X509_get0_notAfter(cert.get()));
  f.days_left = days;
  return f;
}

Qos security_qos(const std::string& dir, const std::string& identity) {
  require_security_files(dir, identity);
  const fs::path base(dir);
  const fs::path id = base / "identities" / identity;
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
  (void)verify_security_files(security_dir, identity);  // a damaged file named, not Cyclone's bare "Error"
  return Participant(domain, security_qos(security_dir, identity));
}

ParticipantGuid identity_of(const ParticipantGuid& guid) {
  ParticipantGuid out;
  std::copy(guid.bytes.begin(), guid.bytes.begin() + 6, out.bytes.begin());
  return out;
}

ParticipantGuid identity_of_certificate(const std::string& cert_pem_path) {
  const X509Ptr cert = read_certificate(cert_pem_path);
  unsigned char* der = nullptr;
  const int n = i2d_X509_NAME(X509_get_subject_name(cert.get()), &der);
  if (n <= 0) refuse(cert_pem_path, "its subject cannot be encoded" + openssl_reason());
  std::array<unsigned char, EVP_MAX_MD_SIZE> h{};
  unsigned int len = 0;
  const int ok = EVP_Digest(der, static_cast<std::size_t>(n), h.data(), &len, EVP_sha256(), nullptr);
  OPENSSL_free(der);
  if (ok != 1 || len < 6) refuse(cert_pem_path, "SHA-256 failed" + openssl_reason());
  ParticipantGuid out;
  out.bytes[0] = static_cast<std::uint8_t>(0x80u | (h[0] >> 1));
  for (std::size_t i = 1; i < 6; ++i) out.bytes[i] = static_cast<std::uint8_t>(((h[i - 1] << 7) & 0xffu) | (h[i] >> 1));
  return out;
}

std::vector<std::pair<ParticipantGuid, std::string>> known_identities(const std::string& dir) {
  std::vector<std::pair<ParticipantGuid, std::string>> out;
  std::error_code ec;
  for (const auto& e : fs::directory_iterator(fs::path(dir) / "identities", ec)) {
    try {
      out.emplace_back(identity_of_certificate((e.path() / "cert.pem").string()), e.path().filename().string());
    } catch (const ProtocolError&) {
    }
  }
  std::sort(out.begin(), out.end());
  return out;
}

}  // namespace foresight::protocol
