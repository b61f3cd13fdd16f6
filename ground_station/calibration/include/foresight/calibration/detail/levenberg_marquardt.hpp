#pragma once
// A small dense Levenberg-Marquardt (Marquardt's diagonal scaling) for the
// 6- and 7-parameter problems of calibration and localization. Internal to
// the estimation libraries. Not real-time code (vectors sized per problem).

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <cmath>

namespace foresight::detail {

struct LmReport {
  int iterations = 0;
  double cost = 0.0;  ///< 0.5 * sum of squared residuals at the solution
  bool converged = false;
};

/// Problem: `evaluate(state, e, J)` fills residuals e (m) and, when J is not
/// null, the Jacobian de/dparams (m x P); `retract(state, delta)` returns the
/// state moved by delta. Residuals are predicted minus measured. P may be
/// Eigen::Dynamic, with the count in `params`.
template <int P, class State, class Evaluate, class Retract>
LmReport levenberg_marquardt(State& state, int residuals, Evaluate&& evaluate, Retract&& retract, int max_iterations,
                             int params = P) {
  using MatP = Eigen::Matrix<double, P, P>;
  using VecP = Eigen::Matrix<double, P, 1>;
  Eigen::VectorXd e(residuals), e_new(residuals);
  Eigen::Matrix<double, Eigen::Dynamic, P> J(residuals, params);
  evaluate(state, e, &J);
  double cost = 0.5 * e.squaredNorm();
  double mu = 1e-4;
  LmReport rep;
  for (int it = 0; it < max_iterations; ++it) {
    rep.iterations = it + 1;
    const MatP H = J.transpose() * J;
    const VecP g = J.transpose() * e;
    bool accepted = false;
    for (int tries = 0; tries < 20 && !accepted; ++tries) {
      MatP A = H;
      for (int i = 0; i < params; ++i) A(i, i) += mu * std::max(H(i, i), 1e-12);
      const VecP delta = -A.ldlt().solve(g);
      if (!delta.allFinite()) {
        mu *= 10.0;
        continue;
      }
      // The model's predicted decrease: nothing left to gain (to rounding).
      const double predicted = -g.dot(delta) - 0.5 * delta.dot(H * delta);
      if (predicted <= 1e-14 * cost || cost < 1e-28) {
        rep.converged = true;
        rep.cost = cost;
        return rep;
      }
      State candidate = retract(state, delta);
      evaluate(candidate, e_new, nullptr);
      const double cost_new = 0.5 * e_new.squaredNorm();
      if (std::isfinite(cost_new) && cost_new <= cost) {
        const double decrease = cost - cost_new;
        state = candidate;
        accepted = true;
        mu = std::max(mu / 5.0, 1e-12);
        // Converged: the step no longer changes the cost or the parameters.
        const bool small_step = delta.norm() < 1e-13 * (1.0 + delta.norm());
        cost = cost_new;
        evaluate(state, e, &J);
        if (decrease <= 1e-10 * cost || small_step || cost < 1e-28) {
          rep.converged = true;
          rep.cost = cost;
          return rep;
        }
      } else {
        mu *= 8.0;
      }
    }
    if (!accepted) {  // no decrease possible: at the minimum to numerical precision
      rep.converged = true;
      break;
    }
  }
  rep.cost = cost;
  return rep;
}

}  // namespace foresight::detail
