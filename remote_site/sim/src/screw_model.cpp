#include "foresight/sim/screw_model.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <stdexcept>

#include "foresight/common/error.hpp"
#include "foresight/common/yaml_util.hpp"
#include "foresight/hw/lst_tool_registers.hpp"
#include "foresight/common/param_checks.hpp"

namespace foresight::sim {

namespace {
constexpr double kTwoPi = 2.0 * std::numbers::pi;
}

void validate(const LstMechanismParams& p) {
  auto positive = [](double v, const char* name) { require_positive(v, "lst_sim", name); };
  auto non_negative = [](double v, const char* name) { require_non_negative(v, "lst_sim", name); };
  positive(p.max_speed_rad_s, "max_speed_rad_s");
  positive(p.max_torque_nm, "max_torque_nm");
  positive(p.latch_travel_s, "latch_travel_s");
  positive(p.stall_time_s, "stall_time_s");
  const ScrewParams& s = p.screw;
  positive(s.engaged_turns, "screw.engaged_turns");
  positive(s.breakaway_torque_nm, "screw.breakaway_torque_nm");
  non_negative(s.rundown_torque_nm, "screw.rundown_torque_nm");
  positive(s.seated_stiffness_nm_per_rad, "screw.seated_stiffness_nm_per_rad");
  non_negative(s.free_torque_nm, "screw.free_torque_nm");
  non_negative(s.loosen_ratio, "screw.loosen_ratio");
  non_negative(s.initial_preload_nm, "screw.initial_preload_nm");
  if (!(s.initial_engaged_turns >= 0.0 && s.initial_engaged_turns <= s.engaged_turns))
    throw std::invalid_argument("lst_sim.screw.initial_engaged_turns must lie in [0, engaged_turns]");
}

LstMechanism::LstMechanism(const LstMechanismParams& params) : params_(params) {
  validate(params_);
  state_.engaged_turns = params_.screw.initial_engaged_turns;
  state_.preload_nm = params_.screw.initial_preload_nm;
}

double LstMechanism::load_torque(bool loosen) const noexcept {
  const ScrewParams& s = params_.screw;
  if (!socket_engaged_) return s.free_torque_nm;
  if (loosen) {
    if (state_.engaged_turns <= 0.0) return s.free_torque_nm;
    return broken_loose_ ? s.breakaway_torque_nm : std::max(s.breakaway_torque_nm, s.loosen_ratio * state_.preload_nm);
  }
  if (state_.engaged_turns < s.engaged_turns) return s.rundown_torque_nm;
  return std::max(state_.preload_nm, s.rundown_torque_nm);
}

double LstMechanism::turn(bool loosen, double angle_rad, double limit_nm, bool& limited) noexcept {
  const ScrewParams& s = params_.screw;
  limited = false;
  if (!socket_engaged_) {
    if (s.free_torque_nm > limit_nm) {
      limited = true;
      return 0.0;
    }
    return angle_rad;
  }
  double remaining = angle_rad;
  double turned = 0.0;
  if (loosen) {
    if (state_.engaged_turns > 0.0) {
      if (load_torque(true) > limit_nm) {
        limited = true;
        return 0.0;
      }
      broken_loose_ = true;
      state_.preload_nm = 0.0;
      // The last turn of thread frees it exactly: engaged - (engaged * 2pi) / 2pi
      // can leave ~1e-16 turns engaged in floating point, which would read as
      // "not free". (A screw left engaged after loosening by the full count
      // was a different cause: the tool's turns counter rounding to the
      // nearest count, lst::turns_to_counts.)
      const double left = state_.engaged_turns * kTwoPi;
      if (remaining <= left) {  // still engaged, or just freed
        state_.engaged_turns -= remaining / kTwoPi;
        if (state_.engaged_turns < 1e-9) state_.engaged_turns = 0.0;  // freed: no rounding residue
        return angle_rad;
      }
      turned += left;
      remaining -= left;
      state_.engaged_turns = 0.0;  // freed
    }
    if (s.free_torque_nm > limit_nm) {
      limited = true;
      return turned;
    }
    return turned + remaining;
  }
  // tighten
  if (state_.engaged_turns < s.engaged_turns) {
    if (s.rundown_torque_nm > limit_nm) {
      limited = true;
      return 0.0;
    }
    const double d = std::min(remaining, (s.engaged_turns - state_.engaged_turns) * kTwoPi);
    state_.engaged_turns += d / kTwoPi;
    turned += d;
    remaining -= d;
    if (remaining <= 0.0 && state_.engaged_turns < s.engaged_turns) return turned;
    state_.engaged_turns = s.engaged_turns;  // seated: the head is on its seat
    state_.preload_nm = s.rundown_torque_nm;
    broken_loose_ = false;
  }
  // Seated: the torque rises with the angle turned past seating.
  if (state_.preload_nm >= limit_nm) {
    limited = true;
    return turned;
  }
  broken_loose_ = false;
  const double to_limit = (limit_nm - state_.preload_nm) / s.seated_stiffness_nm_per_rad;
  if (remaining >= to_limit) {
    state_.preload_nm = limit_nm;
    limited = true;
    return turned + to_limit;
  }
  state_.preload_nm += s.seated_stiffness_nm_per_rad * remaining;
  return turned + remaining;
}

bool LstMechanism::step(const LstCommand& cmd, double dt_s) noexcept {
  if (!(dt_s >= 0.0) || !std::isfinite(dt_s)) return false;  // dt = 0: edges only
  state_.time_s += dt_s;

  // Latch: travels at 1 / latch_travel_s towards the commanded end.
  const double target = cmd.latch ? 1.0 : 0.0;
  if (state_.latch_position != target) {
    if (latch_stuck_) {
      latch_wait_s_ += dt_s;
      if (latch_wait_s_ >= 2.0 * params_.latch_travel_s) state_.fault_bits |= hw::lst::kFaultLatch;
    } else {
      const double d = dt_s / params_.latch_travel_s;
      state_.latch_position = target > state_.latch_position ? std::min(target, state_.latch_position + d)
                                                             : std::max(target, state_.latch_position - d);
    }
  } else {
    latch_wait_s_ = 0.0;
  }
  state_.latched = state_.latch_position >= 1.0;
  state_.unlatched = state_.latch_position <= 0.0;

  // Run: a rising RUN starts a run; the tool ends it by itself on the torque
  // limit or a fault, and then wants RUN cleared.
  bool stopped = false;
  const bool rising = cmd.run && !prev_run_;
  prev_run_ = cmd.run;
  if (!cmd.run) run_active_ = false;
  if (rising) {
    state_.torque_reached = false;
    state_.peak_torque_nm = 0.0;
    stall_s_ = 0.0;
    run_active_ = state_.fault_bits == 0;
    if (!run_active_) stopped = true;  // refused while faulted
  }
  if (run_active_ && state_.fault_bits != 0) {
    run_active_ = false;
    stopped = true;
  }
  state_.speed_rad_s = 0.0;
  state_.torque_nm = 0.0;
  const double sign = cmd.loosen ? -1.0 : 1.0;
  const double speed = std::clamp(cmd.speed_rad_s, 0.0, params_.max_speed_rad_s);
  const double limit = std::clamp(cmd.torque_limit_nm, 0.0, params_.max_torque_nm);
  if (run_active_ && speed > 0.0) {
    if (jam_) {
      stall_s_ += dt_s;
      if (stall_s_ >= params_.stall_time_s) {
        state_.fault_bits |= hw::lst::kFaultJam;
        run_active_ = false;
        stopped = true;
      }
    } else {
      stall_s_ = 0.0;
      bool limited = false;
      const double angle = turn(cmd.loosen, speed * dt_s, limit, limited);
      state_.turns += sign * angle / kTwoPi;
      state_.torque_nm = sign * std::min(load_torque(cmd.loosen), limit);
      if (limited) {
        state_.torque_reached = true;
        run_active_ = false;
        stopped = true;
      } else if (dt_s > 0.0) {
        state_.speed_rad_s = sign * angle / dt_s;
      } else {
        state_.speed_rad_s = sign * speed;
      }
    }
  }
  if (std::abs(state_.torque_nm) > std::abs(state_.peak_torque_nm)) state_.peak_torque_nm = state_.torque_nm;
  state_.running = run_active_;
  return stopped;
}

// ---- config --------------------------------------------------------------------

LstMechanismParams load_lst_mechanism_params(const std::string& path) {
  using yaml::line_of;
  const YAML::Node root = yaml::load_file(path, "cannot open the scene file");
  const YAML::Node sec = yaml::section(root, "lst_sim", path, "simulated LST and screw");
  LstMechanismParams p;
  p.max_speed_rad_s = yaml::number_or(sec, "max_speed_rad_s", p.max_speed_rad_s, path, "lst_sim.");
  p.max_torque_nm = yaml::number_or(sec, "max_torque_nm", p.max_torque_nm, path, "lst_sim.");
  p.latch_travel_s = yaml::number_or(sec, "latch_travel_s", p.latch_travel_s, path, "lst_sim.");
  p.stall_time_s = yaml::number_or(sec, "stall_time_s", p.stall_time_s, path, "lst_sim.");
  const YAML::Node screw = sec["screw"];
  if (screw) {
    if (!screw.IsMap()) throw InputError(path, line_of(screw), "lst_sim.screw: expected a map");
    ScrewParams& s = p.screw;
    const std::string pre = "lst_sim.screw.";
    s.engaged_turns = yaml::number_or(screw, "engaged_turns", s.engaged_turns, path, pre);
    s.breakaway_torque_nm = yaml::number_or(screw, "breakaway_torque_nm", s.breakaway_torque_nm, path, pre);
    s.rundown_torque_nm = yaml::number_or(screw, "rundown_torque_nm", s.rundown_torque_nm, path, pre);
    s.seated_stiffness_nm_per_rad =
        yaml::number_or(screw, "seated_stiffness_nm_per_rad", s.seated_stiffness_nm_per_rad, path, pre);
    s.free_torque_nm = yaml::number_or(screw, "free_torque_nm", s.free_torque_nm, path, pre);
    s.loosen_ratio = yaml::number_or(screw, "loosen_ratio", s.loosen_ratio, path, pre);
    s.initial_engaged_turns = yaml::number_or(screw, "initial_engaged_turns", s.engaged_turns, path, pre);
    s.initial_preload_nm = yaml::number_or(screw, "initial_preload_nm", s.initial_preload_nm, path, pre);
  }
  try {
    validate(p);
  } catch (const std::invalid_argument& e) {
    throw InputError(path, line_of(sec), e.what());
  }
  return p;
}

}  // namespace foresight::sim
