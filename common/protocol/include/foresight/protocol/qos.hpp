#pragma once
// QoS profiles of the protocol, in one place (the reasons are in qos.cpp and
// docs/protocol.md). Both sides must use the same profile for a topic: DDS
// matches a reader and a writer only when their policies are compatible.
// Not real-time: every function allocates.

#include <dds/dds.h>

#include <cstdint>

namespace foresight::protocol {

/// Owns a dds_qos_t. Move-only; clone() copies.
class Qos {
 public:
  Qos();  ///< empty QoS (Cyclone defaults)
  ~Qos();
  Qos(Qos&& other) noexcept;
  Qos& operator=(Qos&& other) noexcept;
  Qos(const Qos&) = delete;
  Qos& operator=(const Qos&) = delete;

  Qos clone() const;
  const dds_qos_t* get() const noexcept { return qos_; }
  dds_qos_t* get() noexcept { return qos_; }

  // Builders, chainable: Qos().reliable(1.0).keep_all()
  Qos& reliable(double max_blocking_s);
  Qos& best_effort();
  Qos& keep_all();
  Qos& keep_last(std::int32_t depth);
  Qos& volatile_durability();
  Qos& transient_local();

 private:
  dds_qos_t* qos_;
};

namespace qos {

/// Commands: reliable, keep-all, volatile (a restarted remote must never
/// replay old commands).
Qos command();
/// Command acks: reliable, keep-all, volatile.
Qos command_ack();
/// Trajectory chunks: reliable, keep-all, volatile, long blocking time.
Qos trajectory_chunk();
/// Upload state per trajectory_id: reliable, keep-last 1, transient-local.
Qos trajectory_status();
/// Joint state, wrench, tool state: best-effort, keep-last `depth`, volatile.
Qos telemetry(std::int32_t depth = 8);
/// Controller status: reliable, keep-last 1, transient-local.
Qos controller_status();
/// Heartbeat: best-effort, keep-last 1, volatile.
Qos heartbeat();
/// Ping and pong: best-effort, keep-last 16, volatile.
Qos ping();

}  // namespace qos
}  // namespace foresight::protocol
