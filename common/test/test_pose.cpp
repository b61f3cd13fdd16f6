#include <gtest/gtest.h>

#include <random>

#include "foresight/common/pose.hpp"

using namespace foresight;

TEST(Pose, RpyRoundTripMatchesPaperConvention) {
  // The paper's eq. 23: R = Rz(gamma) Ry(beta) Rx(alpha).
  const Eigen::Vector3d rpy(0.3, -0.7, 2.1);
  const Eigen::Matrix3d R = rotation_from_rpy(rpy);
  const Eigen::Matrix3d expected = Eigen::AngleAxisd(2.1, Eigen::Vector3d::UnitZ()).toRotationMatrix() *
                                   Eigen::AngleAxisd(-0.7, Eigen::Vector3d::UnitY()).toRotationMatrix() *
                                   Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitX()).toRotationMatrix();
  EXPECT_LT((R - expected).norm(), 1e-12);
  EXPECT_LT((rpy_from_rotation(R) - rpy).norm(), 1e-12);
}

TEST(Pose, RpyRoundTripRandom) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> a(-M_PI, M_PI), b(-M_PI / 2 + 1e-3, M_PI / 2 - 1e-3);
  for (int i = 0; i < 1000; ++i) {
    const Eigen::Vector3d rpy(a(rng), b(rng), a(rng));
    const Eigen::Matrix3d R = rotation_from_rpy(rpy);
    EXPECT_LT(rotation_distance(R, rotation_from_rpy(rpy_from_rotation(R))), 1e-9);
  }
}

TEST(Pose, GimbalLockStillReproducesRotation) {
  const Eigen::Matrix3d R = rotation_from_rpy({0.4, M_PI / 2, -0.2});
  EXPECT_LT(rotation_distance(R, rotation_from_rpy(rpy_from_rotation(R))), 1e-9);
}

TEST(Pose, NearestRotationProjectsNoisyMatrix) {
  const Eigen::Matrix3d R = rotation_from_rpy({0.1, 0.2, 0.3});
  Eigen::Matrix3d M = R;
  M(0, 1) += 0.01;
  M(2, 2) -= 0.02;
  const Eigen::Matrix3d Q = nearest_rotation(M);
  EXPECT_LT((Q.transpose() * Q - Eigen::Matrix3d::Identity()).norm(), 1e-12);
  EXPECT_NEAR(Q.determinant(), 1.0, 1e-12);
  EXPECT_LT(rotation_distance(Q, R), 0.02);
}

TEST(Pose, RotationDistance) {
  EXPECT_NEAR(rotation_distance(Eigen::Matrix3d::Identity(), rotation_from_rpy({0, 0, 0.5})), 0.5, 1e-12);
}
