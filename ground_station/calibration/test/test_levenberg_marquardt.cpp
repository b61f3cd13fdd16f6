// The Levenberg-Marquardt solver's convergence report: converged only when a
// convergence test holds, never because the damping grew until the step
// vanished; the iteration limit and a stall are reported as such.
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "foresight/calibration/levenberg_marquardt.hpp"

using foresight::calibration::levenberg_marquardt;
using foresight::calibration::LmOptions;
using foresight::calibration::LmStop;
using Vec2 = Eigen::Matrix<double, 2, 1>;

namespace {

/// y = a exp(b x) on x = 0..1, a = 2, b = -1.5, with optional noise.
struct ExpFit {
  std::vector<double> x, y;
  explicit ExpFit(double noise) {
    std::mt19937 rng(3);
    std::normal_distribution<double> n(0.0, noise);
    for (int i = 0; i < 20; ++i) {
      x.push_back(i / 19.0);
      y.push_back(2.0 * std::exp(-1.5 * x.back()) + (noise > 0 ? n(rng) : 0.0));
    }
  }
  /// `jacobian_sign` -1 gives a wrong Jacobian (every step uphill).
  auto evaluate(double jacobian_sign = 1.0) const {
    return [this, jacobian_sign](const Vec2& p, Eigen::VectorXd& e, Eigen::Matrix<double, Eigen::Dynamic, 2>* J) {
      for (std::size_t i = 0; i < x.size(); ++i) {
        const double ex = std::exp(p[1] * x[i]);
        e[static_cast<Eigen::Index>(i)] = p[0] * ex - y[i];
        if (J) J->row(static_cast<Eigen::Index>(i)) << jacobian_sign * ex, jacobian_sign * p[0] * x[i] * ex;
      }
    };
  }
  int m() const { return static_cast<int>(x.size()); }
};

const auto kRetract = [](const Vec2& p, const Vec2& d) -> Vec2 { return p + d; };
const auto kNorm = [](const Vec2& p) { return p.norm(); };

}  // namespace

TEST(LevenbergMarquardt, NoiseFreeConvergesToTheTruth) {
  const ExpFit f(0.0);
  Vec2 p(1.0, 0.0);
  const auto rep = levenberg_marquardt<2>(p, f.m(), f.evaluate(), kRetract, kNorm, LmOptions{});
  EXPECT_TRUE(rep.converged) << to_string(rep.stop);
  EXPECT_NEAR(p[0], 2.0, 1e-9);
  EXPECT_NEAR(p[1], -1.5, 1e-9);
  EXPECT_LT(rep.iterations, 50);
}

TEST(LevenbergMarquardt, NoisyConvergesToTheLeastSquaresMinimum) {
  const ExpFit f(0.01);
  Vec2 p(1.0, 0.0);
  const auto rep = levenberg_marquardt<2>(p, f.m(), f.evaluate(), kRetract, kNorm, LmOptions{});
  ASSERT_TRUE(rep.converged) << to_string(rep.stop);
  EXPECT_NE(rep.stop, LmStop::ZeroResidual);
  // At the minimum the gradient J^T e vanishes (relative to its scale; the
  // function tolerance, 1e-10 of the cost, leaves it near 1e-8 here).
  Eigen::VectorXd e(f.m());
  Eigen::Matrix<double, Eigen::Dynamic, 2> J(f.m(), 2);
  f.evaluate()(p, e, &J);
  EXPECT_LT((J.transpose() * e).norm(), 1e-6 * J.norm() * e.norm());
}

TEST(LevenbergMarquardt, AWrongJacobianIsNotConvergence) {
  // Every step goes uphill: no damping helps. The solver used to declare
  // convergence after 20 rejected steps; it must say it found no decrease.
  const ExpFit f(0.01);
  Vec2 p(1.0, 0.0);
  const auto rep = levenberg_marquardt<2>(p, f.m(), f.evaluate(-1.0), kRetract, kNorm, LmOptions{});
  EXPECT_FALSE(rep.converged);
  EXPECT_EQ(rep.stop, LmStop::NoDecrease);
  EXPECT_EQ(p, Vec2(1.0, 0.0));  // nothing accepted
}

TEST(LevenbergMarquardt, TheIterationLimitIsNotConvergence) {
  const ExpFit f(0.01);
  Vec2 p(1.0, 0.0);
  LmOptions opt;
  opt.max_iterations = 2;
  const auto rep = levenberg_marquardt<2>(p, f.m(), f.evaluate(), kRetract, kNorm, opt);
  EXPECT_FALSE(rep.converged);
  EXPECT_EQ(rep.stop, LmStop::MaxIterations);
  EXPECT_EQ(rep.iterations, 2);
}
