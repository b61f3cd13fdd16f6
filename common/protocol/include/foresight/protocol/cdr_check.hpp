#pragma once
// Does a received serialized sample hold every member it claims, before
// Cyclone DDS builds the C struct from it?
//
// Why: Cyclone DDS 0.10.2 (Debian) checks only 4 bytes for every 8-byte
// value in XCDR2 (dds_stream_normalize: check_align_prim{,_many} with the
// 4-byte alignment as the element size), so a sample whose last double, or
// whose sequence or array of doubles, is longer than the bytes it carries
// (up to twice: a sequence of n doubles passes with 4n bytes left) passes the
// receive-side normalize, and dds_stream_read (take) then memcpy()s past the
// heap buffer: any participant could make the remote or the ground read past
// a buffer (fuzz/regressions/fuzz_dds_samples/*_overread_in_cyclone_read).
// Once an offset has run past the end, Cyclone's later checks (strings:
// `size - off`) are unreliable too.
//
// What: for every topic type, a walk of its CDR layout as idlc lays it out
// (XCDR1: natural alignment up to 8; XCDR2: alignment up to 4, a DHEADER
// before every appendable struct and every sequence of non-primitive
// elements) that checks every member, every sequence and string length (and
// bound, and a string's terminator) against the bytes left, the way Cyclone's
// normalize should. Appendable members absent at the end of a DHEADER are
// accepted as Cyclone does (an older sender), except Command's payload union
// (Cyclone abort()s on an absent union: see messages.hpp min_dheader).
// Reader<T> (dds.hpp) drops and counts a sample that fails; the fuzzer
// (fuzz/fuzz_dds_samples.cpp) applies the same check.
//
// Adding a member to a type in idl/foresight_msgs.idl is one line in its
// walk (src/cdr_check.cpp); test_cdr_check round-trips Cyclone-written
// samples of every type through it, so a walk that lags the IDL fails there.
//
// Not real-time (Reader's take path); noexcept, no allocation.

#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <type_traits>

#include "foresight/protocol/messages.hpp"
#include "ros2_msgs.h"

namespace foresight::protocol {

/// The serialized members of one sample: the bytes after the 4-byte
/// encapsulation header, less the padding its options name.
struct CdrPayload {
  std::span<const unsigned char> bytes;
  bool little_endian = true;
  bool xcdr2 = false;
};

/// Splits a whole serialized sample (encapsulation header first) as Cyclone's
/// serdata_default does (padding = options & 2); nullopt when the header is
/// missing or names an encoding Cyclone does not read (parameter lists).
std::optional<CdrPayload> cdr_payload(std::span<const unsigned char> serialized) noexcept;

bool cdr_fits(std::type_identity<msg::Command>, const CdrPayload& p) noexcept;
bool cdr_fits(std::type_identity<msg::CommandAck>, const CdrPayload& p) noexcept;
bool cdr_fits(std::type_identity<msg::TrajectoryChunk>, const CdrPayload& p) noexcept;
bool cdr_fits(std::type_identity<msg::TrajectoryStatus>, const CdrPayload& p) noexcept;
bool cdr_fits(std::type_identity<msg::JointState>, const CdrPayload& p) noexcept;
bool cdr_fits(std::type_identity<msg::Wrench>, const CdrPayload& p) noexcept;
bool cdr_fits(std::type_identity<msg::ToolState>, const CdrPayload& p) noexcept;
bool cdr_fits(std::type_identity<msg::ControllerStatus>, const CdrPayload& p) noexcept;
bool cdr_fits(std::type_identity<msg::Heartbeat>, const CdrPayload& p) noexcept;
bool cdr_fits(std::type_identity<msg::Ping>, const CdrPayload& p) noexcept;
bool cdr_fits(std::type_identity<msg::Pong>, const CdrPayload& p) noexcept;
bool cdr_fits(std::type_identity<sensor_msgs_msg_dds__JointState_>, const CdrPayload& p) noexcept;
bool cdr_fits(std::type_identity<geometry_msgs_msg_dds__WrenchStamped_>, const CdrPayload& p) noexcept;

/// True when `p` holds a complete sample of T: every member inside the bytes
/// (and inside its DHEADER), every length within its bound and the bytes
/// left, every string terminated. Exact for what Cyclone writes: a sample it
/// serialized is never refused (test_cdr_check).
template <class T>
bool cdr_fits(const CdrPayload& p) noexcept {
  return cdr_fits(std::type_identity<T>{}, p);
}

}  // namespace foresight::protocol
