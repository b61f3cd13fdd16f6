#pragma once
// The simulated LST mechanics and the ORU's retaining screw, stepped in time.
// Pure physics, no I/O: the Modbus server (lst_server.hpp) maps registers to
// LstCommand / LstToolState and calls LstMechanism::step; tests step it with
// an explicit dt. step() is noexcept and does not allocate (RT-safe).
//
// Screw (bolt holding the ORU in its slot), state = engaged thread turns e in
// [0, N] (N = engaged_turns; e = N: seated) and the seated preload torque P:
//  - loosening while engaged (e > 0) needs breakaway_torque_nm T for every one
//    of the N turns (a prevailing-torque locking thread), and at the first
//    movement max(T, loosen_ratio x P); e falls by the turns made; at e = 0
//    the screw is free and only free_torque_nm resists;
//  - tightening a screw that is not seated needs rundown_torque_nm; e rises
//    until seated; then the torque rises with the angle turned past seating,
//    P = seated_stiffness_nm_per_rad x angle, until P reaches the tool's
//    torque limit: the run stops there ("tightened to the target torque").
// Tool: an ideal speed-controlled motor with a torque limit. If the load
// torque exceeds the limit the output does not turn, the tool stops and
// reports TORQUE_REACHED. Jam injection: the output cannot turn although the
// torque stays below the limit; after stall_time_s the tool stops with the JAM
// fault. The turns counter integrates the output speed over time. The latch
// travels between open and closed in latch_travel_s; a stuck latch (injected)
// raises the LATCH fault after 2 x latch_travel_s.

#include <cstdint>
#include <string>

namespace foresight::sim {

struct ScrewParams {
  double engaged_turns = 8.0;                 ///< N: thread turns engaged when seated
  double breakaway_torque_nm = 15.0;          ///< T: torque to turn the engaged screw loose-wards
  double rundown_torque_nm = 2.0;             ///< torque to run the unseated screw in
  double seated_stiffness_nm_per_rad = 40.0;  ///< torque rise per radian past seating
  double free_torque_nm = 0.05;               ///< drag of a free (disengaged) screw
  double loosen_ratio = 0.8;                  ///< breakaway of a preloaded screw: max(T, ratio x P)
  double initial_engaged_turns = 8.0;         ///< start state (default: seated)
  double initial_preload_nm = 0.0;
};

struct LstMechanismParams {
  double max_speed_rad_s = 20.0;  ///< the tool refuses SPEED_CMD above this
  double max_torque_nm = 60.0;    ///< the tool refuses TORQUE_LIMIT above this
  double latch_travel_s = 0.3;    ///< open <-> closed
  double stall_time_s = 0.2;      ///< jam detection time
  ScrewParams screw;
};

/// Check the parameters; throws std::invalid_argument naming the field.
void validate(const LstMechanismParams& params);

/// Load the `lst_sim:` section of config/scene.yaml (keys as the fields above,
/// the screw under `screw:`). Throws InputError naming file, line and key.
LstMechanismParams load_lst_mechanism_params(const std::string& scene_yaml_path);

struct LstCommand {
  bool run = false;
  bool loosen = false;            ///< DIRECTION
  bool latch = false;             ///< LATCH: true = close
  double speed_rad_s = 0.0;       ///< magnitude
  double torque_limit_nm = 0.0;
};

struct LstToolState {
  // tool
  bool running = false;
  bool torque_reached = false;
  bool latched = false;    ///< end switch: closed
  bool unlatched = true;   ///< end switch: open
  std::uint16_t fault_bits = 0;  ///< hw::lst::kFault*
  double latch_position = 0.0;   ///< 0 open .. 1 closed
  double turns = 0.0;            ///< + tightening
  double torque_nm = 0.0;        ///< output torque, + clockwise (tightening)
  double speed_rad_s = 0.0;      ///< output speed, + clockwise
  double peak_torque_nm = 0.0;   ///< torque of largest magnitude since RUN last rose
  double time_s = 0.0;           ///< the tool's clock
  // screw (ground truth, not visible over Modbus)
  double engaged_turns = 0.0;
  double preload_nm = 0.0;
  bool screw_free() const { return engaged_turns <= 0.0; }
  bool screw_seated(double n) const { return engaged_turns >= n; }
};

class LstMechanism {
 public:
  explicit LstMechanism(const LstMechanismParams& params);  // validates; may throw

  /// Advance by dt_s (>= 0; 0 applies command edges without moving) under `cmd`. Returns true when the tool stopped by
  /// itself during this step (torque reached or fault): the RUN coil must be
  /// cleared; a new rising RUN starts a new run. noexcept, no allocation.
  bool step(const LstCommand& cmd, double dt_s) noexcept;

  const LstToolState& state() const noexcept { return state_; }
  const LstMechanismParams& params() const noexcept { return params_; }

  void reset_fault() noexcept { state_.fault_bits = 0; }
  void reset_turns() noexcept { state_.turns = 0.0; }

  // Fault injection (simulator controls).
  void set_jam(bool jammed) noexcept { jam_ = jammed; }
  void set_latch_stuck(bool stuck) noexcept { latch_stuck_ = stuck; }
  /// False: the socket is not on the bolt (tool not inserted); it spins free.
  void set_socket_engaged(bool engaged) noexcept { socket_engaged_ = engaged; }

 private:
  /// Torque the load opposes to turning in `loosen` direction right now.
  double load_torque(bool loosen) const noexcept;
  /// Turn the screw by `angle_rad` (>= 0) in the direction, stopping early if
  /// the load torque would exceed `limit_nm`. Returns the angle turned;
  /// `limited` true when it stopped at the limit.
  double turn(bool loosen, double angle_rad, double limit_nm, bool& limited) noexcept;

  LstMechanismParams params_;
  LstToolState state_;
  bool jam_ = false;
  bool latch_stuck_ = false;
  bool socket_engaged_ = true;
  bool prev_run_ = false;
  bool run_active_ = false;   ///< a run in progress (RUN rose and the tool has not stopped)
  bool broken_loose_ = false; ///< the screw has moved loose-wards since it was seated
  double stall_s_ = 0.0;
  double latch_wait_s_ = 0.0;
};

}  // namespace foresight::sim
