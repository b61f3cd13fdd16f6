#include "foresight/daemon/algorithm_params.hpp"

#include <cmath>
#include <cstdio>
#include <utility>
#include <vector>

#include "foresight/control/algorithms.hpp"
#include "foresight/control/payload.hpp"

namespace foresight::daemon {

namespace {

/// One parameter: where it goes and the range a value must lie in (from the
/// task and the arm: the ORU's hole is 8 cm deep and its slot 10 cm, the
/// arm's Cartesian contact speeds a few cm/s, the F/T sensor's 327 N full
/// scale). A value outside is refused with the parameter, the value and the
/// range; nothing is queued.
struct Field {
  const char* name;
  double* value;
  double lo, hi;
  const char* unit;
};

std::string fmt_range(const std::string& algorithm, const Field& f, double v) {
  char buf[160];
  std::snprintf(buf, sizeof buf, ": %s %g out of range [%g, %g]%s%s", f.name, v, f.lo, f.hi, *f.unit ? " " : "",
                f.unit);
  return algorithm + buf;
}

std::string parse_fields(const std::string& algorithm, const std::vector<protocol::NamedValue>& params,
                         std::vector<Field> fields) {
  for (const auto& p : params) {
    Field* hit = nullptr;
    for (auto& f : fields)
      if (p.name == f.name) hit = &f;
    if (hit == nullptr) {
      std::string list;
      for (const auto& f : fields) list += std::string(list.empty() ? "" : ", ") + f.name;
      return algorithm + ": unknown parameter '" + p.name + "' (expected one of: " + list + ")";
    }
    if (!std::isfinite(p.value)) return algorithm + ": parameter '" + p.name + "' is not finite";
    if (!(p.value >= hit->lo && p.value <= hit->hi)) return fmt_range(algorithm, *hit, p.value);
    *hit->value = p.value;
  }
  return {};
}

}  // namespace

std::string parse_algorithm(const protocol::InvokeAlgorithm& invoke, control::AlgorithmParams& out) {
  out = control::AlgorithmParams{};
  out.kind = control::algorithm_from_name(invoke.name.c_str());
  const std::string& n = invoke.name;
  std::string error;
  switch (out.kind) {
    case control::AlgorithmKind::GuardedMove: {
      auto& g = out.guarded_move;
      double frame_base = g.frame == control::TaskFrame::Base ? 1.0 : 0.0;
      error = parse_fields(n, invoke.params,
                           {{"direction_x", &g.direction[0], -1.0, 1.0, ""},
                            {"direction_y", &g.direction[1], -1.0, 1.0, ""},
                            {"direction_z", &g.direction[2], -1.0, 1.0, ""},
                            {"frame_base", &frame_base, 0.0, 1.0, ""},
                            {"speed_m_s", &g.speed_m_s, 1e-4, 0.1, "m/s"},
                            {"force_threshold_n", &g.force_threshold_n, 0.5, 150.0, "N"},
                            {"max_distance_m", &g.max_distance_m, 1e-3, 0.5, "m"}});
      if (!error.empty()) return error;
      if (frame_base != 0.0 && frame_base != 1.0) return n + ": frame_base must be 0 (tool frame) or 1 (base frame)";
      g.frame = frame_base == 1.0 ? control::TaskFrame::Base : control::TaskFrame::Tool;
      if (invoke.timeout_s > 0.0) g.timeout_s = invoke.timeout_s;
      break;
    }
    case control::AlgorithmKind::Insert: {
      auto& i = out.insert;
      error = parse_fields(n, invoke.params,
                           {{"depth_m", &i.depth_m, 1e-3, 0.2, "m"},
                            {"depth_tolerance_m", &i.depth_tolerance_m, 0.0, 0.02, "m"},
                            {"speed_m_s", &i.speed_m_s, 1e-4, 0.1, "m/s"},
                            {"contact_force_n", &i.contact_force_n, 0.5, 100.0, "N"},
                            {"max_force_n", &i.max_force_n, 1.0, 150.0, "N"},
                            {"lateral_stiffness_n_m", &i.lateral_stiffness_n_m, 10.0, 20000.0, "N/m"},
                            {"rotational_stiffness_nm_rad", &i.rotational_stiffness_nm_rad, 0.5, 500.0, "N m/rad"},
                            {"lateral_damping_n_s_m", &i.lateral_damping_n_s_m, 0.0, 60000.0, "N s/m"},
                            {"rotational_damping_nm_s_rad", &i.rotational_damping_nm_s_rad, 0.0, 500.0, "N m s/rad"},
                            {"stall_time_s", &i.stall_time_s, 0.05, 10.0, "s"},
                            {"spiral_pitch_m", &i.spiral_pitch_m, 1e-4, 0.005, "m"},
                            {"spiral_speed_m_s", &i.spiral_speed_m_s, 1e-4, 0.05, "m/s"},
                            {"spiral_max_radius_m", &i.spiral_max_radius_m, 1e-4, 0.02, "m"}});
      if (!error.empty()) return error;
      if (invoke.timeout_s > 0.0) i.timeout_s = invoke.timeout_s;
      break;
    }
    case control::AlgorithmKind::PullOut: {
      auto& o = out.pull_out;
      error = parse_fields(n, invoke.params,
                           {{"distance_m", &o.distance_m, 1e-3, 0.5, "m"},
                            {"speed_m_s", &o.speed_m_s, 1e-4, 0.1, "m/s"},
                            {"max_force_n", &o.max_force_n, 1.0, 150.0, "N"},
                            {"lateral_stiffness_n_m", &o.lateral_stiffness_n_m, 10.0, 20000.0, "N/m"},
                            {"rotational_stiffness_nm_rad", &o.rotational_stiffness_nm_rad, 0.5, 500.0, "N m/rad"}});
      if (!error.empty()) return error;
      if (invoke.timeout_s > 0.0) o.timeout_s = invoke.timeout_s;
      break;
    }
    case control::AlgorithmKind::IdentifyPayload: {
      auto& ip = out.identify_payload;
      error = parse_fields(n, invoke.params,
                           {{"angle_rad", &ip.angle_rad, 1e-4, 0.5, "rad"},
                            {"move_s", &ip.move_s, 0.2, 30.0, "s"},
                            {"settle_s", &ip.settle_s, 0.0, 10.0, "s"},
                            {"window_s", &ip.window_s, 0.01, 10.0, "s"},
                            {"max_contact_n", &ip.max_contact_n, 0.1, 100.0, "N"},
                            {"max_condition", &ip.max_condition, 2.0, 1e6, ""},
                            {"max_residual_n", &ip.max_residual_n, 0.01, 100.0, "N"}});
      if (!error.empty()) return error;
      if (!(invoke.timeout_s >= 0.0 && invoke.timeout_s <= kMaxAlgorithmTimeoutS))
        return n + fmt_timeout(invoke.timeout_s);
      protocol::Reason code{};
      std::array<char, 96> text{};
      if (!control::PayloadIdentifier::validate(ip, code, text)) return std::string(text.data());
      return {};
    }
    case control::AlgorithmKind::None:
      return "unknown algorithm '" + n + "'";
  }
  if (!(invoke.timeout_s >= 0.0 && invoke.timeout_s <= kMaxAlgorithmTimeoutS))
    return n + fmt_timeout(invoke.timeout_s);
  // The controller's own range checks, off the real-time thread, so a bad
  // parameter is REJECTED before anything is queued.
  control::AlgorithmRunner probe;
  protocol::Reason code{};
  std::array<char, 96> text{};
  if (!probe.start(out, Pose::Identity(), 500.0, code, text)) return std::string(text.data());
  return {};
}

std::string fmt_timeout(double timeout_s) {
  char buf[96];
  std::snprintf(buf, sizeof buf, ": timeout_s %g out of range [0, %g] s (0: the default)", timeout_s,
                kMaxAlgorithmTimeoutS);
  return buf;
}

}  // namespace foresight::daemon
