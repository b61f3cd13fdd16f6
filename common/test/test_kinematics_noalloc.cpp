// The real-time half of the kinematics contract: with a pre-built workspace,
// forward_kinematics, jacobian and gravity_torques never touch the heap,
// counted through both operator new and malloc (foresight/test/allocation_counter.hpp:
// Eigen and KDL's Eigen-backed arrays allocate through malloc).

#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

#include "foresight/common/kinematics.hpp"
#include "foresight/common/robot_model.hpp"
#include "foresight/test/allocation_counter.hpp"

using namespace foresight;
using foresight::test::AllocationCounter;

TEST(KinematicsNoAlloc, CounterSeesAllocations) {
  // The guard itself must work, or the tests below prove nothing.
  long seen = 0;
  {
    AllocationCounter counter;
    auto* v = new std::vector<double>(100);  // operator new, twice
    seen = counter.count();
    delete v;
  }
  EXPECT_EQ(seen, 2);
  {
    AllocationCounter counter;
    Eigen::VectorXd x(50);  // Eigen: malloc
    x.setZero();
    seen = counter.count();
  }
  EXPECT_EQ(seen, 1);
}

TEST(KinematicsNoAlloc, FkJacobianGravityDoNotAllocate) {
  const RobotModel model = RobotModel::from_file(FORESIGHT_CONFIG_DIR "/robot.urdf");
  KinematicsWorkspace ws(model);
  const int n = model.dof();
  // Inputs prepared before counting.
  std::mt19937 rng(5);
  std::vector<Eigen::VectorXd> qs;
  for (int k = 0; k < 1000; ++k) {
    Eigen::VectorXd q(n);
    for (int i = 0; i < n; ++i) {
      std::uniform_real_distribution<double> u(model.limits()[i].lower_rad, model.limits()[i].upper_rad);
      q[i] = u(rng);
    }
    qs.push_back(q);
  }
  Eigen::Matrix<double, 6, Eigen::Dynamic> J(6, n);
  Eigen::VectorXd tau(n);
  const int ft = model.link_index("ft_sensor");
  double checksum = 0.0;
  long allocations = 0;
  {
    AllocationCounter counter;
    for (const Eigen::VectorXd& q : qs) {
      const Pose tip = forward_kinematics(model, ws, q);
      const Pose sensor = forward_kinematics(model, ws, q, ft);
      jacobian(model, ws, q, J);
      jacobian(model, ws, q, J, ft);
      gravity_torques(model, ws, q, tau);
      checksum += tip.translation().x() + sensor.translation().z() + J(0, 0) + tau[1];
    }
    allocations = counter.count();
  }
  EXPECT_EQ(allocations, 0) << "the real-time kinematics allocated";
  EXPECT_TRUE(std::isfinite(checksum));
}
