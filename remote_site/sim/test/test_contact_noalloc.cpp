// ContactModel::compute and LstMechanism::step are documented RT-safe: they
// must not touch the heap. Own binary: counts operator new AND malloc inside
// a window (foresight/test/allocation_counter.hpp; Eigen allocates through malloc).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <vector>

#include "foresight/common/object_model.hpp"
#include "foresight/common/scene.hpp"
#include "foresight/sim/contact_model.hpp"
#include "foresight/sim/screw_model.hpp"
#include "foresight/test/allocation_counter.hpp"

using foresight::test::AllocationCounter;
using namespace foresight;
using namespace foresight::sim;

TEST(RtSafety, TheCounterCounts) {
  long seen = 0;
  {
    AllocationCounter counter;
    std::vector<double>* v = new std::vector<double>(100);  // the vector object and its buffer
    Eigen::VectorXd x(50);                                  // Eigen: malloc
    x.setZero();
    seen = counter.count();
    delete v;
  }
  EXPECT_EQ(seen, 3);
}

TEST(RtSafety, ContactComputeDoesNotAllocate) {
  const ObjectModel oru = ObjectModel::from_file(FORESIGHT_CONFIG_DIR "/oru.yaml");
  const Pose base_T_oru = Scene::from_file(FORESIGHT_CONFIG_DIR "/scene.yaml").base_T_object;
  const ContactModel model(oru, load_contact_params(FORESIGHT_CONFIG_DIR "/scene.yaml"));
  Twist v;
  v.v_m_s = Eigen::Vector3d(0.01, -0.02, 0.005);
  v.w_rad_s = Eigen::Vector3d(0.1, 0.0, -0.2);
  double sum = 0.0;
  long allocations = 0;
  {
    AllocationCounter counter;
    for (int i = 0; i < 1000; ++i) {
      // Sweep through face, rim, wall and bottom contacts.
      const double z = -0.01 + 0.1 * i / 1000.0;
      const double x = 0.002 * std::sin(0.05 * i);
      Pose oru_T_tip(Eigen::Translation3d(x, 0.0, z));
      oru_T_tip.linear() = Eigen::AngleAxisd(0.03 * std::cos(0.02 * i), Eigen::Vector3d::UnitY()).toRotationMatrix();
      sum += model.compute(base_T_oru * oru_T_tip, base_T_oru, v).sensor.force_n.norm();
    }
    allocations = counter.count();
  }
  EXPECT_EQ(allocations, 0);
  EXPECT_GT(sum, 0.0);  // contacts did happen
}

TEST(RtSafety, ScrewStepDoesNotAllocate) {
  LstMechanism m(LstMechanismParams{});
  LstCommand cmd;
  cmd.run = true;
  cmd.loosen = true;
  cmd.latch = true;
  cmd.speed_rad_s = 20.0;
  cmd.torque_limit_nm = 40.0;
  long allocations = 0;
  {
    AllocationCounter counter;
    for (int i = 0; i < 5000; ++i) m.step(cmd, 1e-3);
    allocations = counter.count();
  }
  EXPECT_EQ(allocations, 0);
  EXPECT_TRUE(m.state().screw_free());
}
