#pragma once
// The options every command that talks to the remote shares (include it only
// from commands/*.cpp that register a command).

#include "command.hpp"
#include "foresight/session/link_session.hpp"

namespace foresight::cli {

/// `json`: false when the command adds its own --json (e.g. with the render options).
inline void add_link_options(Command& sub, session::LinkOptions& o, bool final_ack = true, bool json = true) {
  sub.add_option("--domain", o.domain, "DDS domain id (default: $FORESIGHT_DDS_DOMAIN, else 0)")
      ->check(check::Range(0, 232));
  sub.add_option("--security", o.security_dir,
                 "DDS Security: the folder made by make_dds_security.sh (default: $FORESIGHT_DDS_SECURITY; unset: "
                 "plain DDS)");
  sub.add_option("--identity", o.identity,
                 "this station's identity in that folder (default: $FORESIGHT_DDS_IDENTITY, else ground)");
  sub.add_option("--connect-timeout", o.connect_timeout_s, "seconds to wait for the remote to answer")
      ->check(check::WaitSeconds)
      ->capture_default_str();
  if (final_ack)
    sub.add_option("--timeout", o.timeout_s,
                   "seconds to wait for the final acknowledgement (default: 1.5 x the expected duration + 3 x the "
                   "measured p99 round trip + 5 s)")
        ->check(check::WaitSeconds);
  if (json) sub.add_flag("--json", o.json, "print one JSON object");
}

}  // namespace foresight::cli
