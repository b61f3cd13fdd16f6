// The clicked-points CSV (n,cam,x,y,z,u,v and the arm-as-fixture form
// n,cam,link,lx,ly,lz,q1..qN,u,v), resolved with the URDF model and forward
// kinematics, then checked against the paper's viewport, as `calibrate` and
// `localize` read it.
#include "foresight/calibration/correspondence.hpp"
#include "foresight/calibration/robot_points.hpp"
#include "foresight/common/robot_model.hpp"
#include "fuzz_support.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const foresight::RobotModel model = foresight::RobotModel::from_file(FORESIGHT_CONFIG_DIR "/robot.urdf");
  static const foresight::calibration::RobotLinkPoints robot(model);
  foresight::fuzz::expect_input_errors([&] {
    const auto points = foresight::calibration::parse_correspondences_csv(foresight::fuzz::text_of(data, size), "fuzz.csv", &robot);
    foresight::calibration::check_in_viewport(points, foresight::camera::Viewport{}, "fuzz.csv");
    (void)foresight::calibration::to_csv(points);
  });
  return 0;
}
