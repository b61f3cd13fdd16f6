#pragma once
// The CANopen SDO client (CiA 301): expedited download and upload, segmented
// upload of visible strings, one bus, blocking with a timeout. Set-up code
// only (NOT real-time: blocks, allocates, throws SdoError/HwError). An
// expedited transfer (or a segmented upload's initiate) that times out is
// aborted and sent once more before it fails; a retry that is answered is
// kept as a notice (notices()). Frames
// that arrive during a transfer and are not its response go to the
// `other_frames` handler (heartbeats, EMCY, boot-ups keep being seen).

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "foresight/common/error.hpp"
#include "foresight/common/spsc_ring.hpp"
#include "foresight/hw/can_bus.hpp"

namespace foresight::hw {

/// Set-up failure (configure/enable): says which bus, node and joint. A
/// ComputationError (foresight/common/error.hpp): an operation failed.
class HwError : public ComputationError {
 public:
  using ComputationError::ComputationError;
};

/// An SDO transfer failed. kind says how; abort_code is the CiA 301 code
/// (received from the server for Abort, sent by us for Timeout/Protocol).
class SdoError : public HwError {
 public:
  enum class Kind { Abort, Timeout, Protocol };
  SdoError(Kind kind, std::uint32_t abort_code, const std::string& message)
      : HwError(message), kind_(kind), abort_code_(abort_code) {}
  Kind kind() const noexcept { return kind_; }
  std::uint32_t abort_code() const noexcept { return abort_code_; }

 private:
  Kind kind_;
  std::uint32_t abort_code_;
};

/// "0x%04X:%02X"
std::string od_name(std::uint16_t index, std::uint8_t sub);
/// "0x" + `digits` upper-case hex digits.
std::string hex_text(std::uint32_t value, int digits);

/// Send one frame, waiting up to 100 ms for room in the transmit queue.
/// Throws HwError "bus NAME: cannot send COB-ID 0x...: <CanIo>". Set-up only.
void write_setup_frame(CanBus& bus, const std::string& bus_name, const can_frame& f);

class SdoClient {
 public:
  using FrameHandler = std::function<void(const can_frame&)>;
  using NodeLabel = std::function<std::string(std::uint8_t node)>;

  /// `bus` must outlive the client. `label(node)` names a node in messages
  /// ("joint3 (bus arm_a node 3)").
  SdoClient(CanBus& bus, std::string bus_name, double timeout_s, FrameHandler other_frames, NodeLabel label);

  /// Expedited upload of a 1..4-byte object.
  std::uint32_t read(std::uint8_t node, std::uint16_t index, std::uint8_t sub);
  /// Expedited download of `size_bytes` (1..4).
  void write(std::uint8_t node, std::uint16_t index, std::uint8_t sub, std::uint32_t value, int size_bytes);
  /// Segmented (or expedited) upload of a visible string (at most 1024 bytes).
  std::string read_string(std::uint8_t node, std::uint16_t index, std::uint8_t sub);

  /// Take the responses from `inbox` instead of reading the bus (which
  /// another thread reads: the real-time cycle hands the node's SDO answers
  /// over, DriveSystem::configure_nodes). Requests are still written to the bus.
  void receive_from(SpscRing<can_frame>* inbox) noexcept { inbox_ = inbox; }

  double timeout_s() const noexcept { return timeout_s_; }
  /// What went wrong and was recovered, one line each ("SDO read 0x1000:00 of
  /// joint3 (bus arm_a node 3): no response within 500 ms; the retry was
  /// answered"), since construction or clear_notices().
  const std::vector<std::string>& notices() const noexcept { return notices_; }
  void clear_notices() { notices_.clear(); }

 private:
  /// One transfer step; with `retry`, a timeout aborts and sends the request
  /// once more before failing (SdoError Timeout: "...: timed out after N ms
  /// (no response), also on the retry").
  can_frame exchange(std::uint8_t node, const can_frame& request, const char* what, std::uint16_t index,
                     std::uint8_t sub, bool retry);
  can_frame exchange_once(std::uint8_t node, const can_frame& request, const std::string& label,
                          std::uint16_t index, std::uint8_t sub);
  [[noreturn]] void throw_response_error(const can_frame& r, const std::string& label, std::uint16_t index,
                                         std::uint8_t sub) const;

  CanBus& bus_;
  std::string bus_name_;
  double timeout_s_;
  FrameHandler other_;
  NodeLabel label_;
  std::vector<std::string> notices_;
  SpscRing<can_frame>* inbox_ = nullptr;
};

}  // namespace foresight::hw
