#pragma once
// A small dense Levenberg-Marquardt (Marquardt's diagonal scaling) for the
// 6-, 7- and 6+7k-parameter problems of calibration and localization: the
// one nonlinear least-squares solver of the estimation libraries (calibration
// owns it; localization and the accuracy study use it through this header).
// Set-up code, not real-time: allocates vectors sized per problem; never
// throws (a failed fit is LmReport::converged == false, and callers report
// "did not converge after N iterations").
//
// Convergence (MINPACK's and Ceres' tests; each is checked only where it
// means something, never against the damping):
// - gradient: the undamped Gauss-Newton step would lower the cost by no more
//   than gradient_tolerance * cost (scale-free: the Newton decrement);
// - function: an accepted step (one that lowered the cost) lowered it by no
//   more than function_tolerance * cost;
// - parameter: an accepted step is <= parameter_tolerance * (|x| + parameter_tolerance),
//   |x| from the caller's `norm(state)`;
// - zero residual: cost <= zero_cost.
// When no damping makes the cost decrease, the solver has stalled: converged
// only if the Gauss-Newton step is itself negligible (parameter test), else
// LmStop::NoDecrease. Running out of iterations is LmStop::MaxIterations.
// Only the first four count as converged.

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <algorithm>
#include <cmath>

namespace foresight::calibration {

enum class LmStop { Gradient, Function, Parameter, ZeroResidual, NoDecrease, MaxIterations };

inline const char* to_string(LmStop s) {
  switch (s) {
    case LmStop::Gradient: return "gradient tolerance";
    case LmStop::Function: return "function tolerance";
    case LmStop::Parameter: return "parameter tolerance";
    case LmStop::ZeroResidual: return "zero residual";
    case LmStop::NoDecrease: return "no step decreases the cost";
    case LmStop::MaxIterations: return "iteration limit";
  }
  return "?";
}

struct LmOptions {
  int max_iterations = 100;
  double gradient_tolerance = 1e-12;   ///< relative to the cost (Newton decrement)
  double function_tolerance = 1e-10;   ///< relative cost decrease of an accepted step
  double parameter_tolerance = 1e-10;  ///< relative step length
  double zero_cost = 1e-28;            ///< absolute: 0.5 |e|^2 at or below this is a zero residual
};

struct LmReport {
  int iterations = 0;
  double cost = 0.0;  ///< 0.5 * sum of squared residuals at the solution
  LmStop stop = LmStop::MaxIterations;
  bool converged = false;
};

/// Problem: `evaluate(state, e, J)` fills residuals e and, when J is not
/// null, the Jacobian de/dparams (m x P); `retract(state, delta)` returns the
/// state moved by delta; `norm(state)` a size of the parameters in the units
/// of delta (for the relative step test). Residuals are predicted minus
/// measured. P may be Eigen::Dynamic, with the count in `params`.
template <int P, class State, class Evaluate, class Retract, class Norm>
LmReport levenberg_marquardt(State& state, int residuals, Evaluate&& evaluate, Retract&& retract, Norm&& norm,
                             const LmOptions& opt, int params = P) {
  using MatP = Eigen::Matrix<double, P, P>;
  using VecP = Eigen::Matrix<double, P, 1>;
  constexpr int kMaxTries = 30;  // damping grows 8x a try: 8^30 ~ 1e27
  Eigen::VectorXd e(residuals), e_new(residuals);
  Eigen::Matrix<double, Eigen::Dynamic, P> J(residuals, params);
  evaluate(state, e, &J);
  double cost = 0.5 * e.squaredNorm();
  double mu = 1e-4;
  LmReport rep;
  auto finish = [&](LmStop stop) {
    rep.stop = stop;
    rep.converged = stop != LmStop::NoDecrease && stop != LmStop::MaxIterations;
    rep.cost = cost;
    return rep;
  };
  auto small_step = [&](double step, const State& x) {
    const double tol = opt.parameter_tolerance;
    return step <= tol * (norm(x) + tol);
  };
  for (int it = 0; it < opt.max_iterations; ++it) {
    if (!std::isfinite(cost)) return finish(LmStop::NoDecrease);
    if (cost <= opt.zero_cost) return finish(LmStop::ZeroResidual);
    rep.iterations = it + 1;
    const MatP H = J.transpose() * J;
    const VecP g = J.transpose() * e;
    // The undamped (Gauss-Newton) step and what it would gain.
    MatP Hr = H;
    for (int i = 0; i < params; ++i) Hr(i, i) += 1e-14 * std::max(H(i, i), 1e-300);
    const VecP gn = -Hr.ldlt().solve(g);
    const double gn_decrease = gn.allFinite() ? -0.5 * g.dot(gn) : INFINITY;
    if (gn_decrease <= opt.gradient_tolerance * cost) return finish(LmStop::Gradient);
    bool accepted = false;
    for (int tries = 0; tries < kMaxTries && !accepted; ++tries) {
      MatP A = H;
      for (int i = 0; i < params; ++i) A(i, i) += mu * std::max(H(i, i), 1e-12);
      const VecP delta = -A.ldlt().solve(g);
      if (!delta.allFinite()) {
        mu *= 10.0;
        continue;
      }
      State candidate = retract(state, delta);
      evaluate(candidate, e_new, nullptr);
      const double cost_new = 0.5 * e_new.squaredNorm();
      if (std::isfinite(cost_new) && cost_new < cost) {  // strictly: an unchanged cost is no progress
        const double decrease = cost - cost_new;
        state = candidate;
        accepted = true;
        mu = std::max(mu / 5.0, 1e-12);
        const double before = cost;
        cost = cost_new;
        evaluate(state, e, &J);
        if (decrease <= opt.function_tolerance * before) return finish(LmStop::Function);
        if (small_step(delta.norm(), state)) return finish(LmStop::Parameter);
      } else {
        mu *= 8.0;
      }
    }
    if (!accepted)  // stalled: at the minimum to rounding only if Gauss-Newton would not move either
      return finish(gn.allFinite() && small_step(gn.norm(), state) ? LmStop::Parameter : LmStop::NoDecrease);
  }
  if (cost <= opt.zero_cost) return finish(LmStop::ZeroResidual);
  return finish(LmStop::MaxIterations);
}

}  // namespace foresight::calibration
