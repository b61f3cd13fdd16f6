// INVOKE_ALGORITHM parameters (issue 26): every parameter of every real-time
// algorithm has a range from the task and the arm; a value outside it, a
// non-finite one, an unknown name or a timeout beyond 600 s is refused with
// the parameter, the value and the range, before anything is queued. The
// edges of each range are accepted.
#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "foresight/daemon/algorithm_params.hpp"

using namespace foresight;

namespace {

std::string parse(const std::string& name, std::vector<protocol::NamedValue> params, double timeout_s = 0.0) {
  protocol::InvokeAlgorithm invoke;
  invoke.name = name;
  invoke.params = std::move(params);
  invoke.timeout_s = timeout_s;
  control::AlgorithmParams out;
  return daemon::parse_algorithm(invoke, out);
}

struct Range {
  const char* algorithm;
  const char* name;
  double lo, hi;
  const char* unit;
};

// The ranges as the operator reads them in docs/control.md.
const Range kRanges[] = {
    {"guarded_move", "direction_x", -1.0, 1.0, ""},
    {"guarded_move", "speed_m_s", 1e-4, 0.1, "m/s"},
    {"guarded_move", "force_threshold_n", 0.5, 150.0, "N"},
    {"guarded_move", "max_distance_m", 1e-3, 0.5, "m"},
    {"insert", "depth_m", 1e-3, 0.2, "m"},
    {"insert", "depth_tolerance_m", 0.0, 0.02, "m"},
    {"insert", "speed_m_s", 1e-4, 0.1, "m/s"},
    {"insert", "contact_force_n", 0.5, 100.0, "N"},
    {"insert", "lateral_stiffness_n_m", 10.0, 20000.0, "N/m"},
    {"insert", "rotational_stiffness_nm_rad", 0.5, 500.0, "N m/rad"},
    {"insert", "lateral_damping_n_s_m", 0.0, 60000.0, "N s/m"},
    {"insert", "rotational_damping_nm_s_rad", 0.0, 500.0, "N m s/rad"},
    {"insert", "stall_time_s", 0.05, 10.0, "s"},
    {"insert", "spiral_pitch_m", 1e-4, 0.005, "m"},
    {"insert", "spiral_speed_m_s", 1e-4, 0.05, "m/s"},
    {"insert", "spiral_max_radius_m", 1e-4, 0.02, "m"},
    {"pull_out", "distance_m", 1e-3, 0.5, "m"},
    {"pull_out", "speed_m_s", 1e-4, 0.1, "m/s"},
    {"pull_out", "max_force_n", 1.0, 150.0, "N"},
    {"identify_payload", "angle_rad", 1e-4, 0.5, "rad"},
    {"identify_payload", "move_s", 0.2, 30.0, "s"},
    {"identify_payload", "settle_s", 0.0, 10.0, "s"},
    {"identify_payload", "window_s", 0.01, 10.0, "s"},
    {"identify_payload", "max_contact_n", 0.1, 100.0, "N"},
    {"identify_payload", "max_condition", 2.0, 1e6, ""},
    {"identify_payload", "max_residual_n", 0.01, 100.0, "N"},
};

std::string expected(const Range& r, const char* value) {
  char buf[200];
  std::snprintf(buf, sizeof buf, "%s: %s %s out of range [%g, %g]%s%s", r.algorithm, r.name, value, r.lo, r.hi,
                *r.unit ? " " : "", r.unit);
  return buf;
}

}  // namespace

TEST(AlgorithmParams, EveryParameterOutsideItsRangeIsRefusedNamingIt) {
  for (const Range& r : kRanges) {
    SCOPED_TRACE(std::string(r.algorithm) + " " + r.name);
    EXPECT_EQ(parse(r.algorithm, {{r.name, 1e300}}), expected(r, "1e+300"));
    EXPECT_EQ(parse(r.algorithm, {{r.name, -1e300}}), expected(r, "-1e+300"));
    if (r.lo > 0.0) {
      EXPECT_EQ(parse(r.algorithm, {{r.name, 1e-300}}), expected(r, "1e-300"));
      EXPECT_EQ(parse(r.algorithm, {{r.name, 0.0}}), expected(r, "0"));
    }
  }
}

TEST(AlgorithmParams, TheEdgesOfEachRangeAreAccepted) {
  for (const Range& r : kRanges) {
    SCOPED_TRACE(std::string(r.algorithm) + " " + r.name);
    // Alone at an edge, the other parameters at their defaults; the
    // controller's own cross-checks (max_force_n > contact_force_n, a
    // non-zero direction) may refuse an edge alone, so pair them.
    std::vector<protocol::NamedValue> lo{{r.name, r.lo}}, hi{{r.name, r.hi}};
    if (std::string(r.name) == "contact_force_n") hi.push_back({"max_force_n", 150.0});
    if (std::string(r.name) == "direction_x") {
      lo.push_back({"direction_z", 0.0});
      hi.push_back({"direction_z", 0.0});
    }
    EXPECT_EQ(parse(r.algorithm, lo), "");
    EXPECT_EQ(parse(r.algorithm, hi), "");
  }
}

TEST(AlgorithmParams, NotFiniteUnknownAndTimeout) {
  EXPECT_EQ(parse("insert", {{"depth_m", std::nan("")}}), "insert: parameter 'depth_m' is not finite");
  EXPECT_EQ(parse("pull_out", {{"depth_m", 0.05}}).rfind("pull_out: unknown parameter 'depth_m' (expected one of: ", 0),
            0u);
  EXPECT_EQ(parse("insert", {}, 1e300), "insert: timeout_s 1e+300 out of range [0, 600] s (0: the default)");
  EXPECT_EQ(parse("insert", {}, -1.0), "insert: timeout_s -1 out of range [0, 600] s (0: the default)");
  EXPECT_EQ(parse("insert", {}, 600.0), "");
  EXPECT_EQ(parse("guarded_move", {{"frame_base", 0.5}}), "guarded_move: frame_base must be 0 (tool frame) or 1 (base frame)");
  // The controller's own cross-check still runs after the ranges.
  EXPECT_EQ(parse("insert", {{"contact_force_n", 50.0}, {"max_force_n", 40.0}}),
            "insert: max_force_n must be > contact_force_n");
}
