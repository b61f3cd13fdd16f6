// Every received DDS sample, from its CDR bytes on: Cyclone's own receive
// path (dds_stream_normalize_data checks the serialized form, then
// dds_stream_read builds the C struct, as serdata_default does for a sample
// from the wire), then what our code does with it:
//   remote: Command -> CommandChecker (envelope, per session) -> check_payload
//           -> from_wire; TrajectoryChunk -> TrajectoryAssembler -> verify
//           against the arm's limits (config/robot.urdf);
//   ground: CommandAck, TrajectoryStatus, JointState, Wrench, ToolState,
//           ControllerStatus -> from_wire / the names of their enums; Pong ->
//           delay_from_pong.
// A hostile participant controls all of these bytes, the encoding (XCDR1/2)
// and the byte order.
//
// Input: [type][encoding] then up to 8 samples of that type, each
// [length: u16 little endian][CDR bytes], fed in order to one checker /
// assembler (sequence numbers, replays and multi-chunk uploads span them).
// encoding bit 0: byte-swapped; bit 1: XCDR2.
//
// FORESIGHT_FUZZ_WRITE_SEEDS=DIR: write well-formed samples of every type
// there (serialized by Cyclone) and exit; scripts/fuzz.sh seeds the corpus so.
#include <dds/dds.h>
#include <dds/ddsi/ddsi_cdrstream.h>

#include <cstring>
#include <fstream>
#include <vector>

#include "foresight/common/robot_model.hpp"
#include "foresight/common/trajectory.hpp"
#include "foresight/protocol/cdr_check.hpp"
#include "foresight/protocol/codec.hpp"
#include "foresight/protocol/commands.hpp"
#include "foresight/protocol/dds.hpp"
#include "foresight/protocol/messages.hpp"
#include "foresight/protocol/trajectory_upload.hpp"
#include "foresight/protocol/convert.hpp"
#include "fuzz_support.hpp"

namespace {
namespace msg = foresight::protocol::msg;
using foresight::protocol::MessageTraits;
using foresight::protocol::Sample;

constexpr std::uint32_t kMaxSample = 1u << 16;

/// FORESIGHT_FUZZ_KNOWN=1 lets the known third-party crashes below through
/// (to reproduce Cyclone's own defects with fuzz/regressions/fuzz_dds_samples/*).
bool let_known_crashes_through() {
  static const bool on = [] {
    const char* v = std::getenv("FORESIGHT_FUZZ_KNOWN");
    return v != nullptr && v[0] == '1';
  }();
  return on;
}

/// Normalizes and reads one sample; false when Cyclone would drop it.
template <class T>
bool decode(const std::uint8_t* bytes, std::size_t n, std::uint8_t encoding, Sample<T>& out) {
  if (n > kMaxSample) return false;
  const std::uint32_t* ops = MessageTraits<T>::descriptor()->m_ops;
  // What serdata_default accepts: the encoding format must be the type's, so
  // an appendable type arrives only as XCDR2 (D_CDR2, with DHEADERs); a
  // final type as XCDR1 (CDR) or XCDR2 (CDR2).
  enum ddsi_sertype_extensibility ext = DDSI_SERTYPE_EXT_FINAL;
  if (!dds_stream_extensibility(ops, &ext)) return false;
  const std::uint32_t xcdr = (encoding & 2) || ext != DDSI_SERTYPE_EXT_FINAL ? 2 : 1;  // CDR_ENC_VERSION_1 / _2
  // Cyclone DDS 0.10.2 accepts samples it then cannot read safely: a Command
  // whose DHEADER ends before the payload union (dds_stream_read abort()s),
  // and in XCDR2 any 8-byte value, or sequence or array of them, longer than
  // the bytes left (normalize checks 4 bytes per double; dds_stream_read then
  // reads past the buffer: regressions *_overread_in_cyclone_read). What
  // Reader<T> does about it (protocol/dds.hpp take_checked: cdr_check.hpp's
  // layout walk, and min_dheader) is done here too, before Cyclone sees the
  // bytes. FORESIGHT_FUZZ_KNOWN=1 skips it (to show Cyclone's own defects).
  if (!let_known_crashes_through()) {
    const foresight::protocol::CdrPayload payload{{bytes, n}, (encoding & 1) == 0, xcdr == 2};
    if (!foresight::protocol::cdr_fits<T>(payload)) return false;
    if constexpr (std::is_same_v<T, msg::Command>) {
      std::uint32_t dheader = 0;
      if (n >= 4) std::memcpy(&dheader, bytes, 4);
      if (encoding & 1) dheader = __builtin_bswap32(dheader);
      if (dheader < MessageTraits<msg::Command>::min_dheader) return false;
    }
  }
  const bool bswap = (encoding & 1) != 0;
  // The receive path hands the normalizer a writable, 8-aligned copy.
  std::vector<std::uint64_t> buf((n + 7) / 8 + 1);
  std::memcpy(buf.data(), bytes, n);
  std::uint32_t off = 0;
  if (dds_stream_normalize_data(reinterpret_cast<char*>(buf.data()), &off, static_cast<std::uint32_t>(n), bswap,
                                xcdr, ops) == nullptr)
    return false;
  dds_istream_t is;
  dds_istream_init(&is, static_cast<std::uint32_t>(n), buf.data(), xcdr);
  out.clear();
  dds_stream_read(&is, reinterpret_cast<char*>(out.get()), ops);
  dds_istream_fini(&is);
  return true;
}

const foresight::TrajectoryLimits& limits() {
  static const foresight::TrajectoryLimits l =
      foresight::TrajectoryLimits::from_model(foresight::RobotModel::from_file(FORESIGHT_CONFIG_DIR "/robot.urdf"));
  return l;
}

struct Remote {
  foresight::protocol::CommandChecker checker;
  foresight::protocol::TrajectoryAssembler assembler;
  void on(const msg::Command& c) {
    const std::int64_t now = foresight::protocol::now_ns();
    (void)foresight::protocol::envelope_of(c, now);
    const auto verdict = checker.check(c, now, 0);
    if (!verdict.ok()) return;
    foresight::protocol::PayloadLimits pl;
    pl.joints = limits().joints;
    const auto payload = foresight::protocol::check_payload(c, pl);
    if (payload.ok()) (void)foresight::protocol::from_wire(c, now);
  }
  void on(const msg::TrajectoryChunk& chunk) {
    const auto progress = assembler.add(chunk);
    if (progress.whole()) {
      auto assembled = assembler.take(chunk.trajectory_id);
      if (assembled) (void)foresight::protocol::verify(*assembled, limits());
    }
  }
};

template <class T>
void run(const std::uint8_t* data, std::size_t size, std::uint8_t encoding) {
  Remote remote;
  Sample<T> s;
  for (int k = 0; k < 8 && size >= 2; ++k) {
    std::size_t n = data[0] | (static_cast<std::size_t>(data[1]) << 8);
    data += 2;
    size -= 2;
    if (n > size) n = size;
    const bool ok = decode<T>(data, n, encoding, s);
    data += n;
    size -= n;
    if (!ok) continue;
    foresight::fuzz::expect_input_errors([&] {
      const T& v = *s;
      if constexpr (std::is_same_v<T, msg::Command> || std::is_same_v<T, msg::TrajectoryChunk>) {
        remote.on(v);
      } else if constexpr (std::is_same_v<T, msg::CommandAck>) {
        (void)foresight::protocol::from_wire(v);
      } else if constexpr (std::is_same_v<T, msg::TrajectoryStatus>) {
        (void)foresight::protocol::to_string(static_cast<foresight::protocol::UploadState>(v.state));
        (void)foresight::protocol::to_string(static_cast<foresight::protocol::Reason>(v.code));
        (void)foresight::protocol::get_hash(v.content_hash);
        (void)std::string(foresight::protocol::text(v.reason));
      } else if constexpr (std::is_same_v<T, msg::Pong>) {
        // Hostile stamps: delay_from_pong reports overflow as valid = false
        // (it was signed-overflow UB; fuzz/regressions/fuzz_dds_samples/).
        const auto d = foresight::protocol::delay_from_pong(v, foresight::protocol::now_ns());
        if (!d.valid && (d.rtt_ns != 0 || d.offset_ns != 0)) __builtin_trap();
      } else if constexpr (std::is_same_v<T, msg::Heartbeat> || std::is_same_v<T, msg::Ping>) {
        (void)v;
      } else {
        (void)foresight::protocol::from_wire(v);
      }
    });
  }
}

// ---- seeds -------------------------------------------------------------------
template <class T>
void write_seed(const std::string& dir, int type, const char* name, const T& value) {
  for (std::uint32_t xcdr : {1u, 2u}) {
    dds_ostream_t os;
    dds_ostream_init(&os, 0, xcdr);
    dds_stream_write(&os, reinterpret_cast<const char*>(&value), MessageTraits<T>::descriptor()->m_ops);
    std::ofstream out(dir + "/" + name + (xcdr == 2 ? "_xcdr2" : "_xcdr1"), std::ios::binary);
    const unsigned char head[4] = {static_cast<unsigned char>(type), static_cast<unsigned char>(xcdr == 2 ? 2 : 0),
                                   static_cast<unsigned char>(os.m_index & 0xff),
                                   static_cast<unsigned char>(os.m_index >> 8)};
    out.write(reinterpret_cast<const char*>(head), 4);
    out.write(reinterpret_cast<const char*>(os.m_buffer), os.m_index);
    dds_ostream_fini(&os);
  }
}

void write_seeds(const std::string& dir) {
  foresight::protocol::CommandSequencer seq(42);
  {
    auto c = seq.next(foresight_msg_CMD_GOTO_JOINT, 10.0);
    const double q[7] = {0.1, -0.2, 0.3, -0.4, 0.5, -0.6, 0.7};
    foresight::protocol::assign(c->payload._u.goto_joint.q_rad, std::span<const double>(q, 7), msg::kMaxJoints, "q");
    c->payload._u.goto_joint.speed_fraction = 0.5;
    write_seed(dir, 0, "command_goto_joint", *c);
  }
  {
    auto c = seq.next(foresight_msg_CMD_GOTO_CART, 10.0);
    foresight::protocol::set_text(c->payload._u.goto_cart.frame, "lst_tip", "frame");
    c->payload._u.goto_cart.position_m[0] = 0.6;
    c->payload._u.goto_cart.orientation_xyzw[3] = 1.0;
    c->payload._u.goto_cart.speed_fraction = 0.2;
    write_seed(dir, 0, "command_goto_cart", *c);
  }
  {
    auto c = seq.next(foresight_msg_CMD_INVOKE_ALGORITHM, 10.0);
    foresight::protocol::set_text(c->payload._u.algorithm.name, "insert", "name");
    msg::NamedValue p[2]{};
    foresight::protocol::set_text(p[0].name, "depth_m", "n");
    p[0].value = 0.06;
    foresight::protocol::set_text(p[1].name, "max_force_n", "n");
    p[1].value = 120;
    foresight::protocol::assign(c->payload._u.algorithm.params, std::span<const msg::NamedValue>(p, 2), msg::kMaxParams,
                                "params");
    c->payload._u.algorithm.timeout_s = 30;
    write_seed(dir, 0, "command_invoke", *c);
  }
  {
    auto c = seq.next(foresight_msg_CMD_ABORT, 10.0);
    c->payload._u.abort.category = foresight_msg_STOP_CAT2;
    foresight::protocol::set_text(c->payload._u.abort.reason, "operator", "reason");
    write_seed(dir, 0, "command_abort", *c);
  }
  {
    auto c = seq.next(foresight_msg_CMD_TRAJECTORY, 10.0);
    c->payload._u.trajectory.trajectory_id = 7;
    c->payload._u.trajectory.start_tolerance_rad = 0.01;
    write_seed(dir, 0, "command_trajectory", *c);
  }
  {
    foresight::Trajectory t;
    t.time_s = {0.0, 0.1, 0.2};
    t.positions_rad = Eigen::MatrixXd::Zero(3, 7);
    t.positions_rad(1, 0) = 0.001;
    t.positions_rad(2, 0) = 0.002;
    auto chunks = foresight::protocol::make_chunks(t, 7, 42, 2);
    for (std::size_t i = 0; i < chunks.size(); ++i)
      write_seed(dir, 1, ("chunk_" + std::to_string(i)).c_str(), *chunks[i]);
  }
  {
    Sample<msg::CommandAck> a;
    a->state = foresight_msg_ACK_COMPLETED;
    const double q[7] = {0, 0, 0, 0, 0, 0, 0};
    foresight::protocol::assign(a->final_q_rad, std::span<const double>(q, 7), msg::kMaxJoints, "q");
    write_seed(dir, 2, "ack", *a);
  }
  {
    Sample<msg::TrajectoryStatus> s;
    foresight::protocol::set_text(s->reason, "validation failed", "reason");
    write_seed(dir, 3, "trajectory_status", *s);
  }
  {
    Sample<msg::JointState> j;
    const double q[7] = {0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7};
    foresight::protocol::assign(j->q_rad, std::span<const double>(q, 7), msg::kMaxJoints, "q");
    foresight::protocol::assign(j->dq_rad_s, std::span<const double>(q, 7), msg::kMaxJoints, "dq");
    foresight::protocol::assign(j->torque_nm, std::span<const double>(q, 7), msg::kMaxJoints, "t");
    write_seed(dir, 4, "joint_state", *j);
  }
  write_seed(dir, 5, "wrench", *Sample<msg::Wrench>());
  write_seed(dir, 6, "tool_state", *Sample<msg::ToolState>());
  {
    Sample<msg::ControllerStatus> s;
    foresight::protocol::set_text(s->stop_reason, "E-stop", "r");
    write_seed(dir, 7, "controller_status", *s);
  }
  write_seed(dir, 8, "pong", *Sample<msg::Pong>());
  write_seed(dir, 9, "heartbeat", *Sample<msg::Heartbeat>());
}
}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  if (const char* dir = std::getenv("FORESIGHT_FUZZ_WRITE_SEEDS")) {
    write_seeds(dir);
    std::exit(0);
  }
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 2) return 0;
  const std::uint8_t type = data[0], encoding = data[1];
  data += 2;
  size -= 2;
  switch (type % 11) {
    case 0: run<msg::Command>(data, size, encoding); break;
    case 1: run<msg::TrajectoryChunk>(data, size, encoding); break;
    case 2: run<msg::CommandAck>(data, size, encoding); break;
    case 3: run<msg::TrajectoryStatus>(data, size, encoding); break;
    case 4: run<msg::JointState>(data, size, encoding); break;
    case 5: run<msg::Wrench>(data, size, encoding); break;
    case 6: run<msg::ToolState>(data, size, encoding); break;
    case 7: run<msg::ControllerStatus>(data, size, encoding); break;
    case 8: run<msg::Pong>(data, size, encoding); break;
    case 9: run<msg::Heartbeat>(data, size, encoding); break;
    default: run<msg::Ping>(data, size, encoding); break;
  }
  return 0;
}
