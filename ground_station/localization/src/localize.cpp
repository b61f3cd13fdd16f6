#include "foresight/localization/localize.hpp"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <Eigen/QR>
#include <Eigen/LU>
#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <set>
#include <sstream>

#include "foresight/calibration/levenberg_marquardt.hpp"
#include "foresight/calibration/outlier_flagging.hpp"
#include "foresight/camera/projection.hpp"

namespace foresight::localization {

namespace {

std::string point_name(const calibration::Correspondence& c) {
  std::string s = "n=" + std::to_string(c.n) + " in view '" + c.cam + "'";
  if (c.line > 0) s += " (line " + std::to_string(c.line) + ")";
  return s;
}


std::string names_of(const std::map<std::string, camera::Camera>& cameras) {
  std::string s;
  for (const auto& [name, cam] : cameras) s += (s.empty() ? "" : ", ") + name;
  return s.empty() ? "none" : s;
}

/// One click with its camera resolved.
struct Obs {
  const calibration::Correspondence* c;
  const camera::Camera* cam;
};

/// Reprojection rms and number of points behind their camera for a pose.
std::pair<int, double> score(const Pose& base_T_object, const std::vector<Obs>& obs) {
  int behind = 0;
  double ss = 0.0;
  for (const auto& o : obs) {
    const Eigen::Vector3d pc = o.cam->to_camera(base_T_object * o.c->p_m);
    if (!(pc.z() > 0.0)) ++behind;
    ss += (o.cam->project_camera(pc) - o.c->uv_px).squaredNorm();
  }
  return {behind, std::sqrt(ss / static_cast<double>(obs.size()))};
}

void check_geometry(const std::vector<Obs>& obs) {
  if (obs.size() < 6)
    throw calibration::EstimationInputError("localization needs at least 6 clicked points over all views, got " +
                          std::to_string(obs.size()));
  std::vector<Eigen::Vector3d> distinct;
  for (const auto& o : obs) {
    if (!o.c->p_m.allFinite() || !o.c->uv_px.allFinite())
      throw calibration::EstimationInputError("point " + point_name(*o.c) + " has a non-finite coordinate");
    bool seen = false;
    for (const auto& d : distinct) seen = seen || (d - o.c->p_m).norm() < 1e-12;
    if (!seen) distinct.push_back(o.c->p_m);
  }
  if (distinct.size() < 4)
    throw calibration::EstimationInputError("localization needs at least 4 distinct model points, got " + std::to_string(distinct.size()));
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const auto& d : distinct) mean += d;
  mean /= static_cast<double>(distinct.size());
  Eigen::Matrix3d scatter = Eigen::Matrix3d::Zero();
  for (const auto& d : distinct) scatter += (d - mean) * (d - mean).transpose();
  const Eigen::Vector3d s =
      Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(scatter).eigenvalues().reverse().cwiseMax(0.0).cwiseSqrt();
  if (s[0] <= 1e-12 || s[1] <= 1e-7 * s[0])
    throw calibration::EstimationInputError("the " + std::to_string(distinct.size()) +
                          " distinct model points are collinear: the object's rotation about that line is undetermined");
}

/// eq. 8 without normal equations: QR of [A | b], then the SVD of the U x U
/// triangle (A's singular values and right singular vectors). x_p is the
/// least-squares solution in the U-1 well-determined directions, x_h the
/// (near) null-space vector. False when A's rank is below U-1.
template <int U>
bool particular_and_null(const Eigen::MatrixXd& A, const Eigen::VectorXd& b, double rank_tolerance,
                         Eigen::VectorXd& xp, Eigen::VectorXd& xh) {
  const Eigen::Index rows = std::max<Eigen::Index>(A.rows(), U + 1);
  Eigen::Matrix<double, Eigen::Dynamic, U + 1> Ab = Eigen::Matrix<double, Eigen::Dynamic, U + 1>::Zero(rows, U + 1);
  Ab.topLeftCorner(A.rows(), U) = A;  // zero rows pad the 6-click case
  Ab.col(U).head(A.rows()) = b;
  const Eigen::HouseholderQR<Eigen::Matrix<double, Eigen::Dynamic, U + 1>> qr(Ab);
  const Eigen::Matrix<double, U + 1, U + 1> R = qr.matrixQR().template topRows<U + 1>().template triangularView<Eigen::Upper>();
  const Eigen::JacobiSVD<Eigen::Matrix<double, U, U>> svd(R.template topLeftCorner<U, U>(),
                                                         Eigen::ComputeFullU | Eigen::ComputeFullV);
  const auto& sv = svd.singularValues();
  if (!(sv[U - 2] > rank_tolerance * sv[0])) return false;
  const Eigen::Matrix<double, U, 1> Utb = svd.matrixU().transpose() * R.template topRightCorner<U, 1>();
  xp = Eigen::VectorXd::Zero(U);
  for (int s = 0; s < U - 1; ++s) xp += svd.matrixV().col(s) * (Utb[s] / sv[s]);
  xh = svd.matrixV().col(U - 1);
  return true;
}

Pose linear_pose(const std::vector<Obs>& obs, double rank_tolerance) {
  const int n = static_cast<int>(obs.size());
  // Object points centred, in their principal axes, scaled to unit RMS.
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const auto& o : obs) mean += o.c->p_m;
  mean /= n;
  Eigen::Matrix3d scatter = Eigen::Matrix3d::Zero();
  for (const auto& o : obs) scatter += (o.c->p_m - mean) * (o.c->p_m - mean).transpose();
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> pca(scatter);
  Eigen::Matrix3d Q = pca.eigenvectors().rowwise().reverse();  // principal axes, largest first
  if (Q.determinant() < 0.0) Q.col(2) = -Q.col(2);
  const Eigen::Vector3d ps = pca.eigenvalues().reverse().cwiseMax(0.0).cwiseSqrt();
  const double sigma = ps[0] / std::sqrt(static_cast<double>(n));
  // Nearly coplanar model points (thinner than a tenth of their extent): the
  // 9-unknown form (two rotation columns, the third their cross product) is
  // the better start; otherwise the full 12-unknown form of eq. 7.
  const bool planar = ps[2] < 0.1 * ps[0];
  Pose best = Pose::Identity();
  std::pair<int, double> best_score{n + 1, 0.0};
  for (int form = planar ? 1 : 0; form < (planar ? 2 : 1); ++form) {
    const int cols = form == 0 ? 3 : 2;   // rotation columns solved for
    const int u = 3 * (cols + 1);         // unknowns: 12 or 9
    Eigen::MatrixXd A(2 * n, u);
    Eigen::VectorXd b(2 * n);
    for (int i = 0; i < n; ++i) {
      const camera::Camera& cam = *obs[i].cam;
      const Eigen::Vector3d p = Q.transpose() * (obs[i].c->p_m - mean) / sigma;
      const Eigen::Matrix3d& Rc = cam.base_T_camera.linear();
      const Eigen::Vector3d c = cam.base_T_camera.translation();
      const Eigen::Vector2d xn = (obs[i].c->uv_px - cam.principal_point()) / cam.f_px;
      for (int r = 0; r < 2; ++r) {
        // eq. 7: a = (camera x or y axis) - x_n (camera z axis), in base:
        // a . (R' p' + t') = a . c_camera.
        const Eigen::Vector3d a = (Rc.col(r) - xn[r] * Rc.col(2)) * cam.f_px;
        for (int j = 0; j < 3; ++j) {
          for (int k = 0; k < cols; ++k) A(2 * i + r, j * (cols + 1) + k) = a[j] * p[k];
          A(2 * i + r, j * (cols + 1) + cols) = a[j];
        }
        b[2 * i + r] = a.dot(c);
      }
    }
    Eigen::VectorXd xp, xh;
    const bool ok = u == 12 ? particular_and_null<12>(A, b, rank_tolerance, xp, xh)
                            : particular_and_null<9>(A, b, rank_tolerance, xp, xh);
    if (!ok)
      throw calibration::EstimationInputError("the linear localization system is rank deficient (rank below " + std::to_string(u - 1) +
                            "): degenerate geometry of the model points and views");
    auto rot_part = [&](const Eigen::VectorXd& x) {
      Eigen::VectorXd r(3 * cols);
      for (int j = 0; j < 3; ++j) r.segment(j * cols, cols) = x.segment(j * (cols + 1), cols);
      return r;
    };
    const Eigen::VectorXd rp = rot_part(xp), rh = rot_part(xh);
    // k from the unit norm of the rotation (rows of R' have norm sigma):
    // |rp + k rh|^2 = cols * sigma^2.
    const double qa = rh.squaredNorm(), qb = 2.0 * rp.dot(rh), qc = rp.squaredNorm() - cols * sigma * sigma;
    const double disc = qb * qb - 4.0 * qa * qc;
    std::vector<double> ks;
    if (disc >= 0.0) {
      ks = {(-qb + std::sqrt(disc)) / (2.0 * qa), (-qb - std::sqrt(disc)) / (2.0 * qa)};
    } else {
      ks = {-qb / (2.0 * qa)};
    }
    for (const double k : ks) {
      const Eigen::VectorXd x = xp + k * xh;
      Eigen::Matrix3d RQ = Eigen::Matrix3d::Zero();  // R Q (object rotation in principal axes)
      Eigen::Vector3d t;
      for (int j = 0; j < 3; ++j) {
        for (int kk = 0; kk < cols; ++kk) RQ(j, kk) = x[j * (cols + 1) + kk] / sigma;
        t[j] = x[j * (cols + 1) + cols];
      }
      if (cols == 2) RQ.col(2) = RQ.col(0).cross(RQ.col(1));
      if (RQ.determinant() <= 0.0) RQ.col(2) = RQ.col(0).cross(RQ.col(1));  // the cross product fix
      if (!RQ.allFinite() || RQ.determinant() <= 0.0) continue;
      Pose T = Pose::Identity();
      T.linear() = nearest_rotation(RQ) * Q.transpose();
      T.translation() = t - T.linear() * mean;  // x' = R(mean + Q p') + t_obj
      const auto sc = score(T, obs);
      if (sc.first < best_score.first || (sc.first == best_score.first && sc.second < best_score.second)) {
        best_score = sc;
        best = T;
      }
    }
  }
  if (best_score.first > n) throw calibration::EstimationError("the linear localization found no pose");
  return best;
}

std::vector<Obs> resolve(const std::vector<calibration::Correspondence>& points, const std::map<std::string, camera::Camera>& cameras,
                         const std::vector<std::string>& views, std::vector<std::string>& used_views) {
  std::set<std::string> wanted(views.begin(), views.end());
  for (const auto& v : views)
    if (!cameras.count(v)) throw calibration::EstimationInputError("unknown view '" + v + "' (known cameras: " + names_of(cameras) + ")");
  std::vector<Obs> obs;
  std::set<std::string> used;
  for (const auto& c : points) {
    if (!wanted.empty() && !wanted.count(c.cam)) continue;
    const auto it = cameras.find(c.cam);
    if (it == cameras.end())
      throw calibration::EstimationInputError("point n=" + std::to_string(c.n) + (c.line > 0 ? " (line " + std::to_string(c.line) + ")" : "") +
                            ": unknown camera '" + c.cam + "' (known cameras: " + names_of(cameras) + ")");
    obs.push_back({&c, &it->second});
    used.insert(c.cam);
  }
  for (const auto& v : views)
    if (!used.count(v)) throw calibration::EstimationInputError("view '" + v + "' has no points");
  used_views.assign(used.begin(), used.end());
  return obs;
}

/// One call of localize_object: the clicks resolved to their cameras, the
/// pose being fitted, and the steps (the fit with outlier flagging, the
/// optional joint refinement with the cameras, the residuals, the
/// covariance with the held cameras' and the arm model's terms).
class Localizer {
 public:
  Localizer(const std::vector<calibration::Correspondence>& points, const std::map<std::string, camera::Camera>& cameras,
            const LocalizationOptions& opt, LocalizationResult& res)
      : cameras_(cameras), opt_(opt), res_(res) {
    check_options();
    var_links_ = opt.arm_link_sigma_m * opt.arm_link_sigma_m;
    arm_term_ = var_links_ > 0.0 && links_ > 0;
    obs_ = resolve(points, cameras, opt.views, res.views);
    check_geometry(obs_);
    n_ = static_cast<int>(obs_.size());
    res.n_points = n_;
    lm_.max_iterations = opt.max_iterations;
  }

  void run() {
    fit_with_outliers();
    refine_jointly();
    if (!state_.R.allFinite() || !state_.t.allFinite()) throw calibration::EstimationError("the nonlinear localization did not converge");
    res_.base_T_object = Pose::Identity();
    res_.base_T_object.linear() = state_.R;
    res_.base_T_object.translation() = state_.t;
    res_.iterations = iterations_;
    residuals();
    covariance();
  }

 private:
  struct State {
    Eigen::Matrix3d R;
    Eigen::Vector3d t;
  };

  void check_options() {
    if (!(opt_.arm_link_sigma_m >= 0.0) || !std::isfinite(opt_.arm_link_sigma_m))
      throw calibration::EstimationInputError("arm link sigma must be a non-negative number of metres, got " +
                                 std::to_string(opt_.arm_link_sigma_m));
    for (const auto& [name, K] : opt_.camera_link_sensitivity) {
      if (K.rows() != 7 || K.cols() == 0 || !K.allFinite())
        throw calibration::EstimationInputError("camera '" + name + "': the link sensitivity must be 7 rows of finite numbers, one column per link (" +
                                   std::to_string(K.rows()) + " x " + std::to_string(K.cols()) + " given)");
      if (links_ > 0 && K.cols() != links_)
        throw calibration::EstimationInputError("camera '" + name + "': the link sensitivity has " + std::to_string(K.cols()) +
                                   " links, another camera's " + std::to_string(links_));
      links_ = K.cols();
    }
    for (const auto& [name, C] : opt_.camera_covariance) {
      const Eigen::LDLT<Eigen::Matrix<double, 7, 7>> ldlt(C);
      if (!C.allFinite() || !C.isApprox(C.transpose(), 1e-9) || ldlt.info() != Eigen::Success ||
          (ldlt.vectorD().array() < -1e-12 * std::max(1.0, C.diagonal().maxCoeff())).any())
        throw calibration::EstimationInputError("camera '" + name + "': the covariance must be a finite, symmetric, positive semi-definite 7x7 matrix");
    }
  }

  const Eigen::MatrixXd* sensitivity_of(const std::string& cam) const {
    const auto it = opt_.camera_link_sensitivity.find(cam);
    return it == opt_.camera_link_sensitivity.end() ? nullptr : &it->second;
  }

  void evaluate(const State& s, Eigen::VectorXd& e, Eigen::Matrix<double, Eigen::Dynamic, 6>* J) const {
    for (int k = 0; k < static_cast<int>(idx_.size()); ++k) {
      const Obs& o = obs_[idx_[k]];
      const camera::Projection pr = camera::project_with_jacobians(*o.cam, s.R * o.c->p_m + s.t);
      e.segment<2>(2 * k) = pr.uv_px - o.c->uv_px;
      if (J) J->block<2, 6>(2 * k, 0) = camera::object_pose_jacobian(pr, s.R, o.c->p_m);  // body rotation, translation
    }
  }

  std::vector<double> residual_norms(const State& s) const {
    std::vector<double> r(static_cast<std::size_t>(n_));
    for (int i = 0; i < n_; ++i) {
      const Eigen::Vector3d pc = obs_[i].cam->to_camera(s.R * obs_[i].c->p_m + s.t);
      r[i] = (obs_[i].cam->project_camera(pc) - obs_[i].c->uv_px).norm();
    }
    return r;
  }

  void require_converged(const char* stage) const {
    if (!last_fit_.converged)
      throw calibration::EstimationError(std::string("the ") + stage + " did not converge after " +
                            std::to_string(last_fit_.iterations) + " iterations (" +
                            calibration::to_string(last_fit_.stop) + ")");
  }

  /// The pose from the linear solution by Levenberg-Marquardt, the outliers
  /// flagged and left out (idx_: the inliers, m_ of them).
  void fit_with_outliers() {
    const auto retract = [](const State& s, const Eigen::Matrix<double, 6, 1>& d) {
      return State{s.R * camera::exp_so3(d.head<3>()), s.t + d.tail<3>()};
    };
    // Size of the parameters in the units of a step (rad, m): for the relative step test.
    const auto state_norm = [](const State& s) { return std::sqrt(3.0 + s.t.squaredNorm()); };
    const auto eval = [this](const State& s, Eigen::VectorXd& e, Eigen::Matrix<double, Eigen::Dynamic, 6>* J) {
      evaluate(s, e, J);
    };
    bool have_state = false;
    const auto fit = [&](const std::vector<bool>& inlier) {
      idx_.clear();
      for (int i = 0; i < n_; ++i)
        if (inlier[i]) idx_.push_back(i);
      if (!have_state) {
        linear_all_ = linear_pose(obs_, opt_.rank_tolerance);
        state_ = {linear_all_.linear(), linear_all_.translation()};
        have_state = true;
      }
      last_fit_ = calibration::levenberg_marquardt<6>(state_, 2 * static_cast<int>(idx_.size()), eval, retract,
                                                     state_norm, lm_);
      iterations_ = last_fit_.iterations;
      return residual_norms(state_);
    };
    std::vector<double> r;
    inlier_ = calibration::flag_outliers(n_, 6, opt_.outliers, fit, r);
    require_converged("nonlinear localization");
    if (!state_.R.allFinite() || !state_.t.allFinite()) throw calibration::EstimationError("the nonlinear localization did not converge");
    idx_.clear();
    for (int i = 0; i < n_; ++i)
      if (inlier_[i]) idx_.push_back(i);
    m_ = static_cast<int>(idx_.size());
  }

  /// The pose's response to the link lengths (body rotation, position; 6 x
  /// links), arm_D_, and the held cameras' uncertainty carried to the pose,
  /// held_body_: the fit's linear response -H^-1 J^T de/dx to a change x,
  /// where a held camera moves its points' pixels (d_camera, times K for the
  /// links) and a jointly refined camera moves its prior's centre. Also the
  /// links' expected share of the final residuals' sum of squares,
  /// var_links ||(I - J H^-1 J^T) de/dlinks||^2: what the fit could not take
  /// (two cameras that disagree); taken out of the pixel noise's estimate,
  /// or the arm would be counted twice (measured: a joint fit's yaw sd 2.4x
  /// the spread).
  void camera_responses(const Eigen::MatrixXd& J, const Eigen::MatrixXd& H, const Eigen::Matrix3d& R,
                        const Eigen::Vector3d& t, const std::vector<std::string>& refined_names) {
    const auto is_refined = [&](const std::string& cam) {
      return std::find(refined_names.begin(), refined_names.end(), cam) != refined_names.end();
    };
    Eigen::MatrixXd dedl = Eigen::MatrixXd::Zero(J.rows(), arm_term_ ? links_ : 0);
    std::map<std::string, Eigen::MatrixXd> dedc;  // per held camera with a covariance
    for (int k = 0; k < m_; ++k) {
      const Obs& o = obs_[idx_[k]];
      if (is_refined(o.c->cam)) continue;
      const Eigen::MatrixXd* K = arm_term_ ? sensitivity_of(o.c->cam) : nullptr;
      const auto cov = opt_.camera_covariance.find(o.c->cam);
      if (!K && cov == opt_.camera_covariance.end()) continue;
      const Eigen::Matrix<double, 2, 7> d_camera = camera::project_with_jacobians(*o.cam, R * o.c->p_m + t).d_camera;
      if (K) dedl.middleRows<2>(2 * k) = d_camera * *K;
      if (cov != opt_.camera_covariance.end()) {
        Eigen::MatrixXd& d = dedc[o.c->cam];
        if (d.size() == 0) d = Eigen::MatrixXd::Zero(J.rows(), 7);
        d.middleRows<2>(2 * k) = d_camera;
      }
    }
    if (arm_term_)
      for (std::size_t j = 0; j < refined_names.size(); ++j)  // the prior's centre moves: d e / d centre = -(d e / d camera)
        if (const Eigen::MatrixXd* K = sensitivity_of(refined_names[j])) {
          const Eigen::Index row = 2 * m_ + 7 * static_cast<Eigen::Index>(j), col = 6 + 7 * static_cast<Eigen::Index>(j);
          dedl.middleRows<7>(row) = -J.block<7, 7>(row, col) * *K;
        }
    const Eigen::LDLT<Eigen::MatrixXd> ldlt(H);
    if (arm_term_) {
      const Eigen::MatrixXd D = -ldlt.solve(J.transpose() * dedl);
      arm_in_residuals_ = var_links_ * (dedl + J * D).squaredNorm();
      arm_D_ = D.topRows(6);
    }
    for (const auto& [name, d] : dedc) {
      const Eigen::MatrixXd A = -ldlt.solve(J.transpose() * d).topRows(6);
      held_body_ += A * opt_.camera_covariance.at(name) * A.transpose();
    }
  }

  /// Optional joint refinement: the pose and every camera that comes with
  /// its calibration information, the cameras held to their calibration by
  /// a prior (a Gaussian with information J^T J in pixel units).
  /// Asymptotically the joint maximum likelihood of calibration and
  /// localization clicks.
  void refine_jointly() {
    for (const auto& v : res_.views)
      if (opt_.camera_information.count(v)) joint_names_.push_back(v);
    const int kj = static_cast<int>(joint_names_.size());
    if (kj == 0) return;
    std::map<std::string, int> slot;
    std::vector<Eigen::Matrix<double, 7, 7>> Lt(kj);
    std::vector<camera::Camera> cams0;
    for (int j = 0; j < kj; ++j) {
      slot[joint_names_[j]] = j;
      cams0.push_back(cameras_.at(joint_names_[j]));
      const Eigen::Matrix<double, 7, 7>& info = opt_.camera_information.at(joint_names_[j]);
      const Eigen::LLT<Eigen::Matrix<double, 7, 7>> llt(info);
      if (llt.info() != Eigen::Success || !info.allFinite())
        throw calibration::EstimationInputError("camera '" + joint_names_[j] + "': calibration information is not positive definite");
      Lt[j] = llt.matrixL().transpose();
    }
    struct JointState {
      Eigen::Matrix3d R;
      Eigen::Vector3d t;
      std::vector<camera::Camera> cams;
    };
    JointState js{state_.R, state_.t, cams0};
    const int m = m_;
    const int np = 6 + 7 * kj, nr = 2 * m + 7 * kj;
    auto jevaluate = [&](const JointState& s, Eigen::VectorXd& e, Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic>* J) {
      if (J) J->setZero();
      for (int k = 0; k < m; ++k) {
        const Obs& o = obs_[idx_[k]];
        const auto it = slot.find(o.c->cam);
        const camera::Camera& cam = it == slot.end() ? *o.cam : s.cams[it->second];
        const camera::Projection pr = camera::project_with_jacobians(cam, s.R * o.c->p_m + s.t);
        e.segment<2>(2 * k) = pr.uv_px - o.c->uv_px;
        if (J) {
          J->block<2, 6>(2 * k, 0) = camera::object_pose_jacobian(pr, s.R, o.c->p_m);
          if (it != slot.end()) J->block<2, 7>(2 * k, 6 + 7 * it->second) = pr.d_camera;
        }
      }
      for (int j = 0; j < kj; ++j) {
        Eigen::Matrix<double, 7, 1> dlt;
        const Eigen::AngleAxisd aa(cams0[j].base_T_camera.linear().transpose() * s.cams[j].base_T_camera.linear());
        dlt << aa.angle() * aa.axis(), s.cams[j].base_T_camera.translation() - cams0[j].base_T_camera.translation(),
            s.cams[j].f_px - cams0[j].f_px;
        e.segment<7>(2 * m + 7 * j) = Lt[j] * dlt;
        if (J) {  // d log(R0^T R exp([d]x)) / dd is the inverse right Jacobian, not I
          Eigen::Matrix<double, 7, 7> D = Eigen::Matrix<double, 7, 7>::Identity();
          D.topLeftCorner<3, 3>() = camera::right_jacobian_inverse_so3(dlt.head<3>());
          J->block<7, 7>(2 * m + 7 * j, 6 + 7 * j) = Lt[j] * D;
        }
      }
    };
    auto jretract = [&](const JointState& s, const Eigen::VectorXd& d) {
      JointState out{s.R * camera::exp_so3(d.head<3>()), s.t + d.segment<3>(3), s.cams};
      for (int j = 0; j < kj; ++j) {
        const auto dc = d.segment<7>(6 + 7 * j);
        out.cams[j].base_T_camera.linear() = s.cams[j].base_T_camera.linear() * camera::exp_so3(dc.head<3>());
        out.cams[j].base_T_camera.translation() += dc.segment<3>(3);
        out.cams[j].f_px += dc[6];
      }
      return out;
    };
    auto jnorm = [&](const JointState& s) {
      double ss = 3.0 * (1 + kj) + s.t.squaredNorm();
      for (int j = 0; j < kj; ++j) ss += s.cams[j].base_T_camera.translation().squaredNorm() + s.cams[j].f_px * s.cams[j].f_px;
      return std::sqrt(ss);
    };
    last_fit_ = calibration::levenberg_marquardt<Eigen::Dynamic>(js, nr, jevaluate, jretract, jnorm, lm_, np);
    require_converged("joint refinement (pose and cameras)");
    iterations_ += last_fit_.iterations;
    state_.R = js.R;
    state_.t = js.t;
    for (int j = 0; j < kj; ++j) refined_[joint_names_[j]] = js.cams[j];
    Eigen::VectorXd e(nr);
    Eigen::MatrixXd J(nr, np);
    jevaluate(js, e, &J);
    joint_H_ = J.transpose() * J;
    joint_ss_ = e.squaredNorm();
    camera_responses(J, joint_H_, js.R, js.t, joint_names_);
    res_.camera_uncertainty = true;
    res_.refined_cameras = refined_;
  }

  const camera::Camera& camera_of(const Obs& o) const {
    const auto it = refined_.find(o.c->cam);
    return it == refined_.end() ? *o.cam : it->second;
  }

  /// Every point's residual at the fitted pose (outliers marked), the rms
  /// over the inliers, the linear stage's rms over them.
  void residuals() {
    std::string behind;
    double ss = 0.0;
    std::vector<Obs> in_obs;
    for (int i = 0; i < n_; ++i) {
      const Obs& o = obs_[i];
      const camera::Camera& cam = camera_of(o);
      const Eigen::Vector3d pc = cam.to_camera(res_.base_T_object * o.c->p_m);
      calibration::PointResidual pr;
      pr.n = o.c->n;
      pr.cam = o.c->cam;
      pr.line = o.c->line;
      pr.r_px = o.c->uv_px - cam.project_camera(pc);
      pr.px = pr.r_px.norm();
      pr.outlier = !inlier_[i];
      if (pr.outlier) {
        res_.outliers.push_back(o.c->n);
      } else {
        if (!(pc.z() > 0.0)) behind += (behind.empty() ? "" : ", ") + point_name(*o.c);
        ss += pr.px * pr.px;
        res_.max_px = std::max(res_.max_px, pr.px);
        in_obs.push_back(o);
      }
      res_.residuals.push_back(pr);
    }
    if (!behind.empty()) throw calibration::EstimationInputError("points behind their camera at the fitted pose: " + behind);
    res_.rms_px = std::sqrt(ss / m_);
    res_.linear_rms_px =
        score(res_.outliers.empty() ? linear_all_ : linear_pose(in_obs, opt_.rank_tolerance), in_obs).second;
  }

  /// Covariance of (rpy, position): s^2 H^-1 (its pose block in the joint
  /// case), the body rotation increments mapped to rpy rates; the held
  /// cameras' and the arm model's terms added.
  void covariance() {
    Eigen::Matrix<double, 6, 6> C_body;
    if (!joint_names_.empty()) {
      const double s2 = std::max(0.0, joint_ss_ - arm_in_residuals_) / std::max(2 * m_ - 6, 1);
      C_body = s2 * joint_H_.inverse().topLeftCorner<6, 6>();
    } else {
      Eigen::VectorXd e(2 * m_);
      Eigen::Matrix<double, Eigen::Dynamic, 6> J(2 * m_, 6);
      evaluate(state_, e, &J);
      const Eigen::Matrix<double, 6, 6> H = J.transpose() * J;
      camera_responses(J, H, state_.R, state_.t, {});
      const double s2 = std::max(0.0, e.squaredNorm() - arm_in_residuals_) / std::max(2 * m_ - 6, 1);
      C_body = s2 * H.inverse();
    }
    Eigen::Matrix<double, 6, 6> G = Eigen::Matrix<double, 6, 6>::Identity();
    G.topLeftCorner<3, 3>() = calibration::rpy_rate_matrix(rpy_from_rotation(state_.R)).inverse();
    C_body += held_body_;
    res_.held_cameras_covariance = G * held_body_ * G.transpose();
    if (arm_term_) {
      const Eigen::Matrix<double, 6, 6> arm_body = var_links_ * arm_D_ * arm_D_.transpose();
      C_body += arm_body;
      res_.arm_model_covariance = G * arm_body * G.transpose();
      res_.arm_link_sensitivity = G * arm_D_;
    }
    res_.covariance = G * C_body * G.transpose();
    const Eigen::Matrix<double, 6, 1> sd = res_.covariance.diagonal().cwiseMax(0.0).cwiseSqrt();
    res_.sigma_rpy_rad = sd.head<3>();
    res_.sigma_position_m = sd.tail<3>();
  }

  const std::map<std::string, camera::Camera>& cameras_;
  const LocalizationOptions& opt_;
  LocalizationResult& res_;
  Eigen::Index links_ = 0;
  double var_links_ = 0.0;
  bool arm_term_ = false;
  std::vector<Obs> obs_;
  int n_ = 0, m_ = 0;
  std::vector<int> idx_;          ///< the points in the fit (the inliers once flagged)
  std::vector<bool> inlier_;
  State state_{};
  int iterations_ = 0;
  calibration::LmOptions lm_;
  calibration::LmReport last_fit_;
  Pose linear_all_ = Pose::Identity();
  Eigen::MatrixXd arm_D_;
  Eigen::Matrix<double, 6, 6> held_body_ = Eigen::Matrix<double, 6, 6>::Zero();
  double arm_in_residuals_ = 0.0;
  std::vector<std::string> joint_names_;
  std::map<std::string, camera::Camera> refined_;
  Eigen::MatrixXd joint_H_;
  double joint_ss_ = 0.0;
};

}  // namespace

Eigen::Vector3d LocalizationResult::rpy_rad() const { return rpy_from_rotation(base_T_object.linear()); }

Pose localize_object_linear(const std::vector<calibration::Correspondence>& points, const std::map<std::string, camera::Camera>& cameras,
                            double rank_tolerance) {
  std::vector<std::string> used;
  const std::vector<Obs> obs = resolve(points, cameras, {}, used);
  check_geometry(obs);
  return linear_pose(obs, rank_tolerance);
}

LocalizationResult localize_object(const std::vector<calibration::Correspondence>& points,
                                   const std::map<std::string, camera::Camera>& cameras, const LocalizationOptions& opt) {
  LocalizationResult res;
  Localizer(points, cameras, opt, res).run();
  return res;
}

}  // namespace foresight::localization
