// Trajectory CSV (t,q1..qN): the parser, then the remote's validation rules
// against the arm's limits and the content hash, as `foresight validate` and
// `send` run them on a file an operator hands in.
#include "foresight/common/robot_model.hpp"
#include "foresight/common/trajectory.hpp"
#include "fuzz_support.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const foresight::TrajectoryLimits limits =
      foresight::TrajectoryLimits::from_model(foresight::RobotModel::from_file(FORESIGHT_CONFIG_DIR "/robot.urdf"));
  foresight::fuzz::expect_input_errors([&] {
    const foresight::Trajectory t = foresight::parse_trajectory_csv(foresight::fuzz::text_of(data, size), "fuzz.csv");
    (void)foresight::validate(t, limits);
    (void)foresight::to_hex(foresight::trajectory_hash(t));
  });
  return 0;
}
