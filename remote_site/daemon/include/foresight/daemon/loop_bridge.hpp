#pragma once
// The supervisor's side of the real-time loop's rings, for what it reads:
// telemetry (the latest sample, a journal row each, the rate limiter's
// episodes) and stops (a fault row each, with its evidence). Motion events
// are the supervisor's to match to its jobs (ControlLoop::poll_event).

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "foresight/control/control_loop.hpp"
#include "foresight/daemon/job.hpp"
#include "foresight/daemon/ledger.hpp"

namespace foresight::daemon {

class LoopBridge {
 public:
  LoopBridge(control::ControlLoop& loop, Ledger& ledger, std::size_t joints);

  /// Every telemetry sample waiting: the latest kept, each journaled, the
  /// rate limiter's episodes journaled (`command_id`: the ground's command
  /// running, 0: none).
  void drain_telemetry(std::uint64_t command_id);
  /// Every drive event waiting (ControlLoop::poll_drive_event), journaled as
  /// a `drive_event` row each: the text DriveSystem::describe gives it, the
  /// detail its fields. Notices (state changes of a power change, EMCY
  /// warnings) included.
  void drain_drive_events();
  /// The next stop, journaled as a fault row with its evidence (naming the
  /// `running` job when the loop stopped it); false when none waits.
  bool next_stop(const Job* running, control::StopEvent& out);

  const control::TelemetrySample& latest() const noexcept { return latest_; }
  bool have_telemetry() const noexcept { return have_telemetry_; }
  /// The loop holds now after a RECOVER's completion; its telemetry may lag the event.
  void set_mode(protocol::ControllerMode mode) noexcept { latest_.mode = mode; }
  /// The last stop; null before the first.
  const control::StopEvent* last_stop() const noexcept { return have_stop_ ? &last_stop_ : nullptr; }
  const protocol::RateLimitReport& rate_limit() const noexcept { return rate_limit_report_; }
  /// The measured joints of the latest sample.
  std::vector<double> current_q() const;

  /// A CLOCK_MONOTONIC stamp of the loop's as wall-clock time (the journal's and the protocol's).
  static std::int64_t to_wall_ns(std::int64_t mono_ns) noexcept;

 private:
  /// The rate limiter's episodes, from the telemetry's counters: one journal
  /// row when it starts limiting, one when it has let go for 200 ms.
  void track_rate_limiter(const control::TelemetrySample& t, std::uint64_t command_id);

  control::ControlLoop& loop_;
  Ledger& ledger_;
  control::TelemetrySample latest_{};
  bool have_telemetry_ = false;
  control::StopEvent last_stop_{};
  bool have_stop_ = false;

  struct RateLimitEpisode {
    bool active = false;
    std::uint32_t joints = 0;        ///< bit j: joint j + 1 limited in this episode
    std::uint64_t first_cycles = 0;  ///< the loop's rate_limited_cycles when it began
    std::uint64_t command_id = 0;    ///< the ground's command running when it began (0: none)
    double max_lag_rad = 0.0;
    std::int64_t last_limited_ns = 0;
  } rate_limit_{};
  protocol::RateLimitReport rate_limit_report_{};
  std::array<std::uint32_t, control::kMaxJoints> rate_limited_joint_cycles_{};
  std::uint64_t drive_events_dropped_ = 0;  ///< the loop's count already journaled
};

}  // namespace foresight::daemon
