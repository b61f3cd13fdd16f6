// Kinematics of a RobotModel. FK, Jacobian and gravity go through KDL solvers
// held in the workspace (each workspace owns a copy of the chain: KDL::Joint
// caches its last pose in mutable members, so two threads must never share a
// chain). IK runs its own combined FK + Jacobian pass (one sweep, fixed-size
// Eigen) inside a damped least-squares (Levenberg-Marquardt) loop with joint
// limit clamping, locking of joints pushed against a limit, and deterministic
// random restarts.

#include "foresight/common/kinematics.hpp"

#include <Eigen/Cholesky>
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <kdl/chaindynparam.hpp>
#include <kdl/chainfksolverpos_recursive.hpp>
#include <kdl/chainjnttojacsolver.hpp>
#include <kdl/jacobian.hpp>
#include <kdl/jntarray.hpp>
#include <limits>
#include <stdexcept>
#include <vector>

namespace foresight {

namespace {

/// One chain segment in the form the IK sweep uses:
/// parent_T_child(q) = [R p] * Rot(axis, q) (the Rot only for revolute joints).
struct FastSegment {
  Eigen::Matrix3d R;
  Eigen::Vector3d p;
  Eigen::Vector3d axis;  // unit, in the joint frame
  bool revolute = false;
};

Pose to_pose(const KDL::Frame& f) {
  Pose T = Pose::Identity();
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) T.linear()(r, c) = f.M(r, c);
    T.translation()[r] = f.p[r];
  }
  return T;
}

Pose nan_pose() {
  Pose T;
  T.matrix().setConstant(std::numeric_limits<double>::quiet_NaN());
  return T;
}

Eigen::Matrix3d axis_rotation(const Eigen::Vector3d& a, double q) {
  const double s = std::sin(q), c = std::cos(q), v = 1.0 - c;
  Eigen::Matrix3d R;
  R << c + a.x() * a.x() * v, a.x() * a.y() * v - a.z() * s, a.x() * a.z() * v + a.y() * s,  //
      a.y() * a.x() * v + a.z() * s, c + a.y() * a.y() * v, a.y() * a.z() * v - a.x() * s,  //
      a.z() * a.x() * v - a.y() * s, a.z() * a.y() * v + a.x() * s, c + a.z() * a.z() * v;
  return R;
}

/// splitmix64: tiny, fast, deterministic; restarts need nothing better.
struct SplitMix64 {
  std::uint64_t state;
  std::uint64_t next() {
    std::uint64_t z = (state += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
  }
  double uniform() { return static_cast<double>(next() >> 11) * (1.0 / 9007199254740992.0); }
};

}  // namespace

struct KinematicsWorkspace::Impl {
  explicit Impl(const RobotModel& model)
      : model_id(model.id()),
        chain(model.chain()),
        fk(chain),
        jac(chain),
        dyn(chain, KDL::Vector(model.gravity().x(), model.gravity().y(), model.gravity().z())),
        q(chain.getNrOfJoints()),
        tau(chain.getNrOfJoints()),
        J(chain.getNrOfJoints()) {
    const int n = static_cast<int>(chain.getNrOfJoints());
    for (unsigned s = 0; s < chain.getNrOfSegments(); ++s) {
      const KDL::Segment& seg = chain.getSegment(s);
      const KDL::Frame F = seg.getFrameToTip();  // at q = 0
      FastSegment f;
      for (int r = 0; r < 3; ++r) {
        for (int c = 0; c < 3; ++c) f.R(r, c) = F.M(r, c);
        f.p[r] = F.p[r];
      }
      f.revolute = seg.getJoint().getType() != KDL::Joint::None;
      if (f.revolute) {
        // RobotModel builds every joint with its origin at F.p, axis in the parent frame.
        const KDL::Vector a = F.M.Inverse() * seg.getJoint().JointAxis();
        f.axis = Eigen::Vector3d(a.x(), a.y(), a.z()).normalized();
      } else {
        f.axis.setZero();
      }
      segments.push_back(f);
    }
    axis_w.resize(n);
    origin_w.resize(n);
    ik_J.resize(6, n);
    ik_J_try.resize(6, n);
    ik_Jw.resize(6, n);
    ik_g.resize(n);
    ik_q_pre.resize(n);
    ik_q.resize(n);
    ik_q_try.resize(n);
    ik_dq.resize(n);
    ik_best.resize(n);
    lower.resize(n);
    upper.resize(n);
    for (int i = 0; i < n; ++i) {
      lower[i] = model.limits()[i].lower_rad;
      upper[i] = model.limits()[i].upper_rad;
    }
  }

  /// base_T_link (R, p) for the first `nseg` segments; with J, also the
  /// geometric Jacobian (reference point at the link origin, base frame).
  void sweep(const Eigen::VectorXd& qv, int nseg, Eigen::Matrix3d& R, Eigen::Vector3d& p,
             Eigen::Matrix<double, 6, Eigen::Dynamic>* Jout) {
    R.setIdentity();
    p.setZero();
    int j = 0;
    for (int s = 0; s < nseg; ++s) {
      const FastSegment& g = segments[s];
      p += R * g.p;
      R = R * g.R;
      if (g.revolute) {
        if (Jout != nullptr) {
          axis_w[j] = R * g.axis;
          origin_w[j] = p;
        }
        R = R * axis_rotation(g.axis, qv[j]);
        ++j;
      }
    }
    if (Jout != nullptr) {
      Jout->setZero();
      for (int i = 0; i < j; ++i) {
        Jout->col(i).head<3>() = axis_w[i].cross(p - origin_w[i]);
        Jout->col(i).tail<3>() = axis_w[i];
      }
    }
  }

  std::uint64_t model_id;
  KDL::Chain chain;
  KDL::ChainFkSolverPos_recursive fk;
  KDL::ChainJntToJacSolver jac;
  KDL::ChainDynParam dyn;
  KDL::JntArray q;
  KDL::JntArray tau;
  KDL::Jacobian J;
  KDL::Frame frame;

  std::vector<FastSegment> segments;
  std::vector<Eigen::Vector3d> axis_w, origin_w;
  Eigen::Matrix<double, 6, Eigen::Dynamic> ik_J, ik_J_try, ik_Jw;
  Eigen::VectorXd ik_g, ik_q_pre, ik_q, ik_q_try, ik_dq, ik_best, lower, upper;
};

KinematicsWorkspace::KinematicsWorkspace(const RobotModel& model) : impl_(std::make_unique<Impl>(model)) {}
KinematicsWorkspace::~KinematicsWorkspace() = default;
KinematicsWorkspace::KinematicsWorkspace(KinematicsWorkspace&&) noexcept = default;
KinematicsWorkspace& KinematicsWorkspace::operator=(KinematicsWorkspace&&) noexcept = default;
std::uint64_t KinematicsWorkspace::model_id() const noexcept { return impl_ ? impl_->model_id : 0; }

bool check(const RobotModel& model, const KinematicsWorkspace& ws) noexcept { return ws.model_id() == model.id(); }

namespace {

/// Segment count for link index `link` (-1 = tip); -1 when out of range.
int segments_for(const RobotModel& model, int link) {
  const int nseg = model.segment_count();
  if (link < 0) return nseg;
  return link <= nseg ? link : -1;
}

bool load_q(const RobotModel& model, KinematicsWorkspace::Impl& w, const Eigen::Ref<const Eigen::VectorXd>& q) {
  if (w.model_id != model.id() || q.size() != model.dof() || w.q.rows() != static_cast<unsigned>(model.dof()))
    return false;
  w.q.data = q;
  return true;
}

}  // namespace

Pose forward_kinematics(const RobotModel& model, KinematicsWorkspace& ws, const Eigen::Ref<const Eigen::VectorXd>& q,
                        int link) noexcept {
  auto& w = ws.impl();
  const int nseg = segments_for(model, link);
  if (nseg < 0 || !load_q(model, w, q)) return nan_pose();
  if (w.fk.JntToCart(w.q, w.frame, nseg) < 0) return nan_pose();
  return to_pose(w.frame);
}

void jacobian(const RobotModel& model, KinematicsWorkspace& ws, const Eigen::Ref<const Eigen::VectorXd>& q,
              Eigen::Ref<Eigen::Matrix<double, 6, Eigen::Dynamic>> J, int link) noexcept {
  auto& w = ws.impl();
  const int nseg = segments_for(model, link);
  if (nseg < 0 || J.cols() != model.dof() || !load_q(model, w, q) || w.jac.JntToJac(w.q, w.J, nseg) < 0) {
    J.setConstant(std::numeric_limits<double>::quiet_NaN());
    return;
  }
  J = w.J.data;
}

void gravity_torques(const RobotModel& model, KinematicsWorkspace& ws, const Eigen::Ref<const Eigen::VectorXd>& q,
                     Eigen::Ref<Eigen::VectorXd> tau) noexcept {
  auto& w = ws.impl();
  if (tau.size() != model.dof() || !load_q(model, w, q) || w.dyn.JntToGravity(w.q, w.tau) < 0) {
    tau.setConstant(std::numeric_limits<double>::quiet_NaN());
    return;
  }
  tau = w.tau.data;
}

namespace {

constexpr int kMaxIterations = 40;    // per attempt; then restart (cheaper than waiting)
constexpr double kLambdaInit = 1e-2;  // LM damping (m^2 scale: the arm is ~1 m)
constexpr double kLambdaMin = 1e-9;
constexpr double kLambdaMax = 1e3;    // beyond this the attempt is stuck: restart
constexpr double kMaxStepRad = 1.0;   // largest joint step per iteration
constexpr int kCentreIterations = 40;
constexpr double kPostureSwitchRad = 2.0 * M_PI / 180.0;

struct Residual {
  Eigen::Matrix<double, 6, 1> e;  // [p_target - p; rotation vector of R_target R^T], base frame
  double position_m = 0.0;
  double rotation_rad = 0.0;
  double cost = 0.0;
};

Residual residual(const Pose& target, const Eigen::Matrix3d& R, const Eigen::Vector3d& p) {
  Residual r;
  r.e.head<3>() = target.translation() - p;
  const Eigen::AngleAxisd aa(target.linear() * R.transpose());
  r.e.tail<3>() = aa.angle() * aa.axis();
  r.position_m = r.e.head<3>().norm();
  r.rotation_rad = std::abs(aa.angle());
  r.cost = r.e.squaredNorm();
  return r;
}

void clamp_to_limits(Eigen::VectorXd& q, const Eigen::VectorXd& lo, const Eigen::VectorXd& hi) {
  q = q.cwiseMax(lo).cwiseMin(hi);
}

/// Smallest distance (rad) of any joint to either of its limits.
double min_margin(const Eigen::VectorXd& q, const Eigen::VectorXd& lo, const Eigen::VectorXd& hi) {
  return std::min((q - lo).minCoeff(), (hi - q).minCoeff());
}

/// Moves a converged solution q along the arm's self-motion manifold
/// away from the joint limits: gradient descent on the barrier
/// H(q) = sum_i 1/(q_i - lower_i)^2 + 1/(upper_i - q_i)^2 (rad; flat in the
/// middle of a range, infinite at its ends, dominated by the smallest
/// margin), projected into the null space of the Jacobian, each step followed
/// by Gauss-Newton corrections back onto the target pose. Steps that lose the
/// pose or do not lower H are refused. Returns the residual of the result.
Residual centre_joints(KinematicsWorkspace::Impl& w, const Pose& target, int nseg, const IkOptions& options,
                       Residual cur, Eigen::VectorXd& q) {
  const int n = static_cast<int>(w.lower.size());
  Eigen::VectorXd& q_try = w.ik_q_try;
  Eigen::VectorXd& g = w.ik_g;
  Eigen::VectorXd& dq = w.ik_dq;
  Eigen::Matrix<double, 6, Eigen::Dynamic>& J = w.ik_J;
  Eigen::Matrix3d R;
  Eigen::Vector3d p;
  const auto cost = [&](const Eigen::VectorXd& x) {
    double h = 0.0;
    for (int i = 0; i < n; ++i) {
      const double a = x[i] - w.lower[i], b = w.upper[i] - x[i];
      if (!(a > 0.0 && b > 0.0)) return std::numeric_limits<double>::infinity();
      h += 1.0 / (a * a) + 1.0 / (b * b);
    }
    return h;
  };
  const auto converged = [&](const Residual& r) {
    return r.position_m <= options.position_tolerance_m && r.rotation_rad <= options.rotation_tolerance_rad;
  };
  double h = cost(q);
  double step_rad = 0.1;
  for (int it = 0; it < kCentreIterations && step_rad > 1e-4; ++it) {
    w.sweep(q, nseg, R, p, &J);
    for (int i = 0; i < n; ++i) {
      const double a = std::max(q[i] - w.lower[i], 1e-6), b = std::max(w.upper[i] - q[i], 1e-6);
      g[i] = -2.0 / (a * a * a) + 2.0 / (b * b * b);
    }
    Eigen::Matrix<double, 6, 6> A;
    A.noalias() = J * J.transpose();
    A.diagonal().array() += 1e-9;
    const Eigen::Matrix<double, 6, 1> Jg = J * g;
    dq.noalias() = J.transpose() * A.llt().solve(Jg);
    dq = dq - g;  // -(I - J^+ J) g
    const double norm = dq.cwiseAbs().maxCoeff();
    if (norm < 1e-9) break;
    q_try = q + dq * (step_rad / norm);
    clamp_to_limits(q_try, w.lower, w.upper);
    Residual r;
    for (int c = 0; c < 4; ++c) {
      w.sweep(q_try, nseg, R, p, &w.ik_J_try);
      r = residual(target, R, p);
      if (converged(r) && r.position_m < 0.1 * options.position_tolerance_m &&
          r.rotation_rad < 0.1 * options.rotation_tolerance_rad)
        break;
      A.noalias() = w.ik_J_try * w.ik_J_try.transpose();
      A.diagonal().array() += 1e-9;
      q_try.noalias() += w.ik_J_try.transpose() * A.llt().solve(r.e);
      clamp_to_limits(q_try, w.lower, w.upper);
    }
    w.sweep(q_try, nseg, R, p, nullptr);
    r = residual(target, R, p);
    const double h_try = cost(q_try);
    if (converged(r) && h_try < h) {
      const bool small_gain = h - h_try < 1e-4 * h;
      q = q_try;
      h = h_try;
      cur = r;
      if (small_gain) break;  // flat: the margins no longer change
      step_rad = std::min(2.0 * step_rad, 0.3);
    } else {
      step_rad *= 0.5;
    }
  }
  return cur;
}

}  // namespace

IkResult inverse_kinematics(const RobotModel& model, KinematicsWorkspace& ws, const Pose& base_T_target,
                            const Eigen::Ref<const Eigen::VectorXd>& seed, const IkOptions& options, int link) {
  if (!check(model, ws))
    throw std::invalid_argument("inverse_kinematics: the workspace was built for another robot model (" +
                                model.source() + " is not its model)");
  auto& w = ws.impl();
  const int n = model.dof();
  if (seed.size() != n)
    throw std::invalid_argument("inverse_kinematics: seed has " + std::to_string(seed.size()) + " joints, the model " +
                                std::to_string(n));
  const int nseg = segments_for(model, link);
  if (nseg <= 0) throw std::invalid_argument("inverse_kinematics: link index " + std::to_string(link) + " out of range");
  if (!base_T_target.matrix().allFinite()) throw std::invalid_argument("inverse_kinematics: target pose is not finite");

  SplitMix64 rng{options.random_seed};
  Eigen::VectorXd& q = w.ik_q;
  Eigen::VectorXd& q_try = w.ik_q_try;
  Eigen::VectorXd& dq = w.ik_dq;
  Eigen::Matrix<double, 6, Eigen::Dynamic>& J = w.ik_J;
  Eigen::Matrix<double, 6, Eigen::Dynamic>& J_try = w.ik_J_try;
  Eigen::Matrix<double, 6, Eigen::Dynamic>& Jw = w.ik_Jw;
  Eigen::VectorXd& g = w.ik_g;
  Eigen::Matrix3d R;
  Eigen::Vector3d p;

  IkResult result;
  Residual best;
  best.cost = std::numeric_limits<double>::infinity();
  double best_margin = -std::numeric_limits<double>::infinity();
  int candidates = 0;
  const auto converged = [&](const Residual& r) {
    return r.position_m <= options.position_tolerance_m && r.rotation_rad <= options.rotation_tolerance_rad;
  };

  const int attempts = 1 + std::max(0, options.max_restarts);
  for (int attempt = 0; attempt < attempts; ++attempt) {
    result.attempts = attempt + 1;
    if (attempt == 0) {
      for (int i = 0; i < n; ++i) q[i] = std::isfinite(seed[i]) ? seed[i] : 0.5 * (w.lower[i] + w.upper[i]);
      clamp_to_limits(q, w.lower, w.upper);
    } else {
      for (int i = 0; i < n; ++i) q[i] = w.lower[i] + rng.uniform() * (w.upper[i] - w.lower[i]);
    }
    w.sweep(q, nseg, R, p, &J);
    Residual cur = residual(base_T_target, R, p);
    double lambda = kLambdaInit;
    for (int it = 0; it < kMaxIterations && !converged(cur); ++it) {
      // Joints at a limit that the gradient pushes further out take no part in this step.
      g.noalias() = J.transpose() * cur.e;
      Jw = J;
      for (int i = 0; i < n; ++i) {
        if ((q[i] <= w.lower[i] && g[i] < 0.0) || (q[i] >= w.upper[i] && g[i] > 0.0)) Jw.col(i).setZero();
      }
      Eigen::Matrix<double, 6, 6> A;
      A.noalias() = Jw * Jw.transpose();
      A.diagonal().array() += lambda;
      dq.noalias() = Jw.transpose() * A.llt().solve(cur.e);
      const double step = dq.cwiseAbs().maxCoeff();
      if (step > kMaxStepRad) dq *= kMaxStepRad / step;
      q_try = q + dq;
      clamp_to_limits(q_try, w.lower, w.upper);
      w.sweep(q_try, nseg, R, p, &J_try);
      const Residual next = residual(base_T_target, R, p);
      if (next.cost < cur.cost) {
        q.swap(q_try);
        J.swap(J_try);
        cur = next;
        lambda = std::max(lambda * 0.1, kLambdaMin);
      } else {
        lambda *= 10.0;
        if (lambda > kLambdaMax) break;
      }
    }
    if (!converged(cur)) {
      if (!result.success && cur.cost < best.cost) {  // remember the closest miss
        best = cur;
        w.ik_best = q;
      }
      continue;
    }
    if (!options.centre_joints) {
      result.success = true;
      best = cur;
      w.ik_best = q;
      break;
    }
    // Centring: compare several solutions (self-motion cannot leave its
    // posture), each taken centred unless centring lowered its smallest
    // margin. A later posture must be clearly better than the earlier ones
    // (the seeded one first), so ties keep the seed's posture.
    w.ik_q_pre = q;
    const Residual pre = cur;
    const double margin_pre = min_margin(q, w.lower, w.upper);
    cur = centre_joints(w, base_T_target, nseg, options, cur, q);
    double margin = min_margin(q, w.lower, w.upper);
    if (margin < margin_pre) {
      q = w.ik_q_pre;
      cur = pre;
      margin = margin_pre;
    }
    if (!result.success || margin > best_margin + kPostureSwitchRad) {
      result.success = true;
      best_margin = margin;
      best = cur;
      w.ik_best = q;
    }
    if (++candidates >= std::max(1, options.centre_candidates)) break;
  }
  result.q = w.ik_best;
  result.position_error_m = best.position_m;
  result.rotation_error_rad = best.rotation_rad;
  return result;
}

void dls_step(const Jacobian& J, const Vector6& e, JointVector& dq, double lambda_max, double w0) noexcept {
  Eigen::Matrix<double, 6, 6> JJt;
  JJt.noalias() = J * J.transpose();
  const double det = JJt.determinant();
  const double w = det > 0.0 ? std::sqrt(det) : 0.0;
  double lambda2 = 1e-6;
  if (w < w0) lambda2 += lambda_max * lambda_max * (1.0 - (w / w0) * (w / w0));
  JJt.diagonal().array() += lambda2;
  const Vector6 y = JJt.ldlt().solve(e);
  dq.resize(J.cols());
  dq.noalias() = J.transpose() * y;
}

}  // namespace foresight
