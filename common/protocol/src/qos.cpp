#include "foresight/protocol/qos.hpp"

#include <utility>

#include "foresight/protocol/error.hpp"

namespace foresight::protocol {

Qos::Qos() : qos_(dds_create_qos()) {
  if (qos_ == nullptr) throw ProtocolError("dds_create_qos: out of memory");
}
Qos::~Qos() {
  if (qos_ != nullptr) dds_delete_qos(qos_);
}
Qos::Qos(Qos&& other) noexcept : qos_(std::exchange(other.qos_, nullptr)) {}
Qos& Qos::operator=(Qos&& other) noexcept {
  if (this != &other) {
    if (qos_ != nullptr) dds_delete_qos(qos_);
    qos_ = std::exchange(other.qos_, nullptr);
  }
  return *this;
}

Qos Qos::clone() const {
  Qos copy;
  check(dds_copy_qos(copy.qos_, qos_), "dds_copy_qos");
  return copy;
}

Qos& Qos::reliable(double max_blocking_s) {
  dds_qset_reliability(qos_, DDS_RELIABILITY_RELIABLE, static_cast<dds_duration_t>(max_blocking_s * 1e9));
  return *this;
}
Qos& Qos::best_effort() {
  dds_qset_reliability(qos_, DDS_RELIABILITY_BEST_EFFORT, 0);
  return *this;
}
Qos& Qos::keep_all() {
  dds_qset_history(qos_, DDS_HISTORY_KEEP_ALL, 0);
  return *this;
}
Qos& Qos::keep_last(std::int32_t depth) {
  if (depth < 1) throw ProtocolError("keep_last: depth must be >= 1, got " + std::to_string(depth));
  dds_qset_history(qos_, DDS_HISTORY_KEEP_LAST, depth);
  return *this;
}
Qos& Qos::volatile_durability() {
  dds_qset_durability(qos_, DDS_DURABILITY_VOLATILE);
  return *this;
}
Qos& Qos::transient_local() {
  dds_qset_durability(qos_, DDS_DURABILITY_TRANSIENT_LOCAL);
  return *this;
}

namespace qos {

// Commands must arrive, all of them, in order: reliable + keep-all. Volatile
// on purpose: with transient-local a remote daemon that restarts would be
// handed the ground's old commands again and could re-run a motion.
// A write blocks at most 1 s when the remote stops acknowledging (then
// ProtocolError with "Timeout"); a command is small, so that only happens
// when the link is gone.
Qos command() { return std::move(Qos().reliable(1.0).keep_all().volatile_durability()); }

// Every state change of a command matters to the ground (a lost COMPLETED
// would leave the simulated arm un-updated): reliable + keep-all. Volatile: a
// ground that joins late learns the present from ControllerStatus, not from
// replayed acks of someone else's session.
Qos command_ack() { return std::move(Qos().reliable(1.0).keep_all().volatile_durability()); }

// A trajectory runs only when every chunk arrived: reliable + keep-all.
// Several 64 KiB chunks can exceed Cyclone's writer history high-water mark,
// so a write may wait for acknowledgements, which take a round trip: at the
// paper's 4 s round trip (plus jitter and retransmissions after loss) 5 s
// failed uploads through the link emulator, so allow 30 s before failing.
// Volatile: an upload is meaningful only to the remote that was there.
Qos trajectory_chunk() { return std::move(Qos().reliable(30.0).keep_all().volatile_durability()); }

// Keyed per trajectory_id; the last state of each upload is what matters, and
// a ground that (re)joins must see which trajectories the remote holds:
// reliable + keep-last 1 + transient-local.
Qos trajectory_status() { return std::move(Qos().reliable(1.0).keep_last(1).transient_local()); }

// Telemetry is periodic and only the newest sample is worth having: a lost or
// late sample is replaced by the next one, and a retransmission would only
// deliver stale data late and add load. Best-effort + keep-last. The depth
// (default 8) lets a reader that wakes up at a lower rate than the publisher
// take the recent samples it missed (plots, logs) without unbounded memory.
Qos telemetry(std::int32_t depth) { return std::move(Qos().best_effort().keep_last(depth).volatile_durability()); }

// The controller status carries the mode and the reason of the last stop:
// state, not a stream, and a stop reason must not be lost: reliable +
// keep-last 1. Transient-local so a ground that starts (or restarts) after
// the remote immediately sees the current mode and why it last stopped.
Qos controller_status() { return std::move(Qos().reliable(1.0).keep_last(1).transient_local()); }

// A heartbeat proves the sender is alive *now*: a retransmitted or replayed
// (transient-local) old beat would claim liveness falsely. Best-effort,
// keep-last 1, volatile; the receiver judges liveness by the age of the last
// beat it got.
Qos heartbeat() { return std::move(Qos().best_effort().keep_last(1).volatile_durability()); }

// Ping/pong measure the network delay. A retransmitted ping would measure
// the retransmission timer, not the path, so pings are best-effort: a lost
// ping is a lost measurement, and the ground sends the next one. Depth 16 so
// a burst of pings (start-up estimate) is not overwritten before it is read.
Qos ping() { return std::move(Qos().best_effort().keep_last(16).volatile_durability()); }

}  // namespace qos
}  // namespace foresight::protocol
