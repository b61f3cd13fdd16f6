#pragma once
// The supervisor's ledger: every row the supervisor writes to the journal,
// and the acks that follow them.
//
// A command's every state is journaled durably before its ack leaves, so the
// journal never says less than the ground was told. The last ack of each
// command is remembered (bounded): a re-sent command is answered with it,
// and a chained command checks its predecessor's. A journal that fails is
// logged, never thrown: the arm's safety does not wait on the disk.

#include <cstdint>
#include <deque>
#include <functional>
#include <map>
#include <string>
#include <utility>
#include <vector>

#include "foresight/journal/journal.hpp"
#include "foresight/protocol/command.hpp"

namespace foresight::daemon {

class Ledger {
 public:
  using SendAck = std::function<void(const protocol::Ack&)>;
  /// `send` may be empty (nothing sent, everything journaled).
  Ledger(journal::Journal& journal, SendAck send);

  /// RECEIVED: the payload and its writer ("participant ..." / the station)
  /// in the row's detail.
  void received(const protocol::Command& command, const std::string& writer_hex, const std::string& station);
  /// Journal durably, then acknowledge.
  void ack(const protocol::Command& command, protocol::AckState state, protocol::Reason code = protocol::Reason::None,
           const std::string& reason = {}, std::vector<double> final_q = {});
  /// REJECTED, logged as a warning.
  void reject(const protocol::Command& command, protocol::Reason code, const std::string& reason);
  /// Send the command's last ack again (a re-sent command); false when none is remembered.
  bool resend(std::uint64_t session, std::uint64_t command_id) const;
  /// The last ack of (session, command id); null when not remembered.
  const protocol::Ack* last(std::uint64_t session, std::uint64_t command_id) const;

  /// An event row (kind, text, JSON detail).
  void event(const std::string& kind, const std::string& text, const std::string& detail = {});
  void upload(const journal::UploadRow& row);
  void fault(const journal::FaultRow& row);
  /// A telemetry row to the journal's ring (not durable; dropped when full).
  void telemetry(const journal::TelemetryRow& row) { (void)journal_.push_telemetry(row); }

 private:
  void acknowledge(const protocol::Command& command, protocol::AckState state, protocol::Reason code,
                   const std::string& reason, std::vector<double> final_q, const std::string& detail_json);

  journal::Journal& journal_;
  SendAck send_;
  using CommandKey = std::pair<std::uint64_t, std::uint64_t>;  ///< (session, command id): ids restart per session
  std::map<CommandKey, protocol::Ack> last_ack_;
  std::deque<CommandKey> last_ack_order_;
};

}  // namespace foresight::daemon
