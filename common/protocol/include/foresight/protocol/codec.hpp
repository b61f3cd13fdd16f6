#pragma once
// Helpers to fill and read the generated C structs from C++: bounded strings,
// sequences, time stamps, and the delay arithmetic of Ping/Pong.
//
// Real-time safety: text(), view(), now_ns(), delay_from_pong() and
// borrow() are noexcept and do not allocate. set_text() and assign() may
// throw (bound exceeded) and assign() allocates when the sequence grows.

#include <dds/dds.h>

#include <cstdint>
#include <cstring>
#include <span>
#include <stdexcept>
#include <string>
#include <string_view>
#include <type_traits>

#include "foresight/protocol/messages.hpp"

namespace foresight::protocol {

/// The text of a bounded IDL string (a char[N + 1] member).
template <std::size_t N>
std::string_view text(const char (&field)[N]) noexcept {
  return std::string_view(field, strnlen(field, N));
}

/// Copies `value` into a bounded IDL string. Throws std::length_error naming
/// `what` when `value` is longer than the bound (N - 1 characters).
template <std::size_t N>
void set_text(char (&field)[N], std::string_view value, std::string_view what) {
  if (value.size() > N - 1) {
    throw std::length_error(std::string(what) + ": " + std::to_string(value.size()) +
                            " characters exceed the protocol bound of " + std::to_string(N - 1));
  }
  std::memcpy(field, value.data(), value.size());
  std::memset(field + value.size(), 0, N - value.size());
}

/// For human-readable text (reasons, faults): cuts `value` at the bound
/// instead of failing, ending it with "..." when it was cut.
template <std::size_t N>
void set_text_truncated(char (&field)[N], std::string_view value) noexcept {
  if (value.size() <= N - 1) {
    std::memcpy(field, value.data(), value.size());
    std::memset(field + value.size(), 0, N - value.size());
    return;
  }
  std::memcpy(field, value.data(), N - 4);
  std::memcpy(field + N - 4, "...", 4);
}

/// Any generated sequence type (dds_sequence_double, ...).
template <class Seq>
concept DdsSequence = requires(Seq s) {
  s._maximum;
  s._length;
  s._buffer;
  s._release;
};

template <DdsSequence Seq>
using SeqElement = std::remove_pointer_t<decltype(Seq::_buffer)>;

/// The elements of a sequence.
template <DdsSequence Seq>
std::span<const SeqElement<Seq>> view(const Seq& seq) noexcept {
  return {seq._buffer, seq._length};
}
template <DdsSequence Seq>
std::span<SeqElement<Seq>> view(Seq& seq) noexcept {
  return {seq._buffer, seq._length};
}

/// Copies `values` into `seq`, (re)allocating with dds_alloc when the
/// capacity is too small; the sequence then owns its buffer (_release), and
/// Sample<T> frees it. `bound` is the IDL bound: exceeding it throws
/// std::length_error naming `what` (Cyclone would refuse the write anyway).
/// For trivially copyable elements only (numbers, plain structs).
template <DdsSequence Seq>
void assign(Seq& seq, std::span<const SeqElement<Seq>> values, std::size_t bound, std::string_view what) {
  using E = SeqElement<Seq>;
  static_assert(std::is_trivially_copyable_v<E>);
  if (values.size() > bound) {
    throw std::length_error(std::string(what) + ": " + std::to_string(values.size()) +
                            " elements exceed the protocol bound of " + std::to_string(bound));
  }
  const auto n = static_cast<std::uint32_t>(values.size());
  if (seq._buffer == nullptr || !seq._release || seq._maximum < n) {
    if (seq._release && seq._buffer != nullptr) dds_free(seq._buffer);
    seq._buffer = n > 0 ? static_cast<E*>(dds_alloc(n * sizeof(E))) : nullptr;
    seq._maximum = n;
    seq._release = n > 0;
  }
  if (n > 0) std::memcpy(seq._buffer, values.data(), n * sizeof(E));
  seq._length = n;
}

/// Points `seq` at caller-owned memory without copying (zero-copy writes of
/// large chunks). The caller keeps `values` alive until the write returned;
/// the sequence does not own it (_release = false), so Sample<T> leaves it.
/// Any buffer the sequence owned before must have been freed by the caller.
template <DdsSequence Seq>
void borrow(Seq& seq, std::span<SeqElement<Seq>> values) noexcept {
  seq._buffer = values.data();
  seq._length = static_cast<std::uint32_t>(values.size());
  seq._maximum = seq._length;
  seq._release = false;
}

/// Wall-clock time (CLOCK_REALTIME) in ns since the epoch: the protocol's
/// *_ns stamps. Comparable across machines only after correcting by the
/// clock offset that Ping/Pong measure.
inline std::int64_t now_ns() noexcept { return dds_time(); }

/// One delay measurement from a pong and the ground's receive time t4.
struct DelaySample {
  std::int64_t rtt_ns = 0;     ///< (t4 - t1) - (t3 - t2): network time, remote processing excluded
  std::int64_t offset_ns = 0;  ///< remote clock - ground clock: ((t2 - t1) + (t3 - t4)) / 2
  bool valid = true;           ///< false: the stamps overflow (hostile or corrupt); the numbers are 0
  /// One-way delays assuming a symmetric path (rtt / 2 each way).
  double one_way_s() const noexcept { return static_cast<double>(rtt_ns) * 0.5e-9; }
};

/// NTP-style estimate (RFC 5905, on-wire protocol). Exact when the path is
/// symmetric; an asymmetry a shifts the offset by a/2. The stamps come from
/// the other side: stamps whose arithmetic would overflow (hostile or
/// corrupt) give valid = false instead of undefined behaviour.
inline DelaySample delay_from_pong(const msg::Pong& pong, std::int64_t ground_receive_ns) noexcept {
  const std::int64_t t1 = pong.ground_send_ns, t2 = pong.remote_receive_ns, t3 = pong.remote_send_ns,
                     t4 = ground_receive_ns;
  DelaySample s;
  std::int64_t there = 0, back = 0, processing = 0, remote_ahead = 0;
  bool overflow = __builtin_sub_overflow(t4, t1, &there);
  overflow |= __builtin_sub_overflow(t3, t2, &processing);
  overflow |= __builtin_sub_overflow(there, processing, &s.rtt_ns);
  overflow |= __builtin_sub_overflow(t2, t1, &remote_ahead);
  overflow |= __builtin_sub_overflow(t3, t4, &back);
  std::int64_t sum = 0;
  overflow |= __builtin_add_overflow(remote_ahead, back, &sum);
  if (overflow) return DelaySample{0, 0, false};
  s.offset_ns = sum / 2;
  return s;
}

// ---- enums in received samples ----
// A received sample is hostile until checked: its enum fields can hold any
// integer, and loading a value outside the enumerators as the enum type is
// undefined behaviour (the generated C enums have no fixed underlying type).
// Read them as raw integers, check them with enum_error() before anything
// else looks at the sample, and only then use them as enums. Real-time safe:
// noexcept, no allocation.

/// The raw integer stored in an enum field, read without loading the enum.
template <class E>
  requires std::is_enum_v<E>
std::uint32_t raw(const E& field) noexcept {
  static_assert(sizeof(E) <= sizeof(std::uint32_t));
  std::underlying_type_t<E> v{};
  std::memcpy(&v, &field, sizeof v);
  return static_cast<std::uint32_t>(v);
}

/// Stores `value` in an enum field without forming an enum value (to echo a
/// received raw value, e.g. an unknown command kind in its REJECTED ack).
template <class E>
  requires std::is_enum_v<E>
void set_raw(E& field, std::uint32_t value) noexcept {
  const auto v = static_cast<std::underlying_type_t<E>>(value);
  std::memcpy(&field, &v, sizeof v);
}

/// The first enum field of a received sample whose raw value is not one of
/// its enumerators ("unknown kind 42", "abort.category 7 is unknown"),
/// nullptr when all are valid. Written into `buf` (64 bytes are enough).
const char* enum_error(const msg::Command& sample, char* buf, std::size_t size) noexcept;
const char* enum_error(const msg::CommandAck& sample, char* buf, std::size_t size) noexcept;
const char* enum_error(const msg::TrajectoryStatus& sample, char* buf, std::size_t size) noexcept;
const char* enum_error(const msg::ToolState& sample, char* buf, std::size_t size) noexcept;
const char* enum_error(const msg::ControllerStatus& sample, char* buf, std::size_t size) noexcept;
const char* enum_error(const msg::Heartbeat& sample, char* buf, std::size_t size) noexcept;

// ---- numbers in received samples ----
// The other side is not trusted either way: a JointState is used only when
// its sequences describe one arm (same length) of finite numbers.

/// Why a received JointState was dropped (the ground counts each).
enum class JointStateDefect : std::uint8_t {
  None = 0,
  JointCount,  ///< q_rad empty, or not the expected joint count
  Length,      ///< dq_rad_s or torque_nm not as long as q_rad
  NotFinite,   ///< a NaN or an infinity in q_rad, dq_rad_s or torque_nm
};
inline constexpr std::size_t kJointStateDefects = 4;

/// Checks a received JointState: q_rad not empty and, when `expected_joints`
/// is not 0, of that length; dq_rad_s and torque_nm as long as q_rad; every
/// value finite. Returns nullptr when it may be used, else the reason
/// ("dq_rad_s has 6 values for 7 joints", "dq_rad_s[2] is not finite"),
/// written into `buf` (96 bytes are enough), with `defect` set to its kind.
/// Real-time safe: noexcept, no allocation.
const char* joint_state_error(const msg::JointState& sample, std::size_t expected_joints, JointStateDefect& defect,
                              char* buf, std::size_t size) noexcept;
const char* to_string(JointStateDefect defect) noexcept;  ///< "joint_count", "length", "not_finite", "none"

// Names of the command enums: the plain types' to_string (command.hpp), one
// table for both sides; the wire value converts with a static_cast.
/// The CiA 402 state name in snake case ("operation_enabled", "unknown"), as
/// `foresight status --json` prints it.
const char* drive_state_name(msg::DriveState state) noexcept;

}  // namespace foresight::protocol
