#pragma once
// Who holds control of the arm.
//
// One ground session holds control (TAKE_CONTROL / RELEASE_CONTROL), from the
// participant that took it: the commander's session id read off a published
// ack and sent from another participant moves nothing. With DDS Security
// (`stations`) writers are identities and control belongs to a station's
// identity, across its processes and sessions. A holder that has sent nothing
// for the lease with nothing of its own running may be superseded.

#include <chrono>
#include <cstdint>
#include <functional>
#include <string>
#include <utility>
#include <vector>

#include "foresight/protocol/command.hpp"

namespace foresight::daemon {

class ControlHolder {
 public:
  using Clock = std::chrono::steady_clock;
  struct Options {
    bool stations = false;  ///< DDS Security: writers are identities
    /// The identities known by name (protocol::known_identities).
    std::vector<std::pair<protocol::ParticipantGuid, std::string>> identities;
    double lease_s = 0.0;  ///< controller.control_lease_s
    /// Told the participant in control whenever it changes (unknown: nobody).
    std::function<void(const protocol::ParticipantGuid&)> announce;
  };
  explicit ControlHolder(Options options) : o_(std::move(options)) {}

  /// The writer of the command at hand (each command sets it before it is handled).
  void set_writer(const protocol::ParticipantGuid& writer) noexcept { writer_ = writer; }
  const protocol::ParticipantGuid& writer() const noexcept { return writer_; }

  std::uint64_t session() const noexcept { return session_; }  ///< 0: nobody holds control
  const protocol::ParticipantGuid& holder_writer() const noexcept { return holder_writer_; }
  bool stations() const noexcept { return o_.stations; }

  /// The command at hand is the holder's: its session, from its participant;
  /// with DDS Security any session of the holding station.
  bool from_holder(const protocol::Command& c) const noexcept {
    return session_ != 0 && writer_ == holder_writer_ && (o_.stations || c.session_id == session_);
  }
  /// "" when the command at hand may command the arm, else why not (NotInControl).
  std::string check(const protocol::Command& c, protocol::Reason* code) const;
  /// The holder is silent past its lease (the caller knows it runs nothing).
  bool lease_over(Clock::time_point now) const noexcept;

  /// The writer at hand takes control for `session`.
  void take(std::uint64_t session);
  void release();
  /// The holder spoke: its lease starts again.
  void touch(Clock::time_point now) noexcept { active_ = now; }

  /// "participant 0110a4c1.5e3f0001.00000000.000001c1", or with DDS Security
  /// "station 'ground' (eb49bb7a.00a60000.00000000.00000000)".
  std::string writer_text(const protocol::ParticipantGuid& writer) const;

 private:
  void set(std::uint64_t session, const protocol::ParticipantGuid& writer);

  Options o_;
  std::uint64_t session_ = 0;
  /// The participant whose TAKE_CONTROL made session_ (unknown when discovery
  /// had lost its writer): the holding session speaks only from it.
  protocol::ParticipantGuid holder_writer_;
  protocol::ParticipantGuid writer_;  ///< of the command at hand
  Clock::time_point active_{};
};

}  // namespace foresight::daemon
