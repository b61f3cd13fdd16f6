// foresight_protocol_peer: the far end for the protocol's loopback tests and
// benchmark. In its own process it
//   - echoes every message type: a sample read on topic X is written back
//     unchanged on "X/echo" (same type, same QoS), so the test can compare
//     every field after a real trip through serialization and the network;
//   - answers like a minimal remote: Ping -> Pong with its receive and send
//     times; Command -> RECEIVED, then QUEUED/EXECUTING/COMPLETED (final joint
//     angles = the GOTO_JOINT target or the trajectory's last sample) or
//     REJECTED with a reason; TrajectoryChunks -> assembled, verified
//     (content hash, permissive limits) -> TrajectoryStatus.
// It exits on SIGTERM/SIGINT, when its parent dies, or after --lifetime-s.
//
// Usage: foresight_protocol_peer --domain N [--lifetime-s S]

#include <signal.h>
#include <sys/prctl.h>

#include <atomic>
#include <csignal>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "foresight/protocol/codec.hpp"
#include "foresight/protocol/commands.hpp"
#include "foresight/protocol/dds.hpp"
#include "foresight/protocol/loopback.hpp"
#include "foresight/protocol/trajectory_upload.hpp"

namespace fp = foresight::protocol;
namespace msg = foresight::protocol::msg;

namespace {

std::atomic<bool> g_stop{false};
void on_signal(int) { g_stop = true; }

struct Pump {
  virtual ~Pump() = default;
  virtual void attach(fp::WaitSet& waitset) = 0;
  virtual void pump() = 0;
};

/// Reads T on `topic` and writes every sample back on "topic/echo".
template <fp::Message T>
struct Echo : Pump {
  Echo(const fp::Participant& p, const char* topic)
      : reader(p, topic), writer(p, std::string(topic) + "/echo", fp::MessageTraits<T>::qos()) {}
  /// With the echo writer's own QoS (e.g. transient-local, so that echoes
  /// written before the test's reader matched this writer still reach it).
  Echo(const fp::Participant& p, const char* topic, const fp::Qos& echo_qos)
      : reader(p, topic), writer(p, std::string(topic) + "/echo", echo_qos) {}
  void attach(fp::WaitSet& waitset) override { waitset.attach(reader); }
  void pump() override {
    while (reader.take(sample)) writer.write(sample);
  }
  fp::Reader<T> reader;
  fp::Writer<T> writer;
  fp::Sample<T> sample;
};

struct Committed {
  foresight::TrajectoryHash hash{};
  std::vector<double> last_q;
};

class MiniRemote {
 public:
  explicit MiniRemote(const fp::Participant& p)
      : ping_(p, fp::topics::kPing, fp::qos::ping()),
        pong_(p),
        command_(p, fp::topics::kCommand, fp::qos::command()),
        ack_(p),
        chunk_(p, fp::topics::kTrajectoryChunk, fp::qos::trajectory_chunk()),
        status_(p) {}

  void attach(fp::WaitSet& waitset) {
    waitset.attach(ping_.reader);
    waitset.attach(command_.reader);
    waitset.attach(chunk_.reader);
  }

  void pump() {
    // The echo readers and these readers are separate DataReaders on the same
    // topics: each gets its own copy of every sample.
    while (ping_.reader.take(ping_sample_)) {
      const std::int64_t received = fp::now_ns();
      fp::Sample<msg::Pong> pong;
      pong->ping_id = ping_sample_->ping_id;
      pong->ground_send_ns = ping_sample_->ground_send_ns;
      pong->remote_receive_ns = received;
      pong->remote_send_ns = fp::now_ns();
      pong_.write(pong);
    }
    while (chunk_.reader.take(chunk_sample_)) on_chunk(*chunk_sample_);
    while (command_.reader.take(command_sample_)) on_command(*command_sample_);
  }

 private:
  template <fp::Message T>
  struct In {
    In(const fp::Participant& p, const char* topic, const fp::Qos& qos) : reader(p, topic, qos) {}
    fp::Reader<T> reader;
  };

  void on_chunk(const msg::TrajectoryChunk& chunk) {
    const auto progress = assembler_.add(chunk);
    fp::Sample<msg::TrajectoryStatus> status;
    status->trajectory_id = chunk.trajectory_id;
    status->chunks_received = progress.chunks_received;
    status->chunk_count = progress.chunk_count;
    status->state = progress.state;
    status->code = progress.code;
    fp::set_text_truncated(status->reason, progress.reason);
    if (progress.whole()) {
      // "Arrived whole, now validating": ASSEMBLING with every chunk counted.
      status->state = foresight_msg_UPLOAD_ASSEMBLING;
      status->stamp_ns = fp::now_ns();
      status_.write(status);
      const auto assembled = assembler_.take(chunk.trajectory_id);
      foresight::TrajectoryLimits limits;
      limits.joints = assembled->trajectory.joints();
      limits.joint_limits.assign(static_cast<std::size_t>(limits.joints),
                                 foresight::JointLimits{-10.0, 10.0, 100.0, 1e6, 1000.0});
      const fp::UploadVerdict verdict = fp::verify(*assembled, limits);
      fp::set_hash(status->content_hash, verdict.computed_hash);
      if (verdict.ok()) {
        status->state = foresight_msg_UPLOAD_COMMITTED;
        Committed c;
        c.hash = verdict.computed_hash;
        const auto& q = assembled->trajectory.positions_rad;
        for (Eigen::Index j = 0; j < q.cols(); ++j) c.last_q.push_back(q(q.rows() - 1, j));
        committed_[chunk.trajectory_id] = std::move(c);
      } else {
        status->state = foresight_msg_UPLOAD_REJECTED;
        status->code = verdict.code;
        fp::set_text_truncated(status->reason, verdict.reason);
      }
    }
    status->stamp_ns = fp::now_ns();
    status_.write(status);
  }

  void ack(const msg::Command& command, msg::AckState state, msg::ReasonCode code = foresight_msg_REASON_NONE,
           const std::string& reason = {}, std::span<const double> final_q = {}) {
    fp::Sample<msg::CommandAck> a;
    fp::fill_ack(*a, command, state, code, reason, final_q);
    ack_.write(a);
  }

  void on_command(const msg::Command& c) {
    ack(c, foresight_msg_ACK_RECEIVED);
    const auto verdict = checker_.check(c, fp::now_ns());
    if (!verdict.ok()) {
      ack(c, foresight_msg_ACK_REJECTED, verdict.code, verdict.reason);
      return;
    }
    std::vector<double> final_q;
    switch (c.payload._d) {
      case foresight_msg_CMD_TRAJECTORY: {
        const auto& run = c.payload._u.trajectory;
        const auto it = committed_.find(run.trajectory_id);
        if (it == committed_.end()) {
          ack(c, foresight_msg_ACK_REJECTED, foresight_msg_REASON_UNKNOWN_TRAJECTORY,
              "trajectory " + std::to_string(run.trajectory_id) + " is not committed");
          return;
        }
        if (fp::get_hash(run.content_hash) != it->second.hash) {
          ack(c, foresight_msg_ACK_REJECTED, foresight_msg_REASON_HASH_MISMATCH,
              "command hash " + foresight::to_hex(fp::get_hash(run.content_hash)) + " differs from the upload's " +
                  foresight::to_hex(it->second.hash));
          return;
        }
        final_q = it->second.last_q;
        break;
      }
      case foresight_msg_CMD_GOTO_JOINT: {
        const auto q = fp::view(c.payload._u.goto_joint.q_rad);
        final_q.assign(q.begin(), q.end());
        break;
      }
      default:
        break;
    }
    ack(c, foresight_msg_ACK_QUEUED);
    ack(c, foresight_msg_ACK_EXECUTING);
    ack(c, foresight_msg_ACK_COMPLETED, foresight_msg_REASON_NONE, {}, final_q);
  }

  In<msg::Ping> ping_;
  fp::Writer<msg::Pong> pong_;
  In<msg::Command> command_;
  fp::Writer<msg::CommandAck> ack_;
  In<msg::TrajectoryChunk> chunk_;
  fp::Writer<msg::TrajectoryStatus> status_;
  fp::Sample<msg::Ping> ping_sample_;
  fp::Sample<msg::Command> command_sample_;
  fp::Sample<msg::TrajectoryChunk> chunk_sample_;
  fp::TrajectoryAssembler assembler_;
  std::map<std::uint64_t, Committed> committed_;
  fp::CommandChecker checker_;
};

int usage(const char* why) {
  std::fprintf(stderr, "foresight_protocol_peer: %s\nusage: foresight_protocol_peer --domain N [--lifetime-s S]\n",
               why);
  return 2;
}

}  // namespace

int main(int argc, char** argv) {
  long domain = -1;
  double lifetime_s = 120.0;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    if (i + 1 >= argc) return usage(("missing value after " + arg).c_str());
    char* end = nullptr;
    if (arg == "--domain") {
      domain = std::strtol(argv[++i], &end, 10);
      if (*end != '\0' || domain < 0 || domain > 232) return usage("--domain wants an integer in 0..232");
    } else if (arg == "--lifetime-s") {
      lifetime_s = std::strtod(argv[++i], &end);
      if (*end != '\0' || !(lifetime_s > 0.0)) return usage("--lifetime-s wants a positive number");
    } else {
      return usage(("unknown argument " + arg).c_str());
    }
  }
  if (domain < 0) return usage("--domain is required");
  prctl(PR_SET_PDEATHSIG, SIGTERM);  // never outlive the test that started us
  std::signal(SIGTERM, on_signal);
  std::signal(SIGINT, on_signal);

  try {
    fp::use_loopback_if_unconfigured();
    fp::Participant participant(static_cast<dds_domainid_t>(domain));
    std::vector<std::unique_ptr<Pump>> echoes;
    echoes.push_back(std::make_unique<Echo<msg::Command>>(participant, fp::topics::kCommand));
    echoes.push_back(std::make_unique<Echo<msg::CommandAck>>(participant, fp::topics::kCommandAck));
    // The upload test cannot re-send (round_trip does): the chunk echoes are
    // kept (transient-local) for a reader that matches this writer late. The
    // last 64 only: keep-all would hold every echo of a benchmark run in the
    // writer's history until Cyclone blocks the writer.
    echoes.push_back(std::make_unique<Echo<msg::TrajectoryChunk>>(
        participant, fp::topics::kTrajectoryChunk, fp::qos::trajectory_chunk().transient_local().keep_last(64)));
    echoes.push_back(std::make_unique<Echo<msg::TrajectoryStatus>>(participant, fp::topics::kTrajectoryStatus));
    echoes.push_back(std::make_unique<Echo<msg::JointState>>(participant, fp::topics::kJointState));
    echoes.push_back(std::make_unique<Echo<msg::Wrench>>(participant, fp::topics::kWrench));
    echoes.push_back(std::make_unique<Echo<msg::ToolState>>(participant, fp::topics::kToolState));
    echoes.push_back(std::make_unique<Echo<msg::ControllerStatus>>(participant, fp::topics::kControllerStatus));
    echoes.push_back(std::make_unique<Echo<msg::Heartbeat>>(participant, fp::topics::kHeartbeat));
    echoes.push_back(std::make_unique<Echo<msg::Ping>>(participant, fp::topics::kPing));
    echoes.push_back(std::make_unique<Echo<msg::Pong>>(participant, fp::topics::kPong));
    MiniRemote remote(participant);

    fp::WaitSet waitset(participant);
    for (auto& e : echoes) e->attach(waitset);
    remote.attach(waitset);

    const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(lifetime_s);
    while (!g_stop && std::chrono::steady_clock::now() < end) {
      waitset.wait(std::chrono::milliseconds(100));
      remote.pump();  // pongs first: they are timed
      for (auto& e : echoes) e->pump();
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "foresight_protocol_peer: %s\n", e.what());
    return 1;
  }
  return 0;
}
