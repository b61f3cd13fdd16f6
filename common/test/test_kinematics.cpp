// FK, Jacobian, gravity torques and IK of the Foresight arm (config/robot.urdf)
// against independent answers: hand-computed poses, central finite
// differences, the potential energy, and FK round trips.

#include <gtest/gtest.h>
#include <kdl/chain.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <random>
#include <thread>
#include <vector>

#include "foresight/common/kinematics.hpp"
#include "foresight/common/object_model.hpp"
#include "foresight/common/robot_model.hpp"
#include "foresight/common/scene.hpp"

using namespace foresight;

namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kDeg = kPi / 180.0;

const RobotModel& arm() {
  static const RobotModel model = RobotModel::from_file(FORESIGHT_CONFIG_DIR "/robot.urdf");
  return model;
}

Eigen::VectorXd random_in_limits(const RobotModel& m, std::mt19937& rng) {
  Eigen::VectorXd q(m.dof());
  for (int i = 0; i < m.dof(); ++i) {
    std::uniform_real_distribution<double> u(m.limits()[i].lower_rad, m.limits()[i].upper_rad);
    q[i] = u(rng);
  }
  return q;
}

/// Rotation vector w with R_b = exp([w]x) R_a (base frame).
Eigen::Vector3d rotation_vector(const Eigen::Matrix3d& R_a, const Eigen::Matrix3d& R_b) {
  const Eigen::AngleAxisd aa(R_b * R_a.transpose());
  return aa.angle() * aa.axis();
}

}  // namespace

TEST(Kinematics, ModelHasSevenJointsAndTheToolChain) {
  const RobotModel& m = arm();
  ASSERT_EQ(m.dof(), 7);
  EXPECT_EQ(m.links().front().name, "base");
  EXPECT_EQ(m.links().back().name, "lst_tip");
  EXPECT_EQ(m.tip_index(), m.link_index("lst_tip"));
  EXPECT_GT(m.link_index("ft_sensor"), m.link_index("link7"));
  EXPECT_EQ(m.link_index("nope"), -1);
}

TEST(Kinematics, ForwardKinematicsHandComputed) {
  const RobotModel& m = arm();
  KinematicsWorkspace ws(m);
  Eigen::VectorXd q = Eigen::VectorXd::Zero(7);
  // Zero configuration: straight up. Heights along the chain (URDF joint origins):
  // 0.22 + 0.16 + 0.18 + 0.42 + 0.16 + 0.38 + 0.10 + 0.07 + 0.035 + 0.26; the
  // elbow offsets (+0.07, -0.07) cancel.
  Pose T = forward_kinematics(m, ws, q);
  EXPECT_LT((T.translation() - Eigen::Vector3d(0, 0, 1.985)).norm(), 1e-12);
  EXPECT_LT((T.linear() - Eigen::Matrix3d::Identity()).norm(), 1e-12);
  // The elbow pitch axis origin (link4) sits at the 7 cm offset.
  T = forward_kinematics(m, ws, q, m.link_index("link4"));
  EXPECT_LT((T.translation() - Eigen::Vector3d(0.07, 0, 0.98)).norm(), 1e-12);
  EXPECT_LT((forward_kinematics(m, ws, q, 0).matrix() - Eigen::Matrix4d::Identity()).norm(), 1e-15);

  // Shoulder pitch +90 deg: the arm (1.605 m from the shoulder at z = 0.38) lies along +x.
  q[1] = kPi / 2;
  T = forward_kinematics(m, ws, q);
  EXPECT_LT((T.translation() - Eigen::Vector3d(1.605, 0, 0.38)).norm(), 1e-12);
  EXPECT_LT((T.linear() - Eigen::AngleAxisd(kPi / 2, Eigen::Vector3d::UnitY()).toRotationMatrix()).norm(), 1e-12);

  // Elbow +90 deg: from the elbow axis (0.07, 0, 0.98) the rest of the arm,
  // (-0.07, 0, 1.005) at zero, turns about y: Ry(90) (-0.07, 0, 1.005) = (1.005, 0, 0.07).
  q.setZero();
  q[3] = kPi / 2;
  T = forward_kinematics(m, ws, q);
  EXPECT_LT((T.translation() - Eigen::Vector3d(1.075, 0, 1.05)).norm(), 1e-12);

  // Shoulder roll +90 deg carries that to +y; the tool roll only spins the tip about its own axis.
  q[0] = kPi / 2;
  q[6] = kPi / 3;
  T = forward_kinematics(m, ws, q);
  EXPECT_LT((T.translation() - Eigen::Vector3d(0, 1.075, 1.05)).norm(), 1e-12);
  const Eigen::Matrix3d R_expected = Eigen::AngleAxisd(kPi / 2, Eigen::Vector3d::UnitZ()).toRotationMatrix() *
                                     Eigen::AngleAxisd(kPi / 2, Eigen::Vector3d::UnitY()).toRotationMatrix() *
                                     Eigen::AngleAxisd(kPi / 3, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  EXPECT_LT((T.linear() - R_expected).norm(), 1e-12);
}

TEST(Kinematics, JacobianMatchesFiniteDifferencesOfFk) {
  const RobotModel& m = arm();
  KinematicsWorkspace ws(m);
  std::mt19937 rng(7);
  const double h = 1e-6;
  Eigen::Matrix<double, 6, Eigen::Dynamic> J(6, m.dof());
  for (int link : {-1, m.link_index("ft_sensor"), m.link_index("link5"), m.link_index("link2")}) {
    for (int trial = 0; trial < 50; ++trial) {
      const Eigen::VectorXd q = random_in_limits(m, rng);
      jacobian(m, ws, q, J, link);
      for (int i = 0; i < m.dof(); ++i) {
        Eigen::VectorXd qp = q, qm = q;
        qp[i] += h;
        qm[i] -= h;
        const Pose Tp = forward_kinematics(m, ws, qp, link);
        const Pose Tm = forward_kinematics(m, ws, qm, link);
        const Eigen::Vector3d v = (Tp.translation() - Tm.translation()) / (2 * h);
        const Eigen::Vector3d w = rotation_vector(Tm.linear(), Tp.linear()) / (2 * h);
        EXPECT_LT((J.col(i).head<3>() - v).norm(), 1e-7) << "link " << link << " joint " << i;
        EXPECT_LT((J.col(i).tail<3>() - w).norm(), 1e-7) << "link " << link << " joint " << i;
      }
    }
  }
  // Joints beyond the link do not move it: zero columns.
  jacobian(m, ws, random_in_limits(m, rng), J, m.link_index("link2"));
  EXPECT_EQ(J.rightCols(5).norm(), 0.0);
  EXPECT_GT(J.col(0).norm() + J.col(1).norm(), 0.5);
}

TEST(Kinematics, ForwardKinematicsOfEveryLinkIsConsistentAlongTheChain) {
  // FK of link k equals FK of link k-1 times the segment's own transform.
  const RobotModel& m = arm();
  KinematicsWorkspace ws(m);
  std::mt19937 rng(3);
  const Eigen::VectorXd q = random_in_limits(m, rng);
  int j = 0;
  for (int k = 1; k <= m.tip_index(); ++k) {
    const KDL::Segment& seg = m.chain().getSegment(k - 1);
    const bool moving = seg.getJoint().getType() != KDL::Joint::None;
    const KDL::Frame f = seg.pose(moving ? q[j] : 0.0);
    if (moving) ++j;
    Pose step = Pose::Identity();
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 3; ++c) step.linear()(r, c) = f.M(r, c);
      step.translation()[r] = f.p[r];
    }
    const Pose expected = forward_kinematics(m, ws, q, k - 1) * step;
    EXPECT_LT((forward_kinematics(m, ws, q, k).matrix() - expected.matrix()).norm(), 1e-12) << m.links()[k].name;
  }
  EXPECT_EQ(j, 7);
}

TEST(Kinematics, GravityTorquesAreTheGradientOfPotentialEnergy) {
  const RobotModel& m = arm();
  KinematicsWorkspace ws(m);
  // V(q) = -sum_k m_k g . c_k(q), c_k the centre of mass of link k in the base frame.
  const auto potential = [&](const Eigen::VectorXd& q) {
    double V = 0.0;
    for (int k = 1; k <= m.tip_index(); ++k) {
      const KDL::RigidBodyInertia& I = m.chain().getSegment(k - 1).getInertia();
      const Eigen::Vector3d cog_link(I.getCOG().x(), I.getCOG().y(), I.getCOG().z());
      V -= I.getMass() * m.gravity().dot(forward_kinematics(m, ws, q, k) * cog_link);
    }
    return V;
  };
  double total_mass = 0.0;
  for (const auto& l : m.links()) total_mass += l.mass_kg;
  EXPECT_NEAR(total_mass, 9.0 + 6.0 + 9.0 + 5.0 + 6.0 + 2.0 + 1.2 + 0.35 + 2.6, 1e-12);  // arm + sensor + tool

  std::mt19937 rng(11);
  Eigen::VectorXd tau(m.dof());
  const double h = 1e-6;
  for (int trial = 0; trial < 50; ++trial) {
    const Eigen::VectorXd q = random_in_limits(m, rng);
    gravity_torques(m, ws, q, tau);
    for (int i = 0; i < m.dof(); ++i) {
      Eigen::VectorXd qp = q, qm = q;
      qp[i] += h;
      qm[i] -= h;
      EXPECT_NEAR(tau[i], (potential(qp) - potential(qm)) / (2 * h), 1e-5) << "joint " << i;
    }
    EXPECT_NEAR(tau[0], 0.0, 1e-9);  // the base roll axis is vertical
  }
  // Known case, upright: only the COMs off the arm axis load the pitch joints. Shoulder (x = 0):
  // link3 COM at x = 0.01 (9 kg), link4 COM at 0.07 - 0.04 (5 kg), the LST COM at 0.015 (2.6 kg).
  // Elbow (x = 0.07): link4 at -0.04, link5 .. lst (12.15 kg) on the axis x = 0, i.e. at -0.07,
  // plus the LST's own 0.015. Wrist pitch (x = 0): the LST only.
  gravity_torques(m, ws, Eigen::VectorXd::Zero(7), tau);
  Eigen::VectorXd tau_expected = Eigen::VectorXd::Zero(7);
  tau_expected[1] = -9.81 * (9.0 * 0.01 + 5.0 * 0.03 + 2.6 * 0.015);  // holding torque = -(x m g) about +y
  tau_expected[3] = -9.81 * (5.0 * -0.04 + 12.15 * -0.07 + 2.6 * 0.015);
  tau_expected[5] = -9.81 * (2.6 * 0.015);
  EXPECT_LT((tau - tau_expected).norm(), 1e-9) << tau.transpose();
  Eigen::VectorXd q = Eigen::VectorXd::Zero(7);
  q[1] = kPi / 2;
  gravity_torques(m, ws, q, tau);
  // Lever arms: COM heights above the shoulder in the upright pose become x distances.
  const double moment = 6.0 * 0.08 + 9.0 * (0.18 + 0.24) + 5.0 * (0.60 + 0.08) + 6.0 * (0.76 + 0.20) +
                        2.0 * (1.14 + 0.05) + 1.2 * (1.24 + 0.035) + 0.35 * (1.31 + 0.0175) + 2.6 * (1.345 + 0.09);
  EXPECT_NEAR(tau[1], -9.81 * moment, 1e-9);  // gravity pulls the arm down: rotation about +y towards -z
}

TEST(Kinematics, InverseKinematicsRoundTripOnThousandRandomPoses) {
  const RobotModel& m = arm();
  KinematicsWorkspace ws(m);
  std::mt19937 rng(2026);
  const int kPoses = 1000;
  int ok = 0;
  std::vector<double> times_us;
  double worst_pos = 0.0, worst_rot = 0.0;
  for (int n = 0; n < kPoses; ++n) {
    const Eigen::VectorXd q_true = random_in_limits(m, rng);
    const Eigen::VectorXd seed = random_in_limits(m, rng);
    const Pose target = forward_kinematics(m, ws, q_true);
    IkOptions opt;
    opt.random_seed = static_cast<unsigned>(n);
    const auto t0 = std::chrono::steady_clock::now();
    const IkResult r = inverse_kinematics(m, ws, target, seed, opt);
    times_us.push_back(std::chrono::duration<double, std::micro>(std::chrono::steady_clock::now() - t0).count());
    ASSERT_EQ(r.q.size(), 7);
    EXPECT_TRUE(m.within_limits(r.q)) << "pose " << n;
    // Check the answer with the KDL FK, not the solver's own sweep.
    const Pose T = forward_kinematics(m, ws, r.q);
    const double pos = (T.translation() - target.translation()).norm();
    const double rot = rotation_distance(T.linear(), target.linear());
    EXPECT_NEAR(pos, r.position_error_m, 1e-9);
    EXPECT_NEAR(rot, r.rotation_error_rad, 1e-7);
    if (r.success) {
      EXPECT_LE(pos, opt.position_tolerance_m + 1e-12);
      EXPECT_LE(rot, opt.rotation_tolerance_rad + 1e-12);
    }
    if (r.success && pos <= 1e-3 && rot <= 0.1 * kDeg && m.within_limits(r.q)) {
      ++ok;
      worst_pos = std::max(worst_pos, pos);
      worst_rot = std::max(worst_rot, rot);
    }
  }
  std::sort(times_us.begin(), times_us.end());
  std::printf("IK: %d/%d within 1 mm / 0.1 deg; median %.1f us, p99 %.1f us, max %.1f us; worst %.2e m %.2e rad\n",
              ok, kPoses, times_us[kPoses / 2], times_us[kPoses * 99 / 100], times_us.back(), worst_pos, worst_rot);
  EXPECT_GE(ok, 995);
}

TEST(Kinematics, InverseKinematicsUnreachableReportsFailureAndResidual) {
  const RobotModel& m = arm();
  KinematicsWorkspace ws(m);
  // 3 m in front of the base: the tip reaches at most 1.605 m from the shoulder (0, 0, 0.38).
  const Pose target = make_pose(Eigen::Vector3d(3.0, 0.0, 0.5), Eigen::Vector3d::Zero());
  IkOptions opt;
  opt.max_restarts = 10;
  const IkResult r = inverse_kinematics(m, ws, target, m.mid_configuration(), opt);
  EXPECT_FALSE(r.success);
  EXPECT_EQ(r.attempts, 11);
  ASSERT_EQ(r.q.size(), 7);
  EXPECT_TRUE(m.within_limits(r.q));
  const double shoulder_distance = (target.translation() - Eigen::Vector3d(0, 0, 0.38)).norm();
  EXPECT_GE(r.position_error_m, shoulder_distance - 1.605 - 1e-9);
  // The residual is the one of the returned configuration.
  const Pose T = forward_kinematics(m, ws, r.q);
  EXPECT_NEAR((T.translation() - target.translation()).norm(), r.position_error_m, 1e-9);
  EXPECT_NEAR(rotation_distance(T.linear(), target.linear()), r.rotation_error_rad, 1e-7);

  // Reachable position, but an orientation the wrist cannot take there: the
  // tool pointing back at the base from 1.5 m out needs the arm to fold past its limits.
  const Pose behind = make_pose(Eigen::Vector3d(1.55, 0.0, 0.38), Eigen::Vector3d(0.0, -kPi / 2, 0.0));
  const IkResult r2 = inverse_kinematics(m, ws, behind, m.mid_configuration(), opt);
  EXPECT_FALSE(r2.success);
  EXPECT_GT(r2.position_error_m + r2.rotation_error_rad, 1e-3);
}

TEST(Kinematics, InverseKinematicsIsDeterministicAndSeeded) {
  const RobotModel& m = arm();
  KinematicsWorkspace ws(m);
  std::mt19937 rng(99);
  const Eigen::VectorXd q_true = random_in_limits(m, rng);
  const Pose target = forward_kinematics(m, ws, q_true);
  const IkResult a = inverse_kinematics(m, ws, target, random_in_limits(m, rng));
  KinematicsWorkspace ws2(m);
  std::mt19937 rng2(99);
  random_in_limits(m, rng2);
  const IkResult b = inverse_kinematics(m, ws2, target, random_in_limits(m, rng2));
  ASSERT_TRUE(a.success);
  EXPECT_EQ((a.q - b.q).norm(), 0.0);
  EXPECT_EQ(a.attempts, b.attempts);
  // Seeded at the answer: it is returned at once, unchanged.
  const IkResult c = inverse_kinematics(m, ws, target, q_true);
  EXPECT_TRUE(c.success);
  EXPECT_EQ(c.attempts, 1);
  EXPECT_LT((c.q - q_true).norm(), 1e-12);
  // A small move from a known configuration stays on the same branch (close to the seed).
  Eigen::VectorXd q_near = q_true;
  q_near.array() += 0.02;
  if (m.within_limits(q_near)) {
    const IkResult d = inverse_kinematics(m, ws, forward_kinematics(m, ws, q_near), q_true);
    EXPECT_TRUE(d.success);
    EXPECT_LT((d.q - q_true).cwiseAbs().maxCoeff(), 0.1);
  }
}

TEST(Kinematics, InverseKinematicsOfAnIntermediateLink) {
  const RobotModel& m = arm();
  KinematicsWorkspace ws(m);
  std::mt19937 rng(5);
  const int ft = m.link_index("ft_sensor");
  int ok = 0;
  for (int n = 0; n < 50; ++n) {
    const Pose target = forward_kinematics(m, ws, random_in_limits(m, rng), ft);
    const IkResult r = inverse_kinematics(m, ws, target, random_in_limits(m, rng), IkOptions{}, ft);
    const Pose T = forward_kinematics(m, ws, r.q, ft);
    if (r.success && (T.translation() - target.translation()).norm() < 1e-3 &&
        rotation_distance(T.linear(), target.linear()) < 0.1 * kDeg)
      ++ok;
  }
  EXPECT_EQ(ok, 50);
}

TEST(Kinematics, CentredIkKeepsThePoseAndWidensTheMargins) {
  const RobotModel& m = arm();
  KinematicsWorkspace ws(m);
  std::mt19937 rng(17);
  const auto margin = [&](const Eigen::VectorXd& q) {
    double mm = 1e9;
    for (int i = 0; i < m.dof(); ++i)
      mm = std::min({mm, q[i] - m.limits()[i].lower_rad, m.limits()[i].upper_rad - q[i]});
    return mm;
  };
  int wider = 0;
  for (int n = 0; n < 100; ++n) {
    const Eigen::VectorXd q_true = random_in_limits(m, rng);
    const Pose target = forward_kinematics(m, ws, q_true);
    IkOptions opt;
    opt.centre_joints = true;
    const IkResult r = inverse_kinematics(m, ws, target, q_true, opt);  // starts at a solution
    ASSERT_TRUE(r.success);
    const Pose T = forward_kinematics(m, ws, r.q);
    EXPECT_LE((T.translation() - target.translation()).norm(), opt.position_tolerance_m);
    EXPECT_LE(rotation_distance(T.linear(), target.linear()), opt.rotation_tolerance_rad);
    EXPECT_TRUE(m.within_limits(r.q));
    // The seeded solution itself is a candidate: never worse than q_true.
    EXPECT_GE(margin(r.q), margin(q_true) - 1e-9);
    if (margin(r.q) > margin(q_true) + 1 * kDeg) ++wider;
  }
  EXPECT_GE(wider, 80);  // random configurations are mostly close to some limit
}

TEST(Kinematics, BadArgumentsGiveNanOrThrow) {
  const RobotModel& m = arm();
  KinematicsWorkspace ws(m);
  const Eigen::VectorXd q6 = Eigen::VectorXd::Zero(6);
  const Eigen::VectorXd q7 = Eigen::VectorXd::Zero(7);
  // Real-time functions cannot throw: wrong sizes or link indices give NaN.
  EXPECT_TRUE(std::isnan(forward_kinematics(m, ws, q6).translation().x()));
  EXPECT_TRUE(std::isnan(forward_kinematics(m, ws, q7, m.tip_index() + 1).translation().x()));
  Eigen::Matrix<double, 6, Eigen::Dynamic> J(6, 7);
  jacobian(m, ws, q6, J);
  EXPECT_TRUE(J.array().isNaN().all());
  Eigen::VectorXd tau(7);
  gravity_torques(m, ws, q6, tau);
  EXPECT_TRUE(tau.array().isNaN().all());
  // ... and a valid call afterwards works again.
  EXPECT_NEAR(forward_kinematics(m, ws, q7).translation().z(), 1.985, 1e-12);
  // IK is set-up code: it throws.
  const Pose target = forward_kinematics(m, ws, q7);
  EXPECT_THROW(inverse_kinematics(m, ws, target, q6), std::invalid_argument);
  EXPECT_THROW(inverse_kinematics(m, ws, target, q7, IkOptions{}, 0), std::invalid_argument);
  EXPECT_THROW(inverse_kinematics(m, ws, target, q7, IkOptions{}, 99), std::invalid_argument);
  Pose bad = target;
  bad.translation().x() = NAN;
  EXPECT_THROW(inverse_kinematics(m, ws, bad, q7), std::invalid_argument);
}

TEST(Kinematics, OneModelManyThreadsEachWithItsWorkspace) {
  const RobotModel& m = arm();
  std::mt19937 rng(23);
  std::vector<Eigen::VectorXd> qs;
  for (int k = 0; k < 2000; ++k) qs.push_back(random_in_limits(m, rng));
  std::vector<Pose> expected;
  {
    KinematicsWorkspace ws(m);
    for (const auto& q : qs) expected.push_back(forward_kinematics(m, ws, q));
  }
  std::vector<int> mismatches(4, 0);
  std::vector<std::thread> threads;
  for (int t = 0; t < 4; ++t) {
    threads.emplace_back([&, t] {
      KinematicsWorkspace ws(m);
      Eigen::Matrix<double, 6, Eigen::Dynamic> J(6, m.dof());
      for (int pass = 0; pass < 5; ++pass) {
        for (std::size_t k = 0; k < qs.size(); ++k) {
          jacobian(m, ws, qs[(k + t) % qs.size()], J);  // interleave other work on the same workspace
          if (!forward_kinematics(m, ws, qs[k]).isApprox(expected[k], 1e-14)) ++mismatches[t];
        }
      }
    });
  }
  for (auto& th : threads) th.join();
  for (int t = 0; t < 4; ++t) EXPECT_EQ(mismatches[t], 0) << "thread " << t;
}

TEST(Kinematics, WorkspaceCanBeMoved) {
  const RobotModel& m = arm();
  KinematicsWorkspace a(m);
  KinematicsWorkspace b(std::move(a));
  KinematicsWorkspace c(m);
  c = std::move(b);
  EXPECT_NEAR(forward_kinematics(m, c, Eigen::VectorXd::Zero(7)).translation().z(), 1.985, 1e-12);
}

// ---- a workspace belongs to its model (as Pinocchio's model.check(data)) ----

TEST(KinematicsWorkspace, RefusesAnotherModel) {
  const RobotModel arm = RobotModel::from_file(FORESIGHT_CONFIG_DIR "/robot.urdf");
  // Same joint count, different kinematics: the shoulder link 5 cm longer.
  std::vector<double> delta(arm.segment_count(), 0.0);
  delta[2] = 0.05;
  const RobotModel longer = arm.with_link_lengths_changed(delta);
  ASSERT_EQ(longer.dof(), arm.dof());
  KinematicsWorkspace ws(arm);
  EXPECT_TRUE(check(arm, ws));
  const RobotModel copy = arm;  // a copy is the same model
  EXPECT_TRUE(check(copy, ws));
  EXPECT_FALSE(check(longer, ws));

  const Eigen::VectorXd q = arm.mid_configuration();
  // The mismatch used to compute the workspace's model (arm) silently.
  EXPECT_FALSE(forward_kinematics(longer, ws, q).matrix().allFinite());
  Eigen::Matrix<double, 6, Eigen::Dynamic> J(6, arm.dof());
  jacobian(longer, ws, q, J);
  EXPECT_FALSE(J.allFinite());
  Eigen::VectorXd tau(arm.dof());
  gravity_torques(longer, ws, q, tau);
  EXPECT_FALSE(tau.allFinite());
  try {
    inverse_kinematics(longer, ws, forward_kinematics(arm, ws, q), q);
    ADD_FAILURE() << "no error";
  } catch (const std::invalid_argument& e) {
    EXPECT_EQ(std::string(e.what()), "inverse_kinematics: the workspace was built for another robot model (" +
                                         std::string(FORESIGHT_CONFIG_DIR "/robot.urdf") + " is not its model)");
  }
  // The right workspace still works for both.
  EXPECT_TRUE(forward_kinematics(arm, ws, q).matrix().allFinite());
  KinematicsWorkspace ws_longer(longer);
  EXPECT_TRUE(forward_kinematics(longer, ws_longer, q).matrix().allFinite());
}

TEST(RobotModel, LinkLengthChangeMovesTheTipByExactlyThatMuch) {
  // One offset longer by d: the tip moves by d along that offset's direction
  // (a rigid motion of everything after it), |dp| = d at every q.
  const RobotModel arm = RobotModel::from_file(FORESIGHT_CONFIG_DIR "/robot.urdf");
  KinematicsWorkspace ws(arm);
  std::mt19937 rng(9);
  const std::vector<int> offsets = arm.offset_segments();
  ASSERT_GE(offsets.size(), 3u);
  for (unsigned k = 0; k < static_cast<unsigned>(arm.segment_count()); ++k) {
    const bool listed = std::find(offsets.begin(), offsets.end(), static_cast<int>(k)) != offsets.end();
    if (!listed) {
      // A segment without an offset is not listed, and a change to it changes nothing.
      EXPECT_LT(arm.chain().getSegment(k).getFrameToTip().p.Norm(), RobotModel::kMinOffset_m) << "segment " << k;
      std::vector<double> delta(arm.segment_count(), 0.0);
      delta[k] = 0.002;
      const RobotModel same = arm.with_link_lengths_changed(delta);
      KinematicsWorkspace ws_same(same);
      const Eigen::VectorXd q = arm.mid_configuration();
      EXPECT_LT((forward_kinematics(same, ws_same, q).translation() - forward_kinematics(arm, ws, q).translation()).norm(),
                1e-15)
          << "segment " << k;
      continue;
    }
    std::vector<double> delta(arm.segment_count(), 0.0);
    delta[k] = 0.002;
    const RobotModel changed = arm.with_link_lengths_changed(delta);
    EXPECT_NE(changed.id(), arm.id());
    KinematicsWorkspace wc(changed);
    for (int t = 0; t < 5; ++t) {
      Eigen::VectorXd q(arm.dof());
      for (int i = 0; i < arm.dof(); ++i)
        q[i] = std::uniform_real_distribution<double>(arm.limits()[i].lower_rad, arm.limits()[i].upper_rad)(rng);
      const Eigen::Vector3d dp =
          forward_kinematics(changed, wc, q).translation() - forward_kinematics(arm, ws, q).translation();
      EXPECT_NEAR(dp.norm(), 0.002, 1e-12) << "segment " << k;
    }
  }
  EXPECT_THROW(arm.with_link_lengths_changed({0.1}), std::invalid_argument);
}
