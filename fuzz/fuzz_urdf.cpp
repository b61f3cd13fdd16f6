// URDF loading (urdfdom -> our KDL chain, limits, inertias), then forward
// kinematics at the middle of the limits, as `foresight robot` and the
// daemon do with config/robot.urdf.
#include "foresight/common/kinematics.hpp"
#include "foresight/common/robot_model.hpp"
#include "fuzz_support.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  foresight::fuzz::expect_input_errors([&] {
    const auto model = foresight::RobotModel::from_xml(foresight::fuzz::text_of(data, size), "fuzz.urdf");
    foresight::KinematicsWorkspace ws(model);
    (void)foresight::forward_kinematics(model, ws, model.mid_configuration());
  });
  return 0;
}
