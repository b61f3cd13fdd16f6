// Plant::step is documented allocation-free (it runs at every SYNC on the
// simulator thread, and in-process in benchmarks): through every ORU state.
// Own binary: the allocation counter (foresight/test/allocation_counter.hpp).
#include <gtest/gtest.h>

#include <vector>

#include "foresight/common/kinematics.hpp"
#include "foresight/common/object_model.hpp"
#include "foresight/common/robot_model.hpp"
#include "foresight/common/scene.hpp"
#include "foresight/test/allocation_counter.hpp"
#include "foresight/sim/plant.hpp"

using namespace foresight;

TEST(PlantRtSafety, StepDoesNotAllocateInAnyOruState) {
  const RobotModel robot = RobotModel::from_file(FORESIGHT_CONFIG_DIR "/robot.urdf");
  const ObjectModel oru = ObjectModel::from_file(FORESIGHT_CONFIG_DIR "/oru.yaml");
  const Pose base_T_oru = Scene::from_file(FORESIGHT_CONFIG_DIR "/scene.yaml").base_T_object;
  sim::Plant plant(robot, oru, base_T_oru, sim::load_plant_params(FORESIGHT_CONFIG_DIR "/scene.yaml"));
  KinematicsWorkspace ws(robot);
  // A path: 6 cm into the hole, out 15 cm and back (joints by IK, set-up).
  std::vector<std::vector<double>> path;
  Eigen::VectorXd seed = robot.mid_configuration();
  for (int i = 0; i <= 40; ++i) {
    const double z = i <= 20 ? 0.06 - 0.15 * i / 20.0 : -0.09 + 0.15 * (i - 20) / 20.0;
    const IkResult ik = inverse_kinematics(robot, ws, base_T_oru * Pose(Eigen::Translation3d(0.0005, 0.0, z)), seed);
    ASSERT_TRUE(ik.success);
    seed = ik.q;
    path.emplace_back(ik.q.data(), ik.q.data() + ik.q.size());
  }
  const std::vector<double> qd(path[0].size(), 0.01);
  sim::LstToolState tool;
  tool.engaged_turns = 8.0;
  plant.step(path[0], qd, tool);  // first call outside the window

  double sum = 0.0;
  foresight::test::AllocationCounter counter;
  tool.latched = true;
  sum += plant.step(path[0], qd, tool).wrench_ft[2];  // gripped
  tool.engaged_turns = 0.0;
  sum += plant.step(path[0], qd, tool).wrench_ft[2];  // loose: seated
  for (const auto& q : path) sum += plant.step(q, qd, tool).wrench_ft[2];  // carried and back
  tool.engaged_turns = 8.0;
  sum += plant.step(path.back(), qd, tool).wrench_ft[2];  // fastened
  const sim::OruState final_state = plant.truth().state;  // copies a Pose, no heap
  counter.pause();
  EXPECT_EQ(counter.count(), 0);
  EXPECT_EQ(final_state, sim::OruState::Fastened);
  EXPECT_TRUE(std::isfinite(sum));
}
