#include "foresight/daemon/ledger.hpp"

#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>

#include <cctype>
#include <type_traits>
#include <variant>

#include "foresight/common/json_text.hpp"
#include "foresight/control/command.hpp"
#include "foresight/common/format.hpp"

namespace foresight::daemon {

using protocol::AckState;
using protocol::Reason;

namespace {

constexpr std::size_t kAckMemory = 1024;  // commands whose last ack is kept (duplicates, chains)

/// The payload as JSON, for the RECEIVED row.
nlohmann::json payload_json(const protocol::Command& c) {
  nlohmann::json j = nlohmann::json::object();
  std::visit(
      [&](const auto& p) {
        using P = std::decay_t<decltype(p)>;
        if constexpr (std::is_same_v<P, protocol::RunTrajectory>) {
          j["trajectory_id"] = p.trajectory_id;
          j["hash"] = to_hex(p.content_hash);
          j["compliant"] = p.compliant;
          j["start_tolerance_rad"] = p.start_tolerance_rad;
          j["upload_wait_s"] = p.upload_wait_s;
        } else if constexpr (std::is_same_v<P, protocol::InvokeAlgorithm>) {
          j["name"] = p.name;
          nlohmann::json params = nlohmann::json::object();
          for (const auto& nv : p.params) params[nv.name] = nv.value;
          j["params"] = params;
          j["timeout_s"] = p.timeout_s;
        } else if constexpr (std::is_same_v<P, protocol::Request>) {
          j["what"] = static_cast<int>(p.what);
        } else if constexpr (std::is_same_v<P, protocol::CameraCommand>) {
          j["camera"] = p.camera;
          j["action"] = static_cast<int>(p.action);
          j["pan_rad"] = p.pan_rad;
          j["tilt_rad"] = p.tilt_rad;
          j["focal_px"] = p.focal_px;
        } else if constexpr (std::is_same_v<P, protocol::GotoJoint>) {
          j["q_rad"] = p.q_rad;
          j["speed_fraction"] = p.speed_fraction;
        } else if constexpr (std::is_same_v<P, protocol::GotoCart>) {
          j["frame"] = p.frame;
          const Eigen::Vector3d t = p.base_T_frame.translation();
          j["position_m"] = {t.x(), t.y(), t.z()};
          const Eigen::Quaterniond q(p.base_T_frame.linear());
          j["orientation_xyzw"] = {q.x(), q.y(), q.z(), q.w()};
          j["speed_fraction"] = p.speed_fraction;
        } else if constexpr (std::is_same_v<P, protocol::Abort>) {
          j["target_command_id"] = p.target_command_id;
          j["category"] = static_cast<int>(p.category);
          j["reason"] = p.reason;
        }
      },
      c.payload);
  return j;
}

}  // namespace

Ledger::Ledger(journal::Journal& journal, SendAck send) : journal_(journal), send_(std::move(send)) {}

void Ledger::received(const protocol::Command& command, const std::string& writer_hex, const std::string& station) {
  nlohmann::json detail = payload_json(command);
  detail["writer"] = writer_hex;  // the participant (with DDS Security: the identity) that sent it
  if (!station.empty()) detail["station"] = station;
  if (command.after_command_id != 0) detail["after_command_id"] = command.after_command_id;
  acknowledge(command, AckState::Received, Reason::None, {}, {}, json_text(detail));
}

void Ledger::ack(const protocol::Command& command, AckState state, Reason code, const std::string& reason,
                 std::vector<double> final_q) {
  nlohmann::json detail = nlohmann::json::object();
  if (!final_q.empty()) detail["final_q_rad"] = final_q;
  acknowledge(command, state, code, reason, std::move(final_q), json_text(detail));
}

void Ledger::acknowledge(const protocol::Command& command, AckState state, Reason code, const std::string& reason,
                         std::vector<double> final_q, const std::string& detail_json) {
  protocol::Ack a;
  a.session_id = command.session_id;
  a.command_id = command.command_id;
  a.sequence_number = command.sequence_number;
  a.kind = command.kind;
  a.state = state;
  a.code = code;
  a.reason = reason;
  a.stamp_ns = journal::Journal::now_ns();
  a.final_q_rad = std::move(final_q);

  journal::CommandRow row;
  row.stamp_ns = a.stamp_ns;
  row.session_id = a.session_id;
  row.command_id = a.command_id;
  row.sequence_number = a.sequence_number;
  row.kind = upper(control::to_string(a.kind));
  row.state = upper(control::to_string(state));
  row.code = upper(control::to_string(code));
  row.reason = reason;
  row.detail = detail_json;
  try {
    journal_.record_command(row);  // durable before the ack leaves
  } catch (const std::exception& e) {
    spdlog::error("journal: {} (command {} {})", e.what(), a.command_id, row.state);
  }
  if (send_) send_(a);
  const CommandKey key{a.session_id, a.command_id};
  if (!last_ack_.count(key)) {
    last_ack_order_.push_back(key);
    if (last_ack_order_.size() > kAckMemory) {
      last_ack_.erase(last_ack_order_.front());
      last_ack_order_.pop_front();
    }
  }
  last_ack_[key] = std::move(a);
}

void Ledger::reject(const protocol::Command& command, Reason code, const std::string& reason) {
  spdlog::warn("command {} ({}) rejected: {}: {}", command.command_id, control::to_string(command.kind),
               control::to_string(code), reason);
  ack(command, AckState::Rejected, code, reason);
}

bool Ledger::resend(std::uint64_t session, std::uint64_t command_id) const {
  const protocol::Ack* a = last(session, command_id);
  if (a == nullptr) return false;
  if (send_) send_(*a);
  return true;
}

const protocol::Ack* Ledger::last(std::uint64_t session, std::uint64_t command_id) const {
  const auto it = last_ack_.find({session, command_id});
  return it == last_ack_.end() ? nullptr : &it->second;
}

void Ledger::event(const std::string& kind, const std::string& text, const std::string& detail) {
  try {
    journal::EventRow row;
    row.stamp_ns = journal::Journal::now_ns();
    row.kind = kind;
    row.text = text;
    row.detail = detail;
    journal_.record_event(row);
  } catch (const std::exception& e) {
    spdlog::error("journal: {}", e.what());
  }
}

void Ledger::upload(const journal::UploadRow& row) {
  try {
    journal_.record_upload(row);
  } catch (const std::exception& ex) {
    spdlog::error("journal: {}", ex.what());
  }
}

void Ledger::fault(const journal::FaultRow& row) {
  try {
    journal_.record_fault(row);
  } catch (const std::exception& ex) {
    spdlog::error("journal: {}", ex.what());
  }
}

}  // namespace foresight::daemon
