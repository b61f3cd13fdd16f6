#include "foresight/daemon/control_holder.hpp"

#include <cstdio>

namespace foresight::daemon {

namespace {

/// A session id as 16 hex digits.
std::string hex16(std::uint64_t v) {
  char buf[20];
  std::snprintf(buf, sizeof buf, "%016llx", static_cast<unsigned long long>(v));
  return buf;
}

}  // namespace

std::string ControlHolder::check(const protocol::Command& c, protocol::Reason* code) const {
  if (from_holder(c)) return {};
  *code = protocol::Reason::NotInControl;
  if (session_ != 0 && c.session_id == session_) {
    // The holder's session id from another participant: read off a
    // published ack, it must not move the arm (journaled with its writer).
    return "session " + hex16(session_) + " is in control from " + writer_text(holder_writer_) +
           "; this command came from " + writer_text(writer_);
  }
  if (session_ == 0) return std::string("no ground station holds control: send TAKE_CONTROL first");
  if (o_.stations) return writer_text(holder_writer_) + " holds control";
  return "ground session " + hex16(session_) + " holds control";
}

bool ControlHolder::lease_over(Clock::time_point now) const noexcept {
  return session_ != 0 && now - active_ > std::chrono::duration<double>(o_.lease_s);
}

void ControlHolder::take(std::uint64_t session) { set(session, writer_); }

void ControlHolder::release() { set(0, {}); }

void ControlHolder::set(std::uint64_t session, const protocol::ParticipantGuid& writer) {
  session_ = session;
  holder_writer_ = session != 0 ? writer : protocol::ParticipantGuid{};
  if (o_.announce) o_.announce(holder_writer_);
}

std::string ControlHolder::writer_text(const protocol::ParticipantGuid& writer) const {
  if (!o_.stations) return "participant " + writer.hex();
  for (const auto& [id, name] : o_.identities)
    if (id == writer) return "station '" + name + "' (" + writer.hex() + ")";
  return "station " + writer.hex();
}

}  // namespace foresight::daemon
