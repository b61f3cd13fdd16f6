#pragma once
// A simulated CANopen node on the far end of a mock bus: object dictionary,
// SDO server (expedited download/upload, segmented upload), NMT slave,
// heartbeat producer, EMCY producer, and fault injection. SimDrive and
// SimFtSensor derive from it. Not real-time code (it simulates the device).
//
// Threading: the CanSimulator thread calls handle()/tick(); the public
// injection and query methods may be called from any other thread (each node
// has its own mutex).

#include <linux/can.h>

#include <atomic>
#include <chrono>
#include <cstdint>
#include <map>
#include <mutex>
#include <string>

#include "foresight/hw/canopen.hpp"

namespace foresight::sim {

using Clock = std::chrono::steady_clock;

/// Where a node's frames go (the simulator writes them on the bus).
class FrameSink {
 public:
  virtual ~FrameSink() = default;
  virtual void send(const can_frame& f) = 0;
};

class SimNode {
 public:
  SimNode(std::uint8_t node_id, std::uint32_t device_type, std::string device_name);
  virtual ~SimNode();
  SimNode(const SimNode&) = delete;
  SimNode& operator=(const SimNode&) = delete;

  std::uint8_t node_id() const noexcept { return node_id_; }
  hw::canopen::NmtState nmt_state() const;

  // ---- fault injection (any thread) ----------------------------------------
  /// Stop (true) or resume sending heartbeats; everything else keeps working.
  void silence_heartbeat(bool silent);
  /// Ignore every frame and send nothing (a node that fell off the bus).
  void stop_answering(bool silent);
  /// The next SDO access to index:sub is aborted with `code`.
  void inject_sdo_abort(std::uint16_t index, std::uint8_t sub, std::uint32_t code);
  /// The next `count` SDO requests (initiate: expedited read or write) to
  /// index:sub are served, but their responses are lost on the wire.
  void drop_sdo_responses(std::uint16_t index, std::uint8_t sub, int count);
  /// Segmented uploads answer segment 1 with the wrong toggle bit.
  void inject_bad_toggle(bool on);
  /// Send an EMCY frame (code, error register) at the next tick; no state change.
  void send_emcy(std::uint16_t code, std::uint8_t error_register);
  /// Reboot at the next tick (a brown-out): boot-up message, pre-operational,
  /// object dictionary back to its defaults (PDO mapping lost).
  void inject_reboot();

  /// Frames this node has accepted (addressed to it or broadcast).
  std::uint64_t frames_handled() const;

  // ---- simulator side ---------------------------------------------------------
  void handle(const can_frame& f, Clock::time_point now, FrameSink& out);
  void tick(Clock::time_point now, FrameSink& out);
  /// Power-on: reset and send the boot-up message.
  void power_on(FrameSink& out);

 protected:
  struct Entry {
    std::uint32_t value = 0;
    std::uint8_t size = 4;  // bytes, 1..4; 0 for a string
    bool writable = false;
    std::string text;       // visible string objects
  };
  static constexpr std::uint32_t key(std::uint16_t index, std::uint8_t sub) {
    return (static_cast<std::uint32_t>(index) << 8) | sub;
  }
  void define(std::uint16_t index, std::uint8_t sub, std::uint8_t size, bool writable, std::uint32_t value);
  std::uint32_t get(std::uint16_t index, std::uint8_t sub) const;
  void set(std::uint16_t index, std::uint8_t sub, std::uint32_t value);
  bool has(std::uint16_t index, std::uint8_t sub) const { return od_.count(key(index, sub)) != 0; }

  /// Device hooks, called with mu_ held.
  virtual void reset_application() = 0;  ///< OD and device state to power-on defaults
  virtual void on_sync(Clock::time_point now, FrameSink& out) = 0;
  virtual void on_frame(const can_frame& f, FrameSink& out);  ///< PDOs, other nodes' heartbeats
  virtual void on_tick(Clock::time_point now, FrameSink& out);  ///< time-driven device behaviour
  /// Validate an SDO download; 0 to accept, else the abort code.
  virtual std::uint32_t check_sdo_write(std::uint16_t index, std::uint8_t sub, std::uint32_t value);
  /// After an accepted SDO download (e.g. 0x6060 shows in 0x6061 at once).
  virtual void on_sdo_written(std::uint16_t index, std::uint8_t sub);
  void emit_emcy(std::uint16_t code, std::uint8_t error_register, FrameSink& out);

  mutable std::mutex mu_;
  Clock::time_point now_{};  ///< time of the frame or tick being handled
  std::map<std::uint32_t, Entry> od_;
  hw::canopen::NmtState nmt_ = hw::canopen::NmtState::PreOperational;
  const std::uint8_t node_id_;

 private:
  void reset_communication();
  void sdo(const can_frame& f, FrameSink& out);
  void sdo_abort(std::uint16_t index, std::uint8_t sub, std::uint32_t code, FrameSink& out);
  void boot(FrameSink& out);

  const std::uint32_t device_type_;
  const std::string device_name_;
  bool silent_hb_ = false;
  bool silent_ = false;
  bool bad_toggle_ = false;
  std::map<std::uint32_t, std::uint32_t> pending_aborts_;
  std::map<std::uint32_t, int> dropped_responses_;
  bool dropping_ = false;
  // segmented upload in progress
  bool seg_active_ = false;
  std::string seg_data_;
  std::size_t seg_pos_ = 0;
  std::uint8_t seg_toggle_ = 0;
  int seg_count_ = 0;
  std::uint16_t seg_index_ = 0;
  std::uint8_t seg_sub_ = 0;
  Clock::time_point next_hb_{};
  bool hb_armed_ = false;
  std::uint64_t frames_ = 0;
  bool pending_reboot_ = false;
  bool pending_emcy_ = false;
  std::uint16_t pending_emcy_code_ = 0;
  std::uint8_t pending_emcy_reg_ = 0;
};

}  // namespace foresight::sim
