#pragma once
// Errors from the DDS layer. Set-up code (creating participants, readers,
// writers, waitsets) throws ProtocolError; the message names what was being
// done and Cyclone's own text for the return code (dds_strretcode).

#include <dds/dds.h>

#include <stdexcept>
#include <string>

#include "foresight/common/error.hpp"

namespace foresight::protocol {

/// A ComputationError (foresight/common/error.hpp): the CLI exits 1.
class ProtocolError : public ComputationError {
 public:
  /// `what` describes the failed call, e.g. "create writer on foresight/command".
  ProtocolError(const std::string& what, dds_return_t code)
      : ComputationError(what + ": " + dds_strretcode(code)), code_(code) {}
  explicit ProtocolError(const std::string& what) : ComputationError(what), code_(DDS_RETCODE_ERROR) {}

  /// The Cyclone return code (negative), DDS_RETCODE_ERROR when not from Cyclone.
  dds_return_t code() const noexcept { return code_; }

 private:
  dds_return_t code_;
};

/// Throws ProtocolError when `rc` is negative (a failed call or an invalid
/// entity handle); returns `rc` otherwise.
inline dds_return_t check(dds_return_t rc, const std::string& what) {
  if (rc < 0) throw ProtocolError(what, rc);
  return rc;
}

}  // namespace foresight::protocol
