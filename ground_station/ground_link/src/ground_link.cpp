#include "foresight/ground_link/ground_link.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <atomic>
#include <condition_variable>
#include <deque>
#include <limits>
#include <map>
#include <mutex>
#include <set>
#include <stdexcept>
#include <thread>

#include "foresight/protocol/codec.hpp"
#include "foresight/protocol/commands.hpp"
#include "foresight/protocol/security.hpp"
#include "foresight/protocol/trajectory_upload.hpp"
#include "foresight/protocol/convert.hpp"

namespace foresight::ground_link {

namespace msg = protocol::msg;
using protocol::Reader;
using protocol::Sample;
using protocol::Writer;
using Clock = std::chrono::steady_clock;

namespace {

enum Token : dds_attach_t { kStop = 1, kAck, kUpload, kJoint, kWrench, kTool, kStatus, kHeartbeat };
constexpr int kTakeBatch = 64;
constexpr std::size_t kUploadHistory = 64;

std::chrono::nanoseconds seconds(double s) {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::duration<double>(s));
}

struct UploadSeen {
  protocol::UploadState state = protocol::UploadState::Assembling;
  std::uint32_t chunks_received = 0, chunk_count = 0;
  TrajectoryHash hash{};
  protocol::Reason code = protocol::Reason::None;
  std::string reason;
  Clock::time_point when{};
};

}  // namespace

struct GroundLink::Impl {
  explicit Impl(Config c)
      : config(std::move(c)),
        participant(protocol::make_participant(config.domain, config.security_dir, config.security_identity)),
        commands(config.read_only ? nullptr : std::make_unique<Writer<msg::Command>>(participant)),
        chunks(config.read_only ? nullptr : std::make_unique<Writer<msg::TrajectoryChunk>>(participant)),
        aborts(config.read_only ? std::make_unique<Writer<msg::Command>>(participant, protocol::topics::kAbort) : nullptr),
        heartbeat_out(participant),
        acks(participant),
        uploads(participant),
        joints(participant),
        wrenches(participant),
        tools(participant),
        statuses(participant),
        heartbeats(participant),
        stop_guard(participant),
        waitset(participant),
        delay(participant, config.delay),
        boot_id(protocol::random_id()) {
    waitset.attach(stop_guard, kStop);
    waitset.attach(acks, kAck);
    waitset.attach(uploads, kUpload);
    waitset.attach(joints, kJoint);
    waitset.attach(wrenches, kWrench);
    waitset.attach(tools, kTool);
    waitset.attach(statuses, kStatus);
    waitset.attach(heartbeats, kHeartbeat);
    // Round trips only from the remote: its participant once known (from its
    // other topics); before that, any pong (as any first writer there).
    delay.set_writer_check([this](const protocol::ParticipantGuid& writer) {
      std::lock_guard lock(mutex);
      return !remote_participant.known() || !writer.known() || writer == remote_participant;
    });
    thread = std::thread([this] { run(); });
  }

  void run() noexcept;
  void take_all();
  double age_s(std::int64_t stamp_ns) const {
    const std::int64_t remote_now_on_ground = stamp_ns - delay.clock_offset_ns();
    return static_cast<double>(protocol::now_ns() - remote_now_on_ground) * 1e-9;
  }

  Config config;
  protocol::Participant participant;
  std::mutex send_mutex;  // sequencer + command writer
  protocol::CommandSequencer sequencer;
  std::unique_ptr<Writer<msg::Command>> commands;  // null when read-only
  std::mutex chunk_mutex;
  std::unique_ptr<Writer<msg::TrajectoryChunk>> chunks;
  std::unique_ptr<Writer<msg::Command>> aborts;    // read-only only: topics::kAbort, ABORT and nothing else
  Writer<msg::Heartbeat> heartbeat_out;
  Reader<msg::CommandAck> acks;
  Reader<msg::TrajectoryStatus> uploads;
  Reader<msg::JointState> joints;
  Reader<msg::Wrench> wrenches;
  Reader<msg::ToolState> tools;
  Reader<msg::ControllerStatus> statuses;
  Reader<msg::Heartbeat> heartbeats;
  protocol::GuardCondition stop_guard;
  protocol::WaitSet waitset;
  DelayMonitor delay;
  const std::uint64_t boot_id;

  std::atomic<bool> stopping{false};
  std::atomic<bool> heartbeat_paused{false};

  mutable std::mutex mutex;
  std::condition_variable changed;
  std::map<std::uint64_t, std::vector<protocol::Ack>> ack_log;  // by command id (our session only)
  std::deque<std::uint64_t> ack_order;
  std::map<std::uint64_t, Clock::time_point> sent_at;
  std::map<std::uint64_t, UploadSeen> upload_log;
  std::deque<std::uint64_t> upload_order;
  std::optional<Timed<protocol::JointReport>> joint_state;
  DroppedSamples drops;
  std::optional<Timed<protocol::WrenchReport>> wrench;
  std::optional<Timed<protocol::ToolReport>> tool;
  std::optional<Timed<protocol::StatusReport>> status;
  std::optional<Clock::time_point> remote_heard;
  std::uint64_t remote_boot = 0;
  protocol::ParticipantGuid remote_participant;  // written by the link thread under `mutex`
  // Link thread only.
  Clock::time_point remote_participant_heard{};
  std::map<dds_instance_handle_t, protocol::ParticipantGuid> writers;  // publication handle -> participant
  std::set<protocol::ParticipantGuid> warned;
  /// Whether a sample `reader` took (`info`) comes from the remote (learning
  /// it from the first one, or after remote_loss_s of its silence); a foreign
  /// one is counted and warned about once per participant.
  bool from_remote(dds_entity_t reader, const dds_sample_info_t& info);
  // Link thread only: reused take buffers.
  Sample<msg::CommandAck> ack;
  Sample<msg::TrajectoryStatus> up;
  Sample<msg::JointState> js;
  Sample<msg::Wrench> wr;
  Sample<msg::ToolState> ts;
  Sample<msg::ControllerStatus> cs;
  Sample<msg::Heartbeat> hb;
  std::thread thread;
};

void GroundLink::Impl::run() noexcept {
  Sample<msg::Heartbeat> beat;
  beat->side = foresight_msg_SIDE_GROUND;
  beat->boot_id = boot_id;
  auto next_beat = Clock::now();
  const auto period = seconds(config.heartbeat_period_s);
  while (!stopping.load()) {
    try {
      const auto now = Clock::now();
      if (now >= next_beat) {
        if (!heartbeat_paused.load()) {
          ++beat->counter;
          beat->stamp_ns = protocol::now_ns();
          (void)heartbeat_out.try_write(*beat);
        }
        next_beat = now + period;
      }
      waitset.wait(std::max(std::chrono::nanoseconds(0),
                            std::chrono::duration_cast<std::chrono::nanoseconds>(next_beat - Clock::now())));
      take_all();
    } catch (const std::exception& e) {
      spdlog::error("ground link: {}", e.what());
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
  }
}

bool GroundLink::Impl::from_remote(dds_entity_t reader, const dds_sample_info_t& info) {
  auto it = writers.find(info.publication_handle);
  if (it == writers.end()) {
    if (writers.size() > 256) writers.clear();  // bounded: writers come and go
    it = writers.emplace(info.publication_handle, protocol::writer_participant(reader, info.publication_handle)).first;
  }
  const protocol::ParticipantGuid& writer = it->second;
  const auto now = Clock::now();
  const bool silent = now - remote_participant_heard > seconds(config.remote_loss_s);
  if (writer.known() && writer != remote_participant && (!remote_participant.known() || silent)) {
    if (remote_participant.known())
      spdlog::warn("ground link: the remote is now participant {} (the last one, {}, was silent for {:.1f} s)",
                   writer.hex(), remote_participant.hex(),
                   std::chrono::duration<double>(now - remote_participant_heard).count());
    std::lock_guard lock(mutex);
    remote_participant = writer;
  }
  if (writer == remote_participant || (!writer.known() && !remote_participant.known())) {
    remote_participant_heard = now;
    return true;
  }
  {
    std::lock_guard lock(mutex);
    ++drops.foreign;
  }
  if (warned.size() < 64 && warned.insert(writer).second)
    spdlog::warn("ground link: samples of participant {} on the remote's topics ignored: the remote is {} "
                 "(another process publishing as the remote)",
                 writer.hex(), remote_participant.hex());
  return false;
}

void GroundLink::Impl::take_all() {
  bool any = false;
  dds_sample_info_t info{};
  for (int i = 0; i < kTakeBatch && acks.take(ack, &info); ++i) {
    if (ack->session_id != sequencer.session_id()) continue;  // another ground station's command
    if (!from_remote(acks.get(), info)) continue;
    char why[96];
    if (const char* bad = protocol::enum_error(*ack, why, sizeof why)) {  // raw integers checked before any enum load
      spdlog::warn("ground link: ack of command {} ignored: {}", ack->command_id, bad);
      continue;
    }
    protocol::Ack a = protocol::from_wire(*ack);
    std::lock_guard lock(mutex);
    auto [it, fresh] = ack_log.try_emplace(a.command_id);
    if (fresh) {
      ack_order.push_back(a.command_id);
      while (ack_order.size() > std::max<std::size_t>(1, config.ack_history)) {
        ack_log.erase(ack_order.front());
        sent_at.erase(ack_order.front());
        ack_order.pop_front();
      }
    }
    it->second.push_back(std::move(a));
    any = true;
  }
  for (int i = 0; i < kTakeBatch && uploads.take(up, &info); ++i) {
    if (!from_remote(uploads.get(), info)) continue;
    char why[96];
    if (const char* bad = protocol::enum_error(*up, why, sizeof why)) {
      spdlog::warn("ground link: upload status of trajectory {} ignored: {}", up->trajectory_id, bad);
      continue;
    }
    UploadSeen seen;
    seen.state = static_cast<protocol::UploadState>(protocol::raw(up->state));
    seen.chunks_received = up->chunks_received;
    seen.chunk_count = up->chunk_count;
    seen.hash = protocol::get_hash(up->content_hash);
    seen.code = static_cast<protocol::Reason>(protocol::raw(up->code));
    seen.reason = std::string(protocol::text(up->reason));
    seen.when = Clock::now();
    std::lock_guard lock(mutex);
    auto [it, fresh] = upload_log.insert_or_assign(up->trajectory_id, std::move(seen));
    (void)it;
    if (fresh) {
      upload_order.push_back(up->trajectory_id);
      if (upload_order.size() > kUploadHistory) {
        upload_log.erase(upload_order.front());
        upload_order.pop_front();
      }
    }
    any = true;
  }
  const std::int64_t now = protocol::now_ns();
  for (int i = 0; i < kTakeBatch && joints.take(js, &info); ++i) {
    if (!from_remote(joints.get(), info)) continue;
    char why[96];
    protocol::JointStateDefect defect{};
    if (const char* bad = protocol::joint_state_error(*js, config.joints, defect, why, sizeof why)) {
      std::uint64_t seen = 0;
      {
        std::lock_guard lock(mutex);
        auto& n = defect == protocol::JointStateDefect::JointCount ? drops.joint_state_joint_count
                  : defect == protocol::JointStateDefect::Length   ? drops.joint_state_length
                                                                   : drops.joint_state_not_finite;
        seen = ++n;
      }
      if (seen == 1 || seen % 1000 == 0)  // the first of each reason, then every 1000th
        spdlog::warn("ground link: joint state of cycle {} dropped ({} so far for {}): {}", js->cycle, seen,
                     protocol::to_string(defect), bad);
      continue;
    }
    auto v = protocol::from_wire(*js);
    std::lock_guard lock(mutex);
    joint_state = Timed<protocol::JointReport>{std::move(v), now, 0.0};
    any = true;
  }
  for (int i = 0; i < kTakeBatch && wrenches.take(wr, &info); ++i) {
    if (!from_remote(wrenches.get(), info)) continue;
    std::lock_guard lock(mutex);
    wrench = Timed<protocol::WrenchReport>{protocol::from_wire(*wr), now, 0.0};
    any = true;
  }
  for (int i = 0; i < kTakeBatch && tools.take(ts, &info); ++i) {
    if (!from_remote(tools.get(), info)) continue;
    char why[96];
    if (const char* bad = protocol::enum_error(*ts, why, sizeof why)) {
      spdlog::warn("ground link: tool state ignored: {}", bad);
      continue;
    }
    std::lock_guard lock(mutex);
    tool = Timed<protocol::ToolReport>{protocol::from_wire(*ts), now, 0.0};
    any = true;
  }
  for (int i = 0; i < kTakeBatch && statuses.take(cs, &info); ++i) {
    if (!from_remote(statuses.get(), info)) continue;
    char why[96];
    if (const char* bad = protocol::enum_error(*cs, why, sizeof why)) {
      spdlog::warn("ground link: controller status ignored: {}", bad);
      continue;
    }
    auto v = protocol::from_wire(*cs);
    std::lock_guard lock(mutex);
    status = Timed<protocol::StatusReport>{std::move(v), now, 0.0};
    any = true;
  }
  for (int i = 0; i < kTakeBatch && heartbeats.take(hb, &info); ++i) {
    if (protocol::raw(hb->side) != foresight_msg_SIDE_REMOTE) continue;  // our own (or an invalid side)
    if (!from_remote(heartbeats.get(), info)) continue;
    std::lock_guard lock(mutex);
    remote_heard = Clock::now();
    remote_boot = hb->boot_id;
  }
  if (any) changed.notify_all();
}

GroundLink::GroundLink(Config config) {
  if (!(config.heartbeat_period_s > 0.0)) throw std::invalid_argument("GroundLink: heartbeat_period_s must be positive");
  impl_ = std::make_unique<Impl>(std::move(config));
}

GroundLink::~GroundLink() {
  impl_->stopping.store(true);
  try {
    impl_->stop_guard.trigger();
  } catch (...) {
    // the loop wakes within one heartbeat period anyway
  }
  if (impl_->thread.joinable()) impl_->thread.join();
  impl_->delay.stop();
}

bool GroundLink::wait_for_remote(std::chrono::nanoseconds timeout) {
  const auto deadline = Clock::now() + timeout;
  if (impl_->commands && !impl_->commands->wait_for_readers(1, timeout)) return false;
  if (impl_->chunks && !impl_->chunks->wait_for_readers(1, deadline - Clock::now())) return false;
  if (impl_->aborts && !impl_->aborts->wait_for_readers(1, deadline - Clock::now())) return false;
  // The heartbeat topic matches on its own schedule (seen 17 s late on a
  // loaded host): until the remote's heartbeat reader has matched, it never
  // hears this station, so it could never see the link lost either. Two
  // readers: this station's own (of the remote's beats) and the remote's.
  if (impl_->commands && !impl_->heartbeat_out.wait_for_readers(2, deadline - Clock::now())) return false;
  const auto left = deadline - Clock::now();
  if (left <= Clock::duration::zero()) return false;
  return impl_->delay.wait_samples(1, std::chrono::duration_cast<std::chrono::nanoseconds>(left));
}

std::uint64_t GroundLink::send(protocol::CommandKind kind, const protocol::Payload& payload, double lifetime_s,
                               std::uint64_t after_command_id) {
  Writer<msg::Command>* writer = impl_->commands.get();
  if (writer == nullptr && kind == protocol::CommandKind::Abort) writer = impl_->aborts.get();
  if (writer == nullptr)
    throw std::logic_error("GroundLink: read-only (Config::read_only): cannot send commands but ABORT");
  const double lifetime = lifetime_s < 0.0 ? impl_->config.command_lifetime_s : lifetime_s;
  std::lock_guard send_lock(impl_->send_mutex);
  auto c = impl_->sequencer.next(static_cast<msg::CommandKind>(kind), lifetime);
  protocol::fill_payload(*c, kind, payload);  // throws before the sequence is used on the wire
  c->after_command_id = after_command_id;
  const std::uint64_t id = c->command_id;
  {
    std::lock_guard lock(impl_->mutex);
    impl_->sent_at[id] = Clock::now();
  }
  writer->write(c);
  return id;
}

CommandResult GroundLink::wait_final(std::uint64_t command_id, std::chrono::nanoseconds timeout) {
  const auto start = Clock::now();
  CommandResult r;
  r.command_id = command_id;
  std::unique_lock lock(impl_->mutex);
  const auto terminal = [&] {
    const auto it = impl_->ack_log.find(command_id);
    if (it == impl_->ack_log.end()) return false;
    return std::any_of(it->second.begin(), it->second.end(),
                       [](const protocol::Ack& a) { return protocol::is_terminal(a.state); });
  };
  r.finished = impl_->changed.wait_for(lock, timeout, terminal);
  const auto it = impl_->ack_log.find(command_id);
  if (it != impl_->ack_log.end()) {
    r.acks = it->second;
    const protocol::Ack* last = &r.acks.back();
    for (const auto& a : r.acks) {
      if (protocol::is_terminal(a.state)) last = &a;
    }
    r.state = last->state;
    r.code = last->code;
    r.reason = last->reason;
    r.final_q_rad = last->final_q_rad;
  }
  const auto sent = impl_->sent_at.find(command_id);
  const auto from = sent != impl_->sent_at.end() ? sent->second : start;
  r.elapsed_s = std::chrono::duration<double>(Clock::now() - from).count();
  return r;
}

std::chrono::nanoseconds GroundLink::timeout_for(double expected_duration_s) const {
  const auto stats = impl_->delay.stats();
  const double p99 = stats.count > 0 ? stats.p99_s : impl_->config.default_rtt_s;
  // 1.5 x the expected duration: a remote on a loaded machine may overrun
  // control cycles, which stretches a motion's wall time.
  return seconds(1.5 * std::max(0.0, expected_duration_s) + 3.0 * p99 + impl_->config.timeout_margin_s);
}

CommandResult GroundLink::execute(protocol::CommandKind kind, const protocol::Payload& payload,
                                  double expected_duration_s) {
  const auto id = send(kind, payload);
  return wait_final(id, timeout_for(expected_duration_s));
}

UploadResult GroundLink::upload(const Trajectory& trajectory, std::chrono::nanoseconds timeout,
                                std::uint64_t trajectory_id) {
  UploadResult r = start_upload(trajectory, trajectory_id);
  wait_upload(r, timeout);
  return r;
}

UploadResult GroundLink::start_upload(const Trajectory& trajectory, std::uint64_t trajectory_id) {
  if (!impl_->chunks) throw std::logic_error("GroundLink: read-only (Config::read_only): cannot upload");
  UploadResult r;
  r.trajectory_id = trajectory_id != 0 ? trajectory_id : protocol::random_id();
  r.local_hash = trajectory_hash(trajectory);
  auto parts = protocol::make_chunks(trajectory, r.trajectory_id, impl_->sequencer.session_id(), r.local_hash);
  r.chunk_count = static_cast<std::uint32_t>(parts.size());
  {
    std::lock_guard lock(impl_->mutex);
    impl_->upload_log.erase(r.trajectory_id);
  }
  r.started_ = Clock::now();
  {
    std::lock_guard lock(impl_->chunk_mutex);
    for (const auto& chunk : parts) impl_->chunks->write(chunk);
  }
  return r;
}

void GroundLink::wait_upload(UploadResult& r, std::chrono::nanoseconds timeout) {
  std::unique_lock lock(impl_->mutex);
  const auto final_state = [&] {
    const auto it = impl_->upload_log.find(r.trajectory_id);
    return it != impl_->upload_log.end() && it->second.state != protocol::UploadState::Assembling;
  };
  impl_->changed.wait_until(lock, r.started_ + timeout, final_state);
  const auto it = impl_->upload_log.find(r.trajectory_id);
  if (it != impl_->upload_log.end()) {
    r.state = it->second.state;
    r.code = it->second.code;
    r.reason = it->second.reason;
    if (r.state != protocol::UploadState::Assembling) r.remote_hash = it->second.hash;
  }
  r.elapsed_s = std::chrono::duration<double>(Clock::now() - r.started_).count();
}

std::optional<Timed<protocol::JointReport>> GroundLink::joint_state() const {
  std::lock_guard lock(impl_->mutex);
  auto v = impl_->joint_state;
  if (v) v->age_s = impl_->age_s(v->value.stamp_ns);
  return v;
}
protocol::ParticipantGuid GroundLink::remote_participant() const {
  std::lock_guard lock(impl_->mutex);
  return impl_->remote_participant;
}

DroppedSamples GroundLink::dropped() const {
  DroppedSamples d;
  {
    std::lock_guard lock(impl_->mutex);
    d = impl_->drops;
  }
  d.foreign += impl_->delay.ignored_pongs();  // pongs of another participant than the remote
  return d;
}
std::optional<Timed<protocol::WrenchReport>> GroundLink::wrench() const {
  std::lock_guard lock(impl_->mutex);
  auto v = impl_->wrench;
  if (v) v->age_s = impl_->age_s(v->value.stamp_ns);
  return v;
}
std::optional<Timed<protocol::ToolReport>> GroundLink::tool() const {
  std::lock_guard lock(impl_->mutex);
  auto v = impl_->tool;
  if (v) v->age_s = impl_->age_s(v->value.stamp_ns);
  return v;
}
std::optional<Timed<protocol::StatusReport>> GroundLink::status() const {
  std::lock_guard lock(impl_->mutex);
  auto v = impl_->status;
  if (v) v->age_s = impl_->age_s(v->value.stamp_ns);
  return v;
}

bool GroundLink::remote_alive() const { return remote_silence_s() <= impl_->config.remote_loss_s; }

double GroundLink::remote_silence_s() const {
  std::lock_guard lock(impl_->mutex);
  if (!impl_->remote_heard) return std::numeric_limits<double>::infinity();
  return std::chrono::duration<double>(Clock::now() - *impl_->remote_heard).count();
}

std::uint64_t GroundLink::remote_boot_id() const {
  std::lock_guard lock(impl_->mutex);
  return impl_->remote_boot;
}

DelayMonitor& GroundLink::delay() noexcept { return impl_->delay; }
const DelayMonitor& GroundLink::delay() const noexcept { return impl_->delay; }
std::uint64_t GroundLink::session_id() const noexcept { return impl_->sequencer.session_id(); }
const protocol::Participant& GroundLink::participant() const noexcept { return impl_->participant; }
bool GroundLink::secured() const noexcept { return !impl_->config.security_dir.empty(); }
std::string GroundLink::identity() const { return secured() ? impl_->config.security_identity : std::string(); }
void GroundLink::pause_heartbeat() noexcept { impl_->heartbeat_paused.store(true); }
void GroundLink::resume_heartbeat() noexcept { impl_->heartbeat_paused.store(false); }

}  // namespace foresight::ground_link
