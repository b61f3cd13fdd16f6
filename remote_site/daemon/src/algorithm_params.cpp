#include "foresight/remote/algorithm_params.hpp"

#include <cmath>
#include <cstdio>
#include <utility>
#include <vector>

#include "foresight/control/algorithms.hpp"

namespace foresight::remote {

namespace {

struct Field {
  const char* name;
  double* value;
};

std::string parse_fields(const std::string& algorithm, const std::vector<control::NamedValue>& params,
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
    *hit->value = p.value;
  }
  return {};
}

}  // namespace

std::string parse_algorithm(const control::InvokeAlgorithm& invoke, control::AlgorithmParams& out) {
  out = control::AlgorithmParams{};
  out.kind = control::algorithm_from_name(invoke.name.c_str());
  const std::string& n = invoke.name;
  std::string error;
  switch (out.kind) {
    case control::AlgorithmKind::GuardedMove: {
      auto& g = out.guarded_move;
      double frame_base = g.frame == control::TaskFrame::Base ? 1.0 : 0.0;
      error = parse_fields(n, invoke.params,
                           {{"direction_x", &g.direction[0]},
                            {"direction_y", &g.direction[1]},
                            {"direction_z", &g.direction[2]},
                            {"frame_base", &frame_base},
                            {"speed_m_s", &g.speed_m_s},
                            {"force_threshold_n", &g.force_threshold_n},
                            {"max_distance_m", &g.max_distance_m}});
      if (!error.empty()) return error;
      if (frame_base != 0.0 && frame_base != 1.0) return n + ": frame_base must be 0 (tool frame) or 1 (base frame)";
      g.frame = frame_base == 1.0 ? control::TaskFrame::Base : control::TaskFrame::Tool;
      if (invoke.timeout_s > 0.0) g.timeout_s = invoke.timeout_s;
      break;
    }
    case control::AlgorithmKind::Insert: {
      auto& i = out.insert;
      error = parse_fields(n, invoke.params,
                           {{"depth_m", &i.depth_m},
                            {"depth_tolerance_m", &i.depth_tolerance_m},
                            {"speed_m_s", &i.speed_m_s},
                            {"contact_force_n", &i.contact_force_n},
                            {"max_force_n", &i.max_force_n},
                            {"lateral_stiffness_n_m", &i.lateral_stiffness_n_m},
                            {"rotational_stiffness_nm_rad", &i.rotational_stiffness_nm_rad},
                            {"stall_time_s", &i.stall_time_s},
                            {"spiral_pitch_m", &i.spiral_pitch_m},
                            {"spiral_speed_m_s", &i.spiral_speed_m_s},
                            {"spiral_max_radius_m", &i.spiral_max_radius_m}});
      if (!error.empty()) return error;
      if (invoke.timeout_s > 0.0) i.timeout_s = invoke.timeout_s;
      break;
    }
    case control::AlgorithmKind::PullOut: {
      auto& o = out.pull_out;
      error = parse_fields(n, invoke.params,
                           {{"distance_m", &o.distance_m},
                            {"speed_m_s", &o.speed_m_s},
                            {"max_force_n", &o.max_force_n},
                            {"lateral_stiffness_n_m", &o.lateral_stiffness_n_m},
                            {"rotational_stiffness_nm_rad", &o.rotational_stiffness_nm_rad}});
      if (!error.empty()) return error;
      if (invoke.timeout_s > 0.0) o.timeout_s = invoke.timeout_s;
      break;
    }
    case control::AlgorithmKind::None:
      return "unknown algorithm '" + n + "'";
  }
  if (!(invoke.timeout_s >= 0.0) || !std::isfinite(invoke.timeout_s)) return n + ": timeout_s must be >= 0";
  // The controller's own range checks, off the real-time thread, so a bad
  // parameter is REJECTED before anything is queued.
  control::AlgorithmRunner probe;
  control::Reason code{};
  std::array<char, 96> text{};
  if (!probe.start(out, Pose::Identity(), 500.0, code, text)) return std::string(text.data());
  return {};
}

}  // namespace foresight::remote
