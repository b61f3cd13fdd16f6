#include "foresight/remote_link/remote_link.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <deque>
#include <map>
#include <mutex>
#include <set>
#include <stdexcept>
#include <thread>
#include <tuple>

#include "foresight/protocol/codec.hpp"
#include "foresight/protocol/commands.hpp"
#include "foresight/protocol/dds.hpp"
#include "foresight/protocol/ros2.hpp"
#include "foresight/protocol/security.hpp"
#include "foresight/protocol/trajectory_upload.hpp"
#include "foresight/protocol/convert.hpp"

namespace foresight::remote_link {

namespace msg = protocol::msg;
using protocol::Reader;
using protocol::Sample;
using protocol::Writer;
using Clock = std::chrono::steady_clock;

namespace {

// WaitSet tokens.
enum Token : dds_attach_t { kStop = 1, kCommand, kChunk, kPing, kHeartbeat, kAbortToken };

/// Samples taken per reader per wake-up: bounds one pass of the loop so a
/// flood on one topic cannot starve the heartbeat and the others.
constexpr int kTakeBatch = 64;
/// Accepted commands remembered to tell a re-sent command from a replay.
constexpr std::size_t kRememberedCommands = 256;
/// Rejected uploads whose verdict the assembler keeps (later chunks of the same id stay rejected).
constexpr std::size_t kRememberedRejections = 4;

std::chrono::nanoseconds seconds(double s) {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::duration<double>(s));
}

/// A writer with its own lock: Cyclone writers are used from one thread at a time.
template <class T>
struct LockedWriter {
  LockedWriter(const protocol::Participant& p) : writer(p) {}
  std::mutex mutex;
  Writer<T> writer;
  Sample<T> sample;  // reused: its sequence buffers survive between writes
};

struct UploadRecord {
  msg::UploadState state{};
  std::uint32_t chunks_received = 0, chunk_count = 0;
  TrajectoryHash hash{};
  msg::ReasonCode code{};
  std::string reason;
};

}  // namespace

struct RemoteLink::Impl {
  Impl(Config c, Handlers h)
      : config(std::move(c)),
        handlers(std::move(h)),
        participant(protocol::make_participant(config.domain, config.security_dir, config.security_identity)),
        commands(participant),
        aborts(participant, protocol::topics::kAbort),
        chunks(participant),
        pings(participant),
        heartbeats(participant),
        acks(participant),
        upload_status(participant),
        joints(participant),
        wrenches(participant),
        tools(participant),
        status(participant),
        pongs(participant),
        heartbeat_out(participant),
        stop_guard(participant),
        waitset(participant),
        assembler(protocol::TrajectoryAssembler::Limits{
            static_cast<std::uint32_t>(msg::kMaxJoints),
            static_cast<std::uint32_t>(config.trajectory_limits.max_samples),
            config.max_pending_uploads + kRememberedRejections, std::max<std::size_t>(1, config.max_pending_per_session)}),
        boot_id(protocol::random_id()) {
    waitset.attach(stop_guard, kStop);
    waitset.attach(commands, kCommand);
    waitset.attach(aborts, kAbortToken);
    waitset.attach(chunks, kChunk);
    waitset.attach(heartbeats, kHeartbeat);
    payload_limits.joints = config.trajectory_limits.joints;
    if (!config.pong_in_listener) waitset.attach(pings, kPing);
    if (config.ros2) {
      ros_joints = std::make_unique<LockedWriter<protocol::ros2::JointState>>(participant);
      ros_wrench = std::make_unique<LockedWriter<protocol::ros2::WrenchStamped>>(participant);
      std::lock_guard lock(ros_wrench->mutex);
      protocol::ros2::set_frame_id(ros_wrench->sample->header, config.ros2_wrench_frame);
    }
  }

  bool publish_ros(const protocol::JointReport& r) noexcept {
    if (!ros_joints) return true;
    try {
      std::lock_guard lock(ros_joints->mutex);
      auto& s = *ros_joints->sample;
      if (s.name._length != r.q_rad.size()) {
        std::vector<std::string> names = config.ros2_joint_names;
        if (names.size() != r.q_rad.size()) {
          names.clear();
          for (std::size_t i = 0; i < r.q_rad.size(); ++i) names.push_back("joint" + std::to_string(i + 1));
        }
        protocol::ros2::set_names(s, names);
      }
      protocol::ros2::set_stamp(s.header.stamp, r.stamp_ns);
      if (s.header.frame_id == nullptr) protocol::ros2::set_frame_id(s.header, "");
      protocol::assign(s.position, std::span<const double>(r.q_rad), msg::kMaxJoints, "ros2 position");
      protocol::assign(s.velocity, std::span<const double>(r.dq_rad_s), msg::kMaxJoints, "ros2 velocity");
      protocol::assign(s.effort, std::span<const double>(r.torque_nm), msg::kMaxJoints, "ros2 effort");
      if (ros_joints->writer.try_write(s) < 0) {
        n_write_failures.fetch_add(1);
        return false;
      }
      return true;
    } catch (const std::exception&) {
      n_write_failures.fetch_add(1);
      return false;
    }
  }

  bool publish_ros(const protocol::WrenchReport& r) noexcept {
    if (!ros_wrench) return true;
    std::lock_guard lock(ros_wrench->mutex);
    auto& s = *ros_wrench->sample;
    protocol::ros2::set_stamp(s.header.stamp, r.stamp_ns);
    s.wrench.force = {r.force_tool_n[0], r.force_tool_n[1], r.force_tool_n[2]};
    s.wrench.torque = {r.torque_tool_nm[0], r.torque_tool_nm[1], r.torque_tool_nm[2]};
    if (ros_wrench->writer.try_write(s) < 0) {
      n_write_failures.fetch_add(1);
      return false;
    }
    return true;
  }

  /// Answers pings on Cyclone's receive thread (set in start()): no thread
  /// switch between a ping's arrival and its pong. Only a take and a write
  /// happen there (no entity creation, no lock, nothing that throws).
  static void on_ping_data(dds_entity_t reader, void* arg) noexcept {
    auto* self = static_cast<Impl*>(arg);
    for (int i = 0; i < kTakeBatch; ++i) {
      void* buffers[1] = {self->listener_ping.get()};
      dds_sample_info_t info;
      if (dds_take(reader, buffers, &info, 1, 1) <= 0) break;
      if (info.valid_data) self->answer(*self->listener_ping, self->listener_pong);
    }
  }
  void answer(const msg::Ping& ping, Sample<msg::Pong>& pong) noexcept {
    pong->remote_receive_ns = protocol::now_ns();
    pong->ping_id = ping.ping_id;
    pong->ground_send_ns = ping.ground_send_ns;
    pong->remote_send_ns = protocol::now_ns();
    (void)pongs.try_write(*pong);
    n_pings.fetch_add(1);
  }

  void run() noexcept;
  void serve_commands();
  void serve_commands_of(Reader<msg::Command>& reader, bool abort_only);
  void serve_chunks();
  /// Half uploads idle for upload_idle_timeout_s: rejected, published, reported.
  void expire_uploads();
  /// Every 250 ms: the commander's participant still has a command writer, or on_link(CommanderLeft).
  void watch_commander(Clock::time_point now);
  Clock::time_point next_commander_check{};
  void serve_pings();
  void serve_heartbeats();
  void beat_and_watch();
  void on_chunk(const msg::TrajectoryChunk& chunk);
  void publish_status(std::uint64_t id, const UploadRecord& record);
  void emit_upload(const UploadEvent& event);
  void emit_command(const CommandEvent& event);
  void emit_link(const LinkEvent& event);
  template <class T, class R>
  bool publish(LockedWriter<T>& w, const R& report) noexcept;

  Config config;
  Handlers handlers;
  protocol::PayloadLimits payload_limits;
  protocol::Participant participant;
  Reader<msg::Command> commands;
  Reader<msg::Command> aborts;  // topics::kAbort: ABORT only (an observer's way to stop the arm)
  Reader<msg::TrajectoryChunk> chunks;
  Reader<msg::Ping> pings;
  Reader<msg::Heartbeat> heartbeats;
  LockedWriter<msg::CommandAck> acks;
  LockedWriter<msg::TrajectoryStatus> upload_status;
  LockedWriter<msg::JointState> joints;
  LockedWriter<msg::Wrench> wrenches;
  LockedWriter<msg::ToolState> tools;
  LockedWriter<msg::ControllerStatus> status;
  Writer<msg::Pong> pongs;
  Writer<msg::Heartbeat> heartbeat_out;
  protocol::GuardCondition stop_guard;
  protocol::WaitSet waitset;
  std::unique_ptr<LockedWriter<protocol::ros2::JointState>> ros_joints;   // Config::ros2 only
  std::unique_ptr<LockedWriter<protocol::ros2::WrenchStamped>> ros_wrench;

  // Link thread only.
  struct Session {
    protocol::CommandChecker checker;
    std::uint64_t last_used = 0;
    Clock::time_point last_seen{};
  };
  using SessionKey = std::pair<std::uint64_t, protocol::ParticipantGuid>;
  /// Sessions forgotten (expired or pushed out): their commands stay refused.
  std::set<SessionKey> retired;
  std::deque<SessionKey> retired_order;
  static constexpr std::size_t kMaxRetired = 65536;
  void retire(const SessionKey& key) {
    if (!retired.insert(key).second) return;
    retired_order.push_back(key);
    if (retired_order.size() > kMaxRetired) {
      retired.erase(retired_order.front());
      retired_order.pop_front();
    }
  }
  /// Every second: sessions idle for session_idle_s retired.
  void expire_sessions(Clock::time_point now);
  bool idle(const Session& s, Clock::time_point now) const {
    return now - s.last_seen > std::chrono::duration<double>(config.session_idle_s);
  }
  /// A command the link refuses itself before any sequence check: its
  /// envelope, the code and why, counted, logged and handed on (acked REJECTED).
  void reject_here(CommandEvent& event, const msg::Command& c, std::int64_t received, protocol::Reason code,
                   std::string reason) {
    event.command = protocol::envelope_of(c, received);
    event.code = code;
    event.reason = std::move(reason);
    n_rejected.fetch_add(1);
    spdlog::warn("remote link: rejected {}", event.reason);
    emit_command(event);
  }
  Clock::time_point next_session_check{};
  // Keyed by the session and the participant that wrote it: a participant
  // speaking in another's session (a forged session id) has a sequence of its
  // own, so it can neither advance nor break the real session's (the
  // supervisor then refuses it: not the participant in control).
  std::map<std::pair<std::uint64_t, protocol::ParticipantGuid>, Session> sessions;
  std::uint64_t session_clock = 0;
  std::deque<std::tuple<std::uint64_t, std::uint64_t, std::uint64_t>> accepted;  // session, id, sequence
  protocol::TrajectoryAssembler assembler;
  std::deque<std::uint64_t> rejected_uploads;
  Sample<msg::Command> command_in;
  Sample<msg::TrajectoryChunk> chunk_in;
  Sample<msg::Ping> ping_in;
  Sample<msg::Pong> pong_out;
  Sample<msg::Ping> listener_ping;  // Cyclone's receive thread only
  Sample<msg::Pong> listener_pong;
  Sample<msg::Heartbeat> heartbeat_in;
  Sample<msg::Heartbeat> heartbeat_sample;
  Clock::time_point next_beat{};
  Clock::time_point last_ground_beat{};
  bool ever_heard = false;
  std::uint64_t ground_boot_id = 0;
  Clock::time_point lost_at{};

  // Shared with other threads.
  mutable std::mutex uploads_mutex;
  std::map<std::uint64_t, UploadRecord> records;  // every kept upload's last status
  std::map<std::uint64_t, std::shared_ptr<const Trajectory>> committed;
  std::deque<std::uint64_t> committed_order;

  std::atomic<bool> stopping{false};
  std::atomic<bool> link_up{false};
  std::atomic<std::uint64_t> n_commands{0}, n_rejected{0}, n_acks{0}, n_write_failures{0}, n_pings{0},
      n_chunks{0}, n_committed{0}, n_upload_rejected{0}, n_handler_exceptions{0}, n_foreign_heartbeats{0},
      n_foreign_chunks{0}, n_rate_limited{0};
  /// The per-participant command budget (Config::max_commands_per_s).
  struct Bucket {
    double tokens = 0.0;
    Clock::time_point refilled{};
    std::uint64_t dropped = 0;  ///< since the last report
    Clock::time_point first_drop{};
  };
  static constexpr std::size_t kMaxBuckets = 256;
  std::map<protocol::ParticipantGuid, Bucket> buckets;
  /// Takes a token of `writer`'s bucket; false: over its rate (counted).
  bool admit(const protocol::ParticipantGuid& writer, Clock::time_point now);
  /// One LinkEvent::RateLimited a second per participant that was dropped from.
  void report_rate_limits(Clock::time_point now);
  mutable std::mutex commander_mutex;
  protocol::ParticipantGuid commander;  // set_commander; unknown: anyone's heartbeats count
  /// Who wrote a sample: its participant, or with DDS Security its
  /// identity (protocol::identity_of: every process of one ground station is
  /// one writer, so control, sessions and rate limits belong to the station).
  protocol::ParticipantGuid writer_of(dds_entity_t reader, dds_instance_handle_t handle) const {
    const protocol::ParticipantGuid p = protocol::writer_participant(reader, handle);
    return config.security_dir.empty() ? p : protocol::identity_of(p);
  }
  /// True when `writer` may speak for the link: the commander, or anyone while nobody is in control.
  bool from_commander(const protocol::ParticipantGuid& writer) const {
    std::lock_guard lock(commander_mutex);
    return !commander.known() || writer == commander;
  }
  const std::uint64_t boot_id;
  std::thread thread;
};

void RemoteLink::Impl::run() noexcept {
  const auto period = seconds(std::min(config.heartbeat_period_s, config.link_loss_s / 4.0));
  next_beat = Clock::now();
  while (!stopping.load()) {
    try {
      beat_and_watch();
      const auto wait = std::max(std::chrono::nanoseconds(0),
                                 std::min<std::chrono::nanoseconds>(period, next_beat - Clock::now()));
      waitset.wait(wait);
      if (stopping.load()) break;
      serve_pings();  // first: the delay measurement should not wait behind commands
      serve_heartbeats();
      serve_commands();
      serve_chunks();
      expire_uploads();
      expire_sessions(Clock::now());
    } catch (const std::exception& e) {
      // A DDS call failed (should not happen with valid entities): keep serving.
      spdlog::error("remote link: {}", e.what());
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
  }
}

void RemoteLink::Impl::watch_commander(Clock::time_point now) {
  // With DDS Security control belongs to the station's identity, not to one
  // of its processes: it keeps control between commands until it releases it
  // or its lease ends (the supervisor's control_lease_s).
  if (!config.security_dir.empty()) return;
  if (now < next_commander_check) return;
  next_commander_check = now + std::chrono::milliseconds(250);
  protocol::ParticipantGuid who;
  {
    std::lock_guard lock(commander_mutex);
    who = commander;
  }
  if (!who.known()) return;
  std::array<dds_instance_handle_t, 64> handles{};
  const dds_return_t n = dds_get_matched_publications(commands.get(), handles.data(), handles.size());
  if (n < 0) return;
  for (dds_return_t i = 0; i < std::min<dds_return_t>(n, static_cast<dds_return_t>(handles.size())); ++i)
    if (writer_of(commands.get(), handles[static_cast<std::size_t>(i)]) == who) return;
  if (n > static_cast<dds_return_t>(handles.size())) return;  // more writers than looked at: not sure
  {
    std::lock_guard lock(commander_mutex);
    if (commander == who) commander = protocol::ParticipantGuid{};
  }
  LinkEvent e;
  e.kind = LinkEvent::Kind::CommanderLeft;
  e.participant = who;
  spdlog::info("remote link: the commander's participant {} left", who.hex());
  emit_link(e);
}

bool RemoteLink::Impl::admit(const protocol::ParticipantGuid& writer, Clock::time_point now) {
  if (!(config.max_commands_per_s > 0.0)) return true;
  auto it = buckets.find(writer);
  if (it == buckets.end()) {
    if (buckets.size() >= kMaxBuckets) {  // forget the longest idle (a full bucket again when it returns)
      auto idle = std::min_element(buckets.begin(), buckets.end(), [](const auto& a, const auto& b) {
        return a.second.refilled < b.second.refilled;
      });
      buckets.erase(idle);
    }
    it = buckets.emplace(writer, Bucket{config.command_burst, now, 0, {}}).first;
  }
  Bucket& b = it->second;
  b.tokens = std::min(config.command_burst,
                      b.tokens + std::chrono::duration<double>(now - b.refilled).count() * config.max_commands_per_s);
  b.refilled = now;
  if (b.tokens >= 1.0) {
    b.tokens -= 1.0;
    return true;
  }
  if (b.dropped++ == 0) b.first_drop = now;
  n_rate_limited.fetch_add(1);
  return false;
}

void RemoteLink::Impl::report_rate_limits(Clock::time_point now) {
  for (auto& [writer, b] : buckets) {
    if (b.dropped == 0 || now - b.first_drop < std::chrono::seconds(1)) continue;
    LinkEvent e;
    e.kind = LinkEvent::Kind::RateLimited;
    e.participant = writer;
    e.dropped = b.dropped;
    e.silence_s = std::chrono::duration<double>(now - b.first_drop).count();
    spdlog::warn("remote link: {} commands of participant {} dropped in {:.1f} s (over {:.0f} a second)", b.dropped,
                 writer.hex(), e.silence_s, config.max_commands_per_s);
    b.dropped = 0;
    emit_link(e);
  }
}

void RemoteLink::Impl::beat_and_watch() {
  const auto now = Clock::now();
  watch_commander(now);
  report_rate_limits(now);
  if (now >= next_beat) {
    heartbeat_sample->side = foresight_msg_SIDE_REMOTE;
    heartbeat_sample->boot_id = boot_id;
    ++heartbeat_sample->counter;
    heartbeat_sample->stamp_ns = protocol::now_ns();
    (void)heartbeat_out.try_write(*heartbeat_sample);
    next_beat = now + seconds(config.heartbeat_period_s);
  }
  if (link_up.load() && now - last_ground_beat > seconds(config.link_loss_s)) {
    link_up.store(false);
    lost_at = now;
    LinkEvent e;
    e.kind = LinkEvent::Kind::Lost;
    e.silence_s = std::chrono::duration<double>(now - last_ground_beat).count();
    e.ground_boot_id = ground_boot_id;
    spdlog::warn("remote link: link lost (no ground heartbeat for {:.2f} s)", e.silence_s);
    emit_link(e);
  }
}

void RemoteLink::Impl::serve_heartbeats() {
  dds_sample_info_t info{};
  for (int i = 0; i < kTakeBatch && heartbeats.take(heartbeat_in, &info); ++i) {
    if (protocol::raw(heartbeat_in->side) != foresight_msg_SIDE_GROUND) continue;  // our own, looped back (or invalid)
    if (!from_commander(writer_of(heartbeats.get(), info.publication_handle))) {
      n_foreign_heartbeats.fetch_add(1);  // an observer's or an impostor's: keeps no link
      continue;
    }
    const auto now = Clock::now();
    last_ground_beat = now;
    ground_boot_id = heartbeat_in->boot_id;
    if (!link_up.load()) {
      link_up.store(true);
      LinkEvent e;
      e.kind = LinkEvent::Kind::Regained;
      e.silence_s = ever_heard ? std::chrono::duration<double>(now - lost_at).count() : 0.0;
      e.ground_boot_id = ground_boot_id;
      ever_heard = true;
      spdlog::info("remote link: link up (ground boot {:016x})", ground_boot_id);
      emit_link(e);
    }
  }
}

void RemoteLink::Impl::serve_pings() {
  if (config.pong_in_listener) return;
  for (int i = 0; i < kTakeBatch && pings.take(ping_in); ++i) answer(*ping_in, pong_out);
}

void RemoteLink::Impl::serve_commands() {
  serve_commands_of(commands, false);
  serve_commands_of(aborts, true);
}

void RemoteLink::Impl::serve_commands_of(Reader<msg::Command>& reader, bool abort_only) {
  dds_sample_info_t info{};
  for (int i = 0; i < kTakeBatch && reader.take(command_in, &info); ++i) {
    n_commands.fetch_add(1);
    const msg::Command& c = *command_in;
    const std::int64_t received = protocol::now_ns();
    CommandEvent event;
    event.writer = writer_of(reader.get(), info.publication_handle);
    if (abort_only && protocol::raw(c.payload._d) != foresight_msg_CMD_ABORT) {
      if (!admit(event.writer, Clock::now())) continue;
      reject_here(event, c, received, protocol::Reason::BadArgument,
                  std::string("command ") + std::to_string(c.command_id) + ": " + protocol::topics::kAbort +
                      " carries only ABORT");
      continue;
    }
    const bool commanders_abort =
        protocol::raw(c.payload._d) == foresight_msg_CMD_ABORT && from_commander(event.writer);
    if (!commanders_abort && !admit(event.writer, Clock::now())) continue;  // over its rate: dropped, counted
    // Per-session sequence: a second ground station has its own. Beyond
    // max_sessions of one participant, its own least recently used session
    // is forgotten: another participant's new sessions can never evict a
    // ground's (and so reset its sequence for a replay). The participants
    // themselves are bounded by the rate limit's table (kMaxBuckets).
    const auto session_key = std::make_pair(c.session_id, event.writer);
    if (auto known = sessions.find(session_key); known != sessions.end() && idle(known->second, Clock::now())) {
      retire(session_key);  // idle too long: expired now, whether or not the sweep has run
      sessions.erase(known);
    }
    if (retired.count(session_key) != 0) {
      char buf[200];
      std::snprintf(buf, sizeof buf,
                    "session %016llx was forgotten (no command for %.0f s, or more than %zu sessions of its writer): "
                    "its commands are refused; a ground process starts a new session",
                    static_cast<unsigned long long>(c.session_id), config.session_idle_s, config.max_sessions);
      reject_here(event, c, received, protocol::Reason::BadSequence, buf);
      continue;
    }
    auto it = sessions.find(session_key);
    if (it == sessions.end()) {
      auto oldest = sessions.end();
      std::size_t own = 0;
      for (auto s = sessions.begin(); s != sessions.end(); ++s) {
        if (s->first.second != event.writer) continue;
        if (oldest == sessions.end() || s->second.last_used < oldest->second.last_used) oldest = s;
        ++own;
      }
      if (own >= std::max<std::size_t>(1, config.max_sessions)) {
        retire(oldest->first);
        sessions.erase(oldest);
      }
      if (sessions.size() >= kMaxBuckets * std::max<std::size_t>(1, config.max_sessions)) {
        // Every participant at its bound (only without a rate limit): the stalest overall.
        const auto stalest = std::min_element(sessions.begin(), sessions.end(), [](const auto& a, const auto& b) {
          return a.second.last_used < b.second.last_used;
        });
        retire(stalest->first);
        sessions.erase(stalest);
      }
      it = sessions.emplace(session_key, Session{}).first;
    }
    it->second.last_used = ++session_clock;
    it->second.last_seen = Clock::now();
    const auto verdict = it->second.checker.check(c, received, config.clock_offset_ns);
    if (!verdict.ok()) {
      event.command = protocol::envelope_of(c, received);
      event.code = static_cast<protocol::Reason>(verdict.code);
      event.reason = verdict.reason;
      if (verdict.code == foresight_msg_REASON_BAD_SEQUENCE) {
        const auto key = std::make_tuple(c.session_id, c.command_id, c.sequence_number);
        event.duplicate = std::find(accepted.begin(), accepted.end(), key) != accepted.end();
      }
    } else {
      // Past the envelope: a re-send of this very command is a duplicate,
      // whatever the payload check says (the daemon repeats its last ack).
      accepted.emplace_back(c.session_id, c.command_id, c.sequence_number);
      if (accepted.size() > kRememberedCommands) accepted.pop_front();
      const auto payload = protocol::check_payload(c, payload_limits);
      if (!payload.ok()) {
        event.command = protocol::envelope_of(c, received);
        event.code = payload.code;
        event.reason = "command " + std::to_string(c.command_id) + ": " + payload.reason;
      } else {
        event.command = protocol::from_wire(c, received);
      }
    }
    if (!event.accepted()) {
      n_rejected.fetch_add(1);
      spdlog::warn("remote link: rejected {}", event.reason);
    }
    emit_command(event);
  }
}

void RemoteLink::Impl::serve_chunks() {
  dds_sample_info_t info{};
  for (int i = 0; i < kTakeBatch && chunks.take(chunk_in, &info); ++i) {
    n_chunks.fetch_add(1);
    if (!from_commander(writer_of(chunks.get(), info.publication_handle))) {
      n_foreign_chunks.fetch_add(1);  // never stored: another participant holds no upload slot
      continue;
    }
    on_chunk(*chunk_in);
  }
}

void RemoteLink::Impl::on_chunk(const msg::TrajectoryChunk& chunk) {
  const std::uint64_t id = chunk.trajectory_id;
  {
    std::lock_guard lock(uploads_mutex);
    if (committed.count(id) != 0) return;  // a re-sent chunk of a committed upload
  }
  const bool already_rejected = std::find(rejected_uploads.begin(), rejected_uploads.end(), id) != rejected_uploads.end();
  const auto progress = assembler.add(chunk);
  UploadRecord record;
  record.state = progress.state;
  record.chunks_received = progress.chunks_received;
  record.chunk_count = progress.chunk_count;
  record.hash = protocol::get_hash(chunk.content_hash);
  record.code = progress.code;
  record.reason = progress.reason;
  UploadEvent event;
  event.trajectory_id = id;
  event.session_id = chunk.session_id;
  std::shared_ptr<const Trajectory> kept;
  std::optional<std::uint64_t> evicted;
  if (progress.state == foresight_msg_UPLOAD_REJECTED) {
    if (already_rejected) return;  // reported once
    if (progress.code != foresight_msg_REASON_BUSY) {  // a BUSY upload is not remembered by the assembler
      rejected_uploads.push_back(id);
      if (rejected_uploads.size() > kRememberedRejections) {
        assembler.discard(rejected_uploads.front());
        rejected_uploads.pop_front();
      }
    }
    n_upload_rejected.fetch_add(1);
  } else if (progress.whole()) {
    auto assembled = assembler.take(id);
    if (!assembled) return;  // cannot happen: whole() said so
    const auto verdict = protocol::verify(*assembled, config.trajectory_limits);
    record.hash = verdict.computed_hash;
    if (verdict.ok()) {
      record.state = foresight_msg_UPLOAD_COMMITTED;
      record.code = foresight_msg_REASON_NONE;
      record.reason.clear();
      kept = std::make_shared<const Trajectory>(std::move(assembled->trajectory));
      n_committed.fetch_add(1);
    } else {
      record.state = foresight_msg_UPLOAD_REJECTED;
      record.code = verdict.code;
      record.reason = verdict.reason;
      n_upload_rejected.fetch_add(1);
    }
  }
  {
    std::lock_guard lock(uploads_mutex);
    if (record.state == foresight_msg_UPLOAD_ASSEMBLING || record.state == foresight_msg_UPLOAD_COMMITTED ||
        record.state == foresight_msg_UPLOAD_REJECTED) {
      records[id] = record;
    }
    if (kept) {
      committed[id] = kept;
      committed_order.push_back(id);
      if (committed_order.size() > std::max<std::size_t>(1, config.max_committed)) {
        evicted = committed_order.front();
        committed_order.pop_front();
        committed.erase(*evicted);
        records.erase(*evicted);
      }
    }
    // Bound the remembered statuses: assembling and committed ones are
    // bounded by the assembler and max_committed; drop the oldest rejected.
    while (records.size() > config.max_committed + config.max_pending_uploads + 2 * kRememberedRejections) {
      auto victim = std::find_if(records.begin(), records.end(), [](const auto& r) {
        return r.second.state == foresight_msg_UPLOAD_REJECTED;
      });
      if (victim == records.end()) break;
      records.erase(victim);
    }
  }
  publish_status(id, record);
  event.state = static_cast<protocol::UploadState>(record.state);
  event.chunks_received = record.chunks_received;
  event.chunk_count = record.chunk_count;
  event.code = static_cast<protocol::Reason>(record.code);
  event.reason = record.reason;
  event.hash = record.hash;
  event.trajectory = kept;
  if (record.state == foresight_msg_UPLOAD_REJECTED) spdlog::warn("remote link: upload rejected: {}", record.reason);
  emit_upload(event);
  if (evicted) {
    UploadRecord gone;
    gone.state = foresight_msg_UPLOAD_DISCARDED;
    gone.code = foresight_msg_REASON_NONE;
    gone.reason = "discarded: more than " + std::to_string(config.max_committed) + " committed uploads";
    publish_status(*evicted, gone);
    UploadEvent e;
    e.trajectory_id = *evicted;
    e.state = protocol::UploadState::Discarded;
    e.reason = gone.reason;
    emit_upload(e);
  }
}

void RemoteLink::Impl::expire_sessions(Clock::time_point now) {
  if (now < next_session_check) return;
  next_session_check = now + std::chrono::seconds(1);
  for (auto it = sessions.begin(); it != sessions.end();) {
    if (idle(it->second, now)) {
      spdlog::info("remote link: session {:016x} retired after {:.0f} s without a command", it->first.first,
                   config.session_idle_s);
      retire(it->first);
      it = sessions.erase(it);
    } else {
      ++it;
    }
  }
}

void RemoteLink::Impl::expire_uploads() {
  for (const auto& p : assembler.expire(Clock::now(), seconds(config.upload_idle_timeout_s))) {
    UploadRecord record;
    record.state = p.state;
    record.chunks_received = p.chunks_received;
    record.chunk_count = p.chunk_count;
    record.code = p.code;
    record.reason = p.reason;
    {
      std::lock_guard lock(uploads_mutex);
      if (auto it = records.find(p.trajectory_id); it != records.end()) record.hash = it->second.hash;
      records[p.trajectory_id] = record;
    }
    rejected_uploads.push_back(p.trajectory_id);  // its later chunks stay rejected, the verdict bounded
    if (rejected_uploads.size() > kRememberedRejections) {
      assembler.discard(rejected_uploads.front());
      rejected_uploads.pop_front();
    }
    n_upload_rejected.fetch_add(1);
    publish_status(p.trajectory_id, record);
    UploadEvent event;
    event.trajectory_id = p.trajectory_id;
    event.state = protocol::UploadState::Rejected;
    event.chunks_received = record.chunks_received;
    event.chunk_count = record.chunk_count;
    event.code = static_cast<protocol::Reason>(record.code);
    event.reason = record.reason;
    event.hash = record.hash;
    spdlog::warn("remote link: upload rejected: {}", record.reason);
    emit_upload(event);
  }
}

void RemoteLink::Impl::publish_status(std::uint64_t id, const UploadRecord& r) {
  std::lock_guard lock(upload_status.mutex);
  msg::TrajectoryStatus& s = *upload_status.sample;
  s.trajectory_id = id;
  s.state = r.state;
  s.chunks_received = r.chunks_received;
  s.chunk_count = r.chunk_count;
  protocol::set_hash(s.content_hash, r.hash);
  s.code = r.code;
  protocol::set_text_truncated(s.reason, r.reason);
  s.stamp_ns = protocol::now_ns();
  if (upload_status.writer.try_write(s) < 0) n_write_failures.fetch_add(1);
}

void RemoteLink::Impl::emit_command(const CommandEvent& event) {
  try {
    handlers.on_command(event);
  } catch (const std::exception& e) {
    n_handler_exceptions.fetch_add(1);
    spdlog::error("remote link: the command handler threw: {}", e.what());
  } catch (...) {
    n_handler_exceptions.fetch_add(1);
    spdlog::error("remote link: the command handler threw");
  }
}

void RemoteLink::Impl::emit_upload(const UploadEvent& event) {
  if (!handlers.on_upload) return;
  try {
    handlers.on_upload(event);
  } catch (const std::exception& e) {
    n_handler_exceptions.fetch_add(1);
    spdlog::error("remote link: the upload handler threw: {}", e.what());
  } catch (...) {
    n_handler_exceptions.fetch_add(1);
  }
}

void RemoteLink::Impl::emit_link(const LinkEvent& event) {
  if (!handlers.on_link) return;
  try {
    handlers.on_link(event);
  } catch (const std::exception& e) {
    n_handler_exceptions.fetch_add(1);
    spdlog::error("remote link: the link handler threw: {}", e.what());
  } catch (...) {
    n_handler_exceptions.fetch_add(1);
  }
}

template <class T, class R>
bool RemoteLink::Impl::publish(LockedWriter<T>& w, const R& report) noexcept {
  try {
    std::lock_guard lock(w.mutex);
    protocol::to_wire(*w.sample, report);
    if (w.writer.try_write(*w.sample) < 0) {
      n_write_failures.fetch_add(1);
      return false;
    }
    return true;
  } catch (const std::exception& e) {
    n_write_failures.fetch_add(1);
    return false;
  }
}

RemoteLink::RemoteLink(Config config, Handlers handlers) {
  if (!handlers.on_command) throw std::invalid_argument("RemoteLink: no command handler");
  if (!(config.heartbeat_period_s > 0.0)) {
    throw std::invalid_argument("RemoteLink: heartbeat_period_s must be positive");
  }
  if (!(config.link_loss_s > config.heartbeat_period_s)) {
    throw std::invalid_argument("RemoteLink: link_loss_s must exceed heartbeat_period_s");
  }
  if (config.trajectory_limits.joints < 1 ||
      config.trajectory_limits.joint_limits.size() != static_cast<std::size_t>(config.trajectory_limits.joints)) {
    throw std::invalid_argument("RemoteLink: trajectory_limits has no joints (use TrajectoryLimits::from_model)");
  }
  impl_ = std::make_unique<Impl>(std::move(config), std::move(handlers));
}

RemoteLink::~RemoteLink() { stop(); }

void RemoteLink::start() {
  if (impl_->thread.joinable() || impl_->stopping.load()) return;
  if (impl_->config.pong_in_listener) {
    dds_listener_t* listener = dds_create_listener(impl_.get());
    dds_lset_data_available(listener, &Impl::on_ping_data);
    const dds_return_t rc = dds_set_listener(impl_->pings.get(), listener);
    dds_delete_listener(listener);
    protocol::check(rc, "set the ping listener");
  }
  impl_->thread = std::thread([impl = impl_.get()] { impl->run(); });
}

void RemoteLink::stop() noexcept {
  if (!impl_) return;
  impl_->stopping.store(true);
  // Cyclone waits for a running listener callback before this returns.
  if (impl_->config.pong_in_listener) (void)dds_set_listener(impl_->pings.get(), nullptr);
  try {
    impl_->stop_guard.trigger();
  } catch (...) {
    // The thread still sees `stopping` within one wake-up period.
  }
  if (impl_->thread.joinable()) impl_->thread.join();
}

bool RemoteLink::ack(const protocol::Ack& ack) noexcept {
  const bool ok = impl_->publish(impl_->acks, ack);
  if (ok) impl_->n_acks.fetch_add(1);
  return ok;
}

bool RemoteLink::publish(const protocol::JointReport& r) noexcept {
  const bool ros_ok = impl_->publish_ros(r);
  return impl_->publish(impl_->joints, r) && ros_ok;
}
bool RemoteLink::publish(const protocol::WrenchReport& r) noexcept {
  const bool ros_ok = impl_->publish_ros(r);
  return impl_->publish(impl_->wrenches, r) && ros_ok;
}
bool RemoteLink::publish(const protocol::ToolReport& r) noexcept { return impl_->publish(impl_->tools, r); }
bool RemoteLink::publish(const protocol::StatusReport& r) noexcept { return impl_->publish(impl_->status, r); }

void RemoteLink::republish_uploads() noexcept {
  try {
    std::map<std::uint64_t, UploadRecord> copy;
    {
      std::lock_guard lock(impl_->uploads_mutex);
      copy = impl_->records;
    }
    for (const auto& [id, record] : copy) impl_->publish_status(id, record);
  } catch (...) {
    impl_->n_write_failures.fetch_add(1);
  }
}

std::shared_ptr<const Trajectory> RemoteLink::committed(std::uint64_t id) const noexcept {
  std::lock_guard lock(impl_->uploads_mutex);
  const auto it = impl_->committed.find(id);
  return it == impl_->committed.end() ? nullptr : it->second;
}

void RemoteLink::set_commander(const protocol::ParticipantGuid& participant) noexcept {
  std::lock_guard lock(impl_->commander_mutex);
  impl_->commander = participant;
}

LinkStats RemoteLink::stats() const noexcept {
  LinkStats s;
  s.commands = impl_->n_commands.load();
  s.rejected = impl_->n_rejected.load();
  s.acks_written = impl_->n_acks.load();
  s.write_failures = impl_->n_write_failures.load();
  s.pings = impl_->n_pings.load();
  s.chunks = impl_->n_chunks.load();
  s.uploads_committed = impl_->n_committed.load();
  s.uploads_rejected = impl_->n_upload_rejected.load();
  s.handler_exceptions = impl_->n_handler_exceptions.load();
  s.foreign_heartbeats = impl_->n_foreign_heartbeats.load();
  s.foreign_chunks = impl_->n_foreign_chunks.load();
  s.rate_limited = impl_->n_rate_limited.load();
  s.link_up = impl_->link_up.load();
  return s;
}

std::uint64_t RemoteLink::boot_id() const noexcept { return impl_->boot_id; }

}  // namespace foresight::remote_link
