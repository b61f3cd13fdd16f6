// The CDR layout walks of every topic type (cdr_check.hpp says why).
#include "foresight/protocol/cdr_check.hpp"

#include <algorithm>

namespace foresight::protocol {
namespace {

/// Walks serialized members in order. Every call checks that what it reads
/// lies inside the current region (the payload, or the innermost DHEADER);
/// the first failure sticks (ok() false) and later calls do nothing.
/// Offsets are from the start of the payload, as Cyclone aligns them.
class Walk {
 public:
  explicit Walk(const CdrPayload& p) noexcept
      : bytes_(p.bytes), little_(p.little_endian), xcdr2_(p.xcdr2), end_(p.bytes.size()) {}

  bool ok() const noexcept { return ok_; }
  bool xcdr2() const noexcept { return xcdr2_; }

  /// `count` primitives of `size` bytes (1, 2, 4, 8): a scalar, an enum
  /// (its bit_bound's size), a boolean or a fixed array.
  void prim(std::size_t size, std::size_t count = 1) noexcept {
    if (present()) take(size, count);
  }
  /// A 1-byte value (a union's discriminator); 0 when it does not fit.
  std::uint8_t byte() noexcept {
    if (!present() || !take(1, 1)) return 0;
    return bytes_[off_ - 1];
  }
  /// string<bound> (bound 0: unbounded): length with its terminator, 1 ..
  /// bound + 1, within the bytes left, last byte 0 (what Cyclone checks).
  void string(std::uint32_t bound) noexcept {
    if (!present()) return;
    std::uint32_t n = 0;
    if (!u32(n)) return;
    if (n == 0 || (bound != 0 && n > bound + 1) || n > end_ - off_ || bytes_[off_ + n - 1] != 0) {
      ok_ = false;
      return;
    }
    off_ += n;
  }
  /// sequence<primitive of `size` bytes, bound> (bound 0: unbounded): no
  /// DHEADER in either encoding.
  void prim_seq(std::size_t size, std::uint32_t bound) noexcept {
    if (!present()) return;
    std::uint32_t n = 0;
    if (!u32(n)) return;
    if (bound != 0 && n > bound) {
      ok_ = false;
      return;
    }
    if (n != 0) take(size, n);
  }
  /// sequence<non-primitive, bound>: XCDR2 puts a DHEADER before the length
  /// and the elements must end exactly there; `element()` walks one.
  template <class F>
  void seq(std::uint32_t bound, F&& element) noexcept {
    if (!present()) return;
    Region outer = region_;
    if (xcdr2_ && !enter_dheader(false)) return;
    region_.appendable = false;  // elements are all there
    std::uint32_t n = 0;
    // Every element takes at least one byte: the loop is bounded by the bytes.
    if (u32(n) && ((bound != 0 && n > bound) || n > end_ - off_)) ok_ = false;
    for (std::uint32_t i = 0; ok_ && i < n; ++i) element();
    if (xcdr2_ && ok_ && off_ != end_) ok_ = false;
    leave(outer);
  }
  /// A nested @final struct or union member (no DHEADER): `members()` walks it.
  template <class F>
  void final_struct(F&& members, bool required = false) noexcept {
    if (!present(required)) return;
    Region outer = region_;
    region_.appendable = false;  // inside it, every member must be there
    members();
    region_ = outer;
  }
  /// An @appendable struct (the top level or nested): in XCDR2 a DHEADER
  /// bounds its members; trailing members it does not hold are absent (as
  /// Cyclone reads them: defaults), bytes after the known ones skipped.
  template <class F>
  void appendable(F&& members, bool required = false) noexcept {
    if (!present(required)) return;
    if (!xcdr2_) {  // XCDR1 (only a hostile sender): no DHEADER; all members
      final_struct(members, required);
      return;
    }
    Region outer = region_;
    if (!enter_dheader(true)) return;
    members();
    if (ok_) off_ = end_;
    leave(outer);
  }
  /// A member that must be there even at the end of a DHEADER (Command's
  /// payload: Cyclone aborts on an absent union).
  template <class F>
  void required(F&& member) noexcept {
    if (present(true)) final_struct(member);
  }

 private:
  struct Region {
    std::size_t end;
    bool appendable;
  };

  /// Whether the next member is in the data. Inside an appendable struct a
  /// member starting at or after its DHEADER's end is absent (not an error,
  /// unless `required`); elsewhere it must be there.
  bool present(bool required = false) noexcept {
    if (!ok_) return false;
    if (region_.appendable && off_ >= end_) {
      if (required) ok_ = false;
      return false;
    }
    return true;
  }
  bool align(std::size_t size) noexcept {
    const std::size_t a = xcdr2_ ? std::min<std::size_t>(size, 4) : size;
    const std::size_t aligned = (off_ + a - 1) / a * a;
    if (aligned > end_) return ok_ = false;
    off_ = aligned;
    return true;
  }
  bool take(std::size_t size, std::size_t count) noexcept {
    if (!ok_ || !align(size)) return false;
    // count <= 2^32 and size <= 8: no overflow in 64 bits.
    if (static_cast<std::uint64_t>(count) * size > end_ - off_) return ok_ = false;
    off_ += count * size;
    return true;
  }
  bool u32(std::uint32_t& v) noexcept {
    if (!take(4, 1)) return false;
    const unsigned char* b = bytes_.data() + off_ - 4;
    v = little_ ? b[0] | (b[1] << 8) | (b[2] << 16) | (static_cast<std::uint32_t>(b[3]) << 24)
                : b[3] | (b[2] << 8) | (b[1] << 16) | (static_cast<std::uint32_t>(b[0]) << 24);
    return true;
  }
  bool enter_dheader(bool appendable) noexcept {
    std::uint32_t size = 0;
    if (!u32(size)) return false;
    if (size > end_ - off_) return ok_ = false;
    region_ = Region{off_ + size, appendable};
    end_ = region_.end;
    return true;
  }
  void leave(const Region& outer) noexcept {
    region_ = outer;
    end_ = outer.end;
  }

  std::span<const unsigned char> bytes_;
  bool little_;
  bool xcdr2_;
  std::size_t off_ = 0;
  std::size_t end_;
  Region region_{end_, false};
  bool ok_ = true;
};

// Sizes of the IDL's types, as idlc lays them out.
constexpr std::size_t kI8 = 8;       // (unsigned) long long, double
constexpr std::size_t kI4 = 4;       // (unsigned) long
constexpr std::size_t kI2 = 2;       // unsigned short, @bit_bound(16) enum
constexpr std::size_t kEnum8 = 1;    // @bit_bound(8) enum
constexpr std::size_t kBool = 1;
constexpr std::size_t kSha256 = 32;  // octet[32]

void sha256(Walk& w) { w.prim(1, kSha256); }

// ---- Command and its payload (one line per member, in IDL order) ----------
void run_trajectory(Walk& w) {
  w.appendable([&] {
    w.prim(kI8);        // trajectory_id
    sha256(w);          // content_hash
    w.prim(kBool);      // compliant
    w.prim(kI8);        // start_tolerance_rad
    w.prim(kI8);        // upload_wait_s
  });
}
void named_value(Walk& w) {
  w.appendable([&] {
    w.string(foresight_msg_MAX_NAME);  // name
    w.prim(kI8);                       // value
  });
}
void invoke_algorithm(Walk& w) {
  w.appendable([&] {
    w.string(foresight_msg_MAX_NAME);                      // name
    w.seq(foresight_msg_MAX_PARAMS, [&] { named_value(w); });  // params
    w.prim(kI8);                                           // timeout_s
  });
}
void report_request(Walk& w) {
  w.appendable([&] { w.prim(kEnum8); });  // what
}
void camera_command(Walk& w) {
  w.appendable([&] {
    w.string(foresight_msg_MAX_NAME);  // camera
    w.prim(kEnum8);                    // action
    w.prim(kI8);                       // pan_rad
    w.prim(kI8);                       // tilt_rad
    w.prim(kI8);                       // focal_px
  });
}
void goto_joint(Walk& w) {
  w.appendable([&] {
    w.prim_seq(kI8, foresight_msg_MAX_JOINTS);  // q_rad
    w.prim(kI8);                                // speed_fraction
  });
}
void goto_cart(Walk& w) {
  w.appendable([&] {
    w.string(foresight_msg_MAX_NAME);  // frame
    w.prim(kI8, 3);                    // position_m
    w.prim(kI8, 4);                    // orientation_xyzw
    w.prim(kI8);                       // speed_fraction
  });
}
void abort_command(Walk& w) {
  w.appendable([&] {
    w.prim(kI8);                       // target_command_id
    w.prim(kEnum8);                    // category
    w.string(foresight_msg_MAX_TEXT);  // reason
  });
}
/// @final union CommandPayload switch (CommandKind): kinds without a case
/// (take/release control, recover, unknown values) carry nothing.
void command_payload(Walk& w) {
  switch (w.byte()) {
    case foresight_msg_CMD_TRAJECTORY: run_trajectory(w); break;
    case foresight_msg_CMD_INVOKE_ALGORITHM: invoke_algorithm(w); break;
    case foresight_msg_CMD_REQUEST: report_request(w); break;
    case foresight_msg_CMD_CAMERA: camera_command(w); break;
    case foresight_msg_CMD_GOTO_JOINT: goto_joint(w); break;
    case foresight_msg_CMD_GOTO_CART: goto_cart(w); break;
    case foresight_msg_CMD_ABORT: abort_command(w); break;
    default: break;
  }
}

// ---- ROS 2 types (idl/ros2_msgs.idl) ----------------------------------------
void ros2_header(Walk& w) {
  w.final_struct([&] {
    w.final_struct([&] {  // stamp (builtin_interfaces/Time)
      w.prim(kI4);        // sec
      w.prim(kI4);        // nanosec
    });
    w.string(0);  // frame_id
  });
}
void ros2_vector3(Walk& w) {
  w.final_struct([&] { w.prim(kI8, 3); });  // x, y, z
}

template <class F>
bool walk(const CdrPayload& p, F&& members) noexcept {
  Walk w(p);
  members(w);
  return w.ok();
}

}  // namespace

std::optional<CdrPayload> cdr_payload(std::span<const unsigned char> serialized) noexcept {
  if (serialized.size() < 4 || serialized[0] != 0) return std::nullopt;
  CdrPayload p;
  switch (serialized[1]) {
    case 0x00: case 0x01: p.xcdr2 = false; break;  // CDR_BE, CDR_LE
    case 0x06: case 0x07:                         // CDR2_BE, CDR2_LE
    case 0x08: case 0x09: p.xcdr2 = true; break;  // D_CDR2_BE, D_CDR2_LE
    default: return std::nullopt;                 // parameter lists: no type of ours
  }
  p.little_endian = (serialized[1] & 1) != 0;
  const std::size_t pad = serialized[3] & 2u;  // as serdata_default reads the options
  if (serialized.size() - 4 < pad) return std::nullopt;
  p.bytes = serialized.subspan(4, serialized.size() - 4 - pad);
  return p;
}

bool cdr_fits(std::type_identity<msg::Command>, const CdrPayload& p) noexcept {
  return walk(p, [](Walk& w) {
    w.appendable([&] {
      w.prim(kI2);  // protocol_version
      w.prim(kI8);  // session_id
      w.prim(kI8);  // sequence_number
      w.prim(kI8);  // command_id
      w.prim(kI8);  // issued_ns
      w.prim(kI8);  // expires_ns
      w.required([&] { command_payload(w); });  // payload
      w.prim(kI8);  // after_command_id (appended)
    });
  });
}

bool cdr_fits(std::type_identity<msg::CommandAck>, const CdrPayload& p) noexcept {
  return walk(p, [](Walk& w) {
    w.appendable([&] {
      w.prim(kI8);                                // session_id
      w.prim(kI8);                                // command_id
      w.prim(kI8);                                // sequence_number
      w.prim(kEnum8);                             // kind
      w.prim(kEnum8);                             // state
      w.prim(kI2);                                // code
      w.string(foresight_msg_MAX_TEXT);           // reason
      w.prim(kI8);                                // stamp_ns
      w.prim_seq(kI8, foresight_msg_MAX_JOINTS);  // final_q_rad
    });
  });
}

bool cdr_fits(std::type_identity<msg::TrajectoryChunk>, const CdrPayload& p) noexcept {
  return walk(p, [](Walk& w) {
    w.appendable([&] {
      w.prim(kI8);                                      // trajectory_id
      w.prim(kI8);                                      // session_id
      w.prim(kI4);                                      // chunk_index
      w.prim(kI4);                                      // chunk_count
      w.prim(kI4);                                      // joint_count
      w.prim(kI4);                                      // sample_count
      w.prim(kI4);                                      // first_sample
      sha256(w);                                        // content_hash
      w.prim(kI8);                                      // issued_ns
      w.prim_seq(kI8, foresight_msg_MAX_CHUNK_VALUES);  // samples
    });
  });
}

bool cdr_fits(std::type_identity<msg::TrajectoryStatus>, const CdrPayload& p) noexcept {
  return walk(p, [](Walk& w) {
    w.appendable([&] {
      w.prim(kI8);                       // trajectory_id
      w.prim(kEnum8);                    // state
      w.prim(kI4);                       // chunks_received
      w.prim(kI4);                       // chunk_count
      sha256(w);                         // content_hash
      w.prim(kI2);                       // code
      w.string(foresight_msg_MAX_TEXT);  // reason
      w.prim(kI8);                       // stamp_ns
    });
  });
}

bool cdr_fits(std::type_identity<msg::JointState>, const CdrPayload& p) noexcept {
  return walk(p, [](Walk& w) {
    w.prim(kI8);                                // stamp_ns
    w.prim(kI8);                                // cycle
    w.prim_seq(kI8, foresight_msg_MAX_JOINTS);  // q_rad
    w.prim_seq(kI8, foresight_msg_MAX_JOINTS);  // dq_rad_s
    w.prim_seq(kI8, foresight_msg_MAX_JOINTS);  // torque_nm
  });
}

bool cdr_fits(std::type_identity<msg::Wrench>, const CdrPayload& p) noexcept {
  return walk(p, [](Walk& w) {
    w.prim(kI8);     // stamp_ns
    w.prim(kI8, 3);  // force_tool_n
    w.prim(kI8, 3);  // torque_tool_nm
    w.prim(kBool);   // saturated
  });
}

bool cdr_fits(std::type_identity<msg::ToolState>, const CdrPayload& p) noexcept {
  return walk(p, [](Walk& w) {
    w.prim(kI8);     // stamp_ns
    w.prim(kBool);   // latched
    w.prim(kBool);   // running
    w.prim(kEnum8);  // direction
    w.prim(kI8);     // turns
    w.prim(kI8);     // torque_nm
    w.prim(kI4);     // fault_bits
  });
}

bool cdr_fits(std::type_identity<msg::ControllerStatus>, const CdrPayload& p) noexcept {
  return walk(p, [](Walk& w) {
    w.appendable([&] {
      w.prim(kI8);                       // stamp_ns
      w.prim(kEnum8);                    // mode
      w.prim(kI8);                       // active_command_id
      w.prim(kI8);                       // active_trajectory_id
      w.prim(kI8);                       // last_sequence
      w.prim(kEnum8);                    // stop_category
      w.string(foresight_msg_MAX_TEXT);  // stop_reason
      w.prim(kI4);                       // fault_bits
      w.string(foresight_msg_MAX_TEXT);  // fault_text
      w.seq(foresight_msg_MAX_JOINTS, [&] {  // drives
        w.prim(kI2);     // joint
        w.prim(1);       // node_id
        w.prim(kEnum8);  // state
        w.prim(kBool);   // powered
      });
      w.final_struct([&] {  // loop (LoopTiming)
        w.prim(kBool, 3);   // realtime, memory_locked, realtime_required
        w.prim(kI8, 2);     // cycles, overruns
        w.prim(kI4, 2);     // missed_streak_max, max_missed_cycles
        w.prim(kI8, 4);     // latency p99, max; compute p99, max
      });
      w.final_struct([&] {  // rate_limit (RateLimit)
        w.prim(kI8);        // cycles
        w.prim(kBool);      // limiting
        w.prim(kI4);        // last_joint_mask
        w.prim(kI8, 2);     // last_command_id, last_max_lag_rad
      });
      w.seq(foresight_msg_MAX_QUEUE, [&] {  // queue (QueuedCommand)
        w.prim(kI8);     // command_id
        w.prim(kEnum8);  // kind
        w.prim(kI8);     // after_command_id
        w.prim(kEnum8);  // state
      });
    });
  });
}

bool cdr_fits(std::type_identity<msg::Heartbeat>, const CdrPayload& p) noexcept {
  return walk(p, [](Walk& w) {
    w.prim(kEnum8);  // side
    w.prim(kI8);     // boot_id
    w.prim(kI8);     // counter
    w.prim(kI8);     // stamp_ns
  });
}

bool cdr_fits(std::type_identity<msg::Ping>, const CdrPayload& p) noexcept {
  return walk(p, [](Walk& w) {
    w.prim(kI8);  // ping_id
    w.prim(kI8);  // ground_send_ns
  });
}

bool cdr_fits(std::type_identity<msg::Pong>, const CdrPayload& p) noexcept {
  return walk(p, [](Walk& w) {
    w.prim(kI8);  // ping_id
    w.prim(kI8);  // ground_send_ns
    w.prim(kI8);  // remote_receive_ns
    w.prim(kI8);  // remote_send_ns
  });
}

bool cdr_fits(std::type_identity<sensor_msgs_msg_dds__JointState_>, const CdrPayload& p) noexcept {
  return walk(p, [](Walk& w) {
    ros2_header(w);                         // header
    w.seq(0, [&] { w.string(0); });         // name
    w.prim_seq(kI8, 0);                     // position
    w.prim_seq(kI8, 0);                     // velocity
    w.prim_seq(kI8, 0);                     // effort
  });
}

bool cdr_fits(std::type_identity<geometry_msgs_msg_dds__WrenchStamped_>, const CdrPayload& p) noexcept {
  return walk(p, [](Walk& w) {
    ros2_header(w);  // header
    w.final_struct([&] {
      ros2_vector3(w);  // wrench.force
      ros2_vector3(w);  // wrench.torque
    });
  });
}

}  // namespace foresight::protocol
