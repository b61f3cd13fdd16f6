#include "foresight/calibration/calibrate.hpp"

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <Eigen/QR>
#include <Eigen/LU>
#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <sstream>

#include "foresight/calibration/levenberg_marquardt.hpp"
#include "foresight/calibration/outlier_flagging.hpp"
#include "foresight/camera/projection.hpp"

namespace foresight::calibration {

namespace {

std::string point_name(const Correspondence& c) {
  std::string s = "n=" + std::to_string(c.n);
  if (c.line > 0) s += " (line " + std::to_string(c.line) + ")";
  return s;
}


/// Checks count, finiteness and the point geometry needed by the linear stage.
void check_points(const std::vector<Correspondence>& pts, const std::string& name) {
  const std::string who = "camera '" + name + "': ";
  if (pts.size() < 6)
    throw EstimationInputError(who + std::to_string(pts.size()) +
                          " points; the linear calibration needs at least 6 (11 unknowns, 2 equations a point)");
  for (const auto& c : pts)
    if (!c.p_m.allFinite() || !c.uv_px.allFinite())
      throw EstimationInputError(who + "point " + point_name(c) + " has a non-finite coordinate");
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const auto& c : pts) mean += c.p_m;
  mean /= static_cast<double>(pts.size());
  Eigen::Matrix3d scatter = Eigen::Matrix3d::Zero();
  for (const auto& c : pts) scatter += (c.p_m - mean) * (c.p_m - mean).transpose();
  // Singular values of the centred point matrix, largest first.
  const Eigen::Vector3d s = Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(scatter).eigenvalues().reverse().cwiseMax(0.0).cwiseSqrt();
  if (s[0] <= 1e-12 || s[1] <= 1e-7 * s[0])
    throw EstimationInputError(who + "the " + std::to_string(pts.size()) +
                          " points are collinear (or coincide): calibration needs points spread in 3-D");
  if (s[2] <= 1e-7 * s[0]) {
    std::ostringstream m;
    m << who << "the " << pts.size()
      << " points are coplanar: the linear calibration (11 unknowns) is degenerate for points on one plane;"
         " click points off that plane (another arm pose)";
    throw EstimationInputError(m.str());
  }
}

double rms_px(const camera::Camera& cam, const std::vector<Correspondence>& pts) {
  double ss = 0.0;
  for (const auto& c : pts) {
    const Eigen::Vector3d pc = cam.to_camera(c.p_m);
    ss += (cam.project_camera(pc) - c.uv_px).squaredNorm();
  }
  return std::sqrt(ss / static_cast<double>(pts.size()));
}

struct CamState {
  Eigen::Matrix3d R;  // base_R_camera
  Eigen::Vector3d c;  // camera position in base
  double f;
};

}  // namespace

Eigen::Matrix3d rpy_rate_matrix(const Eigen::Vector3d& rpy) {
  const Eigen::Matrix3d Rx = Eigen::AngleAxisd(rpy[0], Eigen::Vector3d::UnitX()).toRotationMatrix();
  const Eigen::Matrix3d Ry = Eigen::AngleAxisd(rpy[1], Eigen::Vector3d::UnitY()).toRotationMatrix();
  Eigen::Matrix3d W;
  W.col(0) = Eigen::Vector3d::UnitX();
  W.col(1) = Rx.transpose() * Eigen::Vector3d::UnitY();
  W.col(2) = Rx.transpose() * Ry.transpose() * Eigen::Vector3d::UnitZ();
  return W;
}

Eigen::Matrix<double, 7, 7> camera_covariance_rpy_from_body(const Eigen::Matrix<double, 7, 7>& body,
                                                            const Eigen::Matrix3d& base_R_camera) {
  Eigen::Matrix<double, 7, 7> T = Eigen::Matrix<double, 7, 7>::Identity();
  T.topLeftCorner<3, 3>() = rpy_rate_matrix(rpy_from_rotation(base_R_camera)).inverse();
  return T * body * T.transpose();
}

Eigen::Matrix<double, 7, 7> camera_covariance_body_from_rpy(const Eigen::Matrix<double, 7, 7>& rpy,
                                                            const Eigen::Matrix3d& base_R_camera) {
  Eigen::Matrix<double, 7, 7> T = Eigen::Matrix<double, 7, 7>::Identity();
  T.topLeftCorner<3, 3>() = rpy_rate_matrix(rpy_from_rotation(base_R_camera));
  return T * rpy * T.transpose();
}

double robust_sigma_px(std::vector<double> r) {
  if (r.empty()) return 0.0;
  const auto mid = r.begin() + static_cast<std::ptrdiff_t>(r.size() / 2);
  std::nth_element(r.begin(), mid, r.end());
  double med = *mid;
  if (r.size() % 2 == 0) med = 0.5 * (med + *std::max_element(r.begin(), mid));
  return med / 1.1774100225154747;  // median of a Rayleigh(sigma) = sigma sqrt(2 ln 2)
}

camera::Camera calibrate_camera_linear(const std::vector<Correspondence>& pts, const camera::Viewport& vp, const std::string& name,
                               double rank_tolerance, bool* cross_product) {
  check_points(pts, name);
  const std::string who = "camera '" + name + "': ";
  check_in_viewport(pts, vp, "camera '" + name + "'");
  const int n = static_cast<int>(pts.size());
  // Normalise: points centred at their centroid and scaled to unit RMS,
  // pixels centred at the principal point and scaled by H/2 (the paper's s_y).
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const auto& c : pts) mean += c.p_m;
  mean /= n;
  double ms = 0.0;
  for (const auto& c : pts) ms += (c.p_m - mean).squaredNorm();
  const double sp = std::sqrt(ms / n);
  const Eigen::Vector2d pp(vp.width_px / 2.0, vp.height_px / 2.0);
  const double s_px = vp.height_px / 2.0;

  // Appendix A with the depth term at the centroid fixed (m34 = 1): 11 unknowns
  // x = (m1, m14, m2, m24, m3); u_n (m3.p + 1) = m1.p + m14, same for v.
  Eigen::Matrix<double, Eigen::Dynamic, 11> B = Eigen::Matrix<double, Eigen::Dynamic, 11>::Zero(2 * n, 11);
  Eigen::VectorXd rhs(2 * n);
  for (int i = 0; i < n; ++i) {
    const Eigen::Vector3d p = (pts[i].p_m - mean) / sp;
    const Eigen::Vector2d uvn = (pts[i].uv_px - pp) / s_px;
    B.block<1, 3>(2 * i, 0) = p.transpose();
    B(2 * i, 3) = 1.0;
    B.block<1, 3>(2 * i, 8) = -uvn.x() * p.transpose();
    rhs[2 * i] = uvn.x();
    B.block<1, 3>(2 * i + 1, 4) = p.transpose();
    B(2 * i + 1, 7) = 1.0;
    B.block<1, 3>(2 * i + 1, 8) = -uvn.y() * p.transpose();
    rhs[2 * i + 1] = uvn.y();
  }
  // Least squares without normal equations: QR of [B | rhs], then the SVD of
  // the 11x11 triangle (same singular values and solution as B's).
  Eigen::Matrix<double, Eigen::Dynamic, 12> Bc(2 * n, 12);
  Bc.leftCols<11>() = B;
  Bc.col(11) = rhs;
  const Eigen::HouseholderQR<Eigen::Matrix<double, Eigen::Dynamic, 12>> qr(Bc);
  const Eigen::Matrix<double, 12, 12> R = qr.matrixQR().topRows<12>().triangularView<Eigen::Upper>();
  const Eigen::JacobiSVD<Eigen::Matrix<double, 11, 11>> svd(R.topLeftCorner<11, 11>(),
                                                           Eigen::ComputeFullU | Eigen::ComputeFullV);
  const auto& sv = svd.singularValues();
  if (!(sv[10] > rank_tolerance * sv[0])) {
    std::ostringstream m;
    m << who << "the linear calibration system is rank deficient (smallest/largest singular value " << sv[10] / sv[0]
      << "): degenerate point geometry";
    throw EstimationInputError(m.str());
  }
  const Eigen::Matrix<double, 11, 1> x = svd.solve(R.topRightCorner<11, 1>());
  const Eigen::Vector3d m1 = x.segment<3>(0), m2 = x.segment<3>(4), m3 = x.segment<3>(8);
  const double m14 = x[3], m24 = x[7], m34 = 1.0;

  // Candidate rotations: the direct third row, and the cross product of the
  // first two (the far / near-orthographic case, appendix A).
  camera::Camera best;
  double best_rms = std::numeric_limits<double>::infinity();
  bool best_cross = false;
  for (int variant = 0; variant < 2; ++variant) {
    const Eigen::Vector3d r1 = m1.normalized();
    Eigen::Vector3d r2 = m2.normalized();
    double lambda = 0.0;
    Eigen::Vector3d r3;
    if (variant == 0) {
      lambda = m3.norm();
      // Sign: the centroid (depth m34 / lambda in these coordinates) in front.
      if (m34 / lambda < 0.0) lambda = -lambda;
      r3 = m3 / lambda;
    } else {
      r3 = r1.cross(r2).normalized();
      lambda = m3.dot(r3);
      if (!(lambda > 0.0)) continue;  // orthographic to the noise level: no depth
    }
    Eigen::Matrix3d M;
    M.row(0) = r1.transpose();
    M.row(1) = r2.transpose();
    M.row(2) = r3.transpose();
    if (M.determinant() <= 0.0) continue;
    const double f_n = 0.5 * (m1.norm() + m2.norm()) / lambda;
    if (!(f_n > 0.0) || !std::isfinite(f_n)) continue;
    const Eigen::Matrix3d R = nearest_rotation(M);  // camera_R_base
    const Eigen::Vector3d t_scaled(m14 / (lambda * f_n), m24 / (lambda * f_n), m34 / lambda);
    camera::Camera cam;
    cam.name = name;
    cam.viewport = vp;
    cam.f_px = f_n * s_px;
    Pose camera_T_base = Pose::Identity();
    camera_T_base.linear() = R;
    camera_T_base.translation() = sp * t_scaled - R * mean;
    cam.base_T_camera = camera_T_base.inverse();
    const double r = rms_px(cam, pts);
    if (std::isfinite(r) && r < best_rms) {
      best_rms = r;
      best = cam;
      best_cross = variant == 1;
    }
  }
  if (!std::isfinite(best_rms))
    throw EstimationError(who + "the linear calibration found no camera with the points in front of it");
  if (cross_product) *cross_product = best_cross;
  return best;
}

Eigen::Vector3d CalibrationResult::rpy_rad() const { return rpy_from_rotation(camera.base_T_camera.linear()); }

camera::CameraCalibrationInfo CalibrationResult::info(const std::string& date_utc) const {
  camera::CameraCalibrationInfo i;
  i.covariance = covariance;
  i.rms_px = rms_px;
  i.max_px = max_px;
  i.n_points = n_points;
  i.outliers = outliers;
  i.date = date_utc;
  if (link_sensitivity.size() > 0) {  // body rotation increments -> rpy rates, as the covariance
    i.arm_link_sigma_m = arm_link_sigma_m;
    i.arm_link_sensitivity = link_sensitivity;
    i.arm_link_sensitivity.topRows<3>() = rpy_rate_matrix(rpy_rad()).inverse() * link_sensitivity.topRows<3>();
  }
  return i;
}

namespace {

/// One call of calibrate_camera: the fit with outlier flagging (from the
/// linear solution), the residuals over the inliers, the covariance with the
/// arm model's term.
class CameraFit {
 public:
  CameraFit(const std::vector<Correspondence>& pts, const camera::Viewport& vp, const std::string& name,
            const CalibrationOptions& opt, CalibrationResult& res)
      : pts_(pts),
        vp_(vp),
        name_(name),
        who_("camera '" + name + "': "),
        opt_(opt),
        res_(res),
        n_(static_cast<int>(pts.size())),
        pp_(vp.width_px / 2.0, vp.height_px / 2.0) {
    res.n_points = n_;
  }

  void run() {
    fit_with_outliers();
    // The final camera and its statistics over the inliers.
    res_.camera.name = name_;
    res_.camera.viewport = vp_;
    res_.camera.f_px = state_.f;
    res_.camera.base_T_camera = Pose::Identity();
    res_.camera.base_T_camera.linear() = state_.R;
    res_.camera.base_T_camera.translation() = state_.c;
    res_.iterations = iterations_;
    if (!(state_.f > 0.0) || !std::isfinite(state_.f) || !state_.R.allFinite() || !state_.c.allFinite())
      throw EstimationError(who_ + "the nonlinear fit did not converge to a valid camera");
    residuals();
    covariance();
  }

 private:
  void evaluate(const CamState& s, Eigen::VectorXd& e, Eigen::Matrix<double, Eigen::Dynamic, 7>* J) const {
    for (int k = 0; k < static_cast<int>(idx_.size()); ++k) {
      const Correspondence& c = pts_[idx_[k]];
      const camera::Projection pr = camera::project_with_jacobians(s.R, s.c, s.f, pp_, c.p_m);
      e.segment<2>(2 * k) = pr.uv_px - c.uv_px;
      if (J) J->block<2, 7>(2 * k, 0) = pr.d_camera;  // body rotation, position, f_px
    }
  }

  std::vector<double> residual_norms(const CamState& s) const {
    std::vector<double> r(static_cast<std::size_t>(n_));
    const Eigen::Matrix3d Rt = s.R.transpose();
    for (int i = 0; i < n_; ++i) {
      const Eigen::Vector3d pc = Rt * (pts_[i].p_m - s.c);
      r[i] = (pp_ + s.f * pc.head<2>() / pc.z() - pts_[i].uv_px).norm();
    }
    return r;
  }

  /// Levenberg-Marquardt from the linear solution (of every point), the
  /// outliers flagged and left out.
  void fit_with_outliers() {
    const auto retract = [](const CamState& s, const Eigen::Matrix<double, 7, 1>& d) {
      return CamState{s.R * camera::exp_so3(d.head<3>()), s.c + d.segment<3>(3), s.f + d[6]};
    };
    // Size of the parameters in the units of a step (rad, m, px): for the relative step test.
    const auto state_norm = [](const CamState& s) { return std::sqrt(3.0 + s.c.squaredNorm() + s.f * s.f); };
    const auto eval = [this](const CamState& s, Eigen::VectorXd& e, Eigen::Matrix<double, Eigen::Dynamic, 7>* J) {
      evaluate(s, e, J);
    };
    bool have_state = false;
    LmReport last_fit;
    const auto fit = [&](const std::vector<bool>& inlier) {
      std::vector<Correspondence> sub;
      idx_.clear();
      for (int i = 0; i < n_; ++i)
        if (inlier[i]) {
          idx_.push_back(i);
          sub.push_back(pts_[i]);
        }
      if (!have_state) {  // first fit: start from the linear solution
        camera::Camera lin = calibrate_camera_linear(sub, vp_, name_, opt_.rank_tolerance, &res_.linear_cross_product);
        linear_all_ = lin;
        state_ = {lin.base_T_camera.linear(), lin.base_T_camera.translation(), lin.f_px};
        have_state = true;
      }
      LmOptions lm;
      lm.max_iterations = opt_.max_iterations;
      last_fit = levenberg_marquardt<7>(state_, 2 * static_cast<int>(idx_.size()), eval, retract,
                                                    state_norm, lm);
      iterations_ = last_fit.iterations;
      return residual_norms(state_);
    };
    std::vector<double> r;
    inlier_ = flag_outliers(n_, 8, opt_.outliers, fit, r);
    if (!last_fit.converged)
      throw EstimationError(who_ + "the nonlinear fit did not converge after " + std::to_string(last_fit.iterations) +
                            " iterations (" + to_string(last_fit.stop) + ")");
  }

  /// Every point's residual (outliers marked), the rms over the inliers,
  /// the linear stage's rms over them.
  void residuals() {
    std::string behind;
    double ss = 0.0;
    for (int i = 0; i < n_; ++i) {
      const Eigen::Vector3d pc = res_.camera.to_camera(pts_[i].p_m);
      PointResidual pr;
      pr.n = pts_[i].n;
      pr.cam = pts_[i].cam;
      pr.line = pts_[i].line;
      pr.r_px = pts_[i].uv_px - res_.camera.project_camera(pc);
      pr.px = pr.r_px.norm();
      pr.outlier = !inlier_[i];
      if (pr.outlier) {
        res_.outliers.push_back(pts_[i].n);
      } else {
        if (!(pc.z() > 0.0)) behind += (behind.empty() ? "" : ", ") + point_name(pts_[i]);
        ss += pr.px * pr.px;
        res_.max_px = std::max(res_.max_px, pr.px);
        in_pts_.push_back(pts_[i]);
      }
      res_.residuals.push_back(pr);
    }
    if (!behind.empty()) throw EstimationInputError(who_ + "points behind the camera: " + behind);
    res_.rms_px = std::sqrt(ss / static_cast<int>(in_pts_.size()));
    if (res_.outliers.empty()) {
      res_.linear_rms_px = rms_px(linear_all_, in_pts_);
    } else {  // the linear stage on the inliers alone
      bool cross = false;
      res_.linear_rms_px = rms_px(calibrate_camera_linear(in_pts_, vp_, name_, opt_.rank_tolerance, &cross), in_pts_);
    }
  }

  /// Covariance in (roll, pitch, yaw, x, y, z, f): J with the rotation
  /// columns mapped from body increments to rpy rates, s^2 (J^T J)^-1; with
  /// the arm model's term when its links have an sd.
  void covariance() {
    const int m = static_cast<int>(in_pts_.size());
    idx_.clear();
    for (int i = 0; i < n_; ++i)
      if (inlier_[i]) idx_.push_back(i);
    Eigen::VectorXd e(2 * m);
    Eigen::Matrix<double, Eigen::Dynamic, 7> J(2 * m, 7);
    evaluate(state_, e, &J);
    res_.information = J.transpose() * J;
    const Eigen::Vector3d rpy = rpy_from_rotation(state_.R);
    J.leftCols<3>() = (J.leftCols<3>() * rpy_rate_matrix(rpy)).eval();
    const double dof = std::max(2 * m - 7, 1);
    const double s2 = e.squaredNorm() / dof;
    res_.residual_variance_px2 = s2;
    const Eigen::Matrix<double, 7, 7> H = J.transpose() * J;
    const Eigen::Matrix<double, 7, 7> H_inv = H.inverse();
    res_.covariance = s2 * H_inv;
    if (opt_.arm_link_sigma_m > 0.0) add_arm_model(J, e, H_inv, rpy, dof);
    res_.sigma = res_.covariance.diagonal().cwiseMax(0.0).cwiseSqrt();
  }

  /// The camera's response to the link lengths: K = H^-1 J^T J_links, with
  /// J_links the pixels' motion per metre of each link (d uv / d p times the
  /// point's sensitivity); the links independent with sd arm_link_sigma_m.
  void add_arm_model(const Eigen::Matrix<double, Eigen::Dynamic, 7>& J, const Eigen::VectorXd& e,
                     const Eigen::Matrix<double, 7, 7>& H_inv, const Eigen::Vector3d& rpy, double dof) {
    const int m = static_cast<int>(idx_.size());
    Eigen::Index links = 0;
    for (const int i : idx_) links = std::max(links, pts_[i].dp_dlinks.cols());
    if (links == 0) return;
    Eigen::MatrixXd J_links = Eigen::MatrixXd::Zero(2 * m, links);
    for (int k = 0; k < m; ++k) {
      const Correspondence& c = pts_[idx_[k]];
      if (c.dp_dlinks.cols() == 0) continue;
      const camera::Projection pr = camera::project_with_jacobians(state_.R, state_.c, state_.f, pp_, c.p_m);
      J_links.block(2 * k, 0, 2, c.dp_dlinks.cols()) = pr.d_point * c.dp_dlinks;
    }
    const Eigen::MatrixXd JtJl = J.transpose() * J_links;
    const Eigen::MatrixXd K = H_inv * JtJl;
    const double var_links = opt_.arm_link_sigma_m * opt_.arm_link_sigma_m;
    res_.arm_model_covariance = var_links * K * K.transpose();
    res_.arm_link_sigma_m = opt_.arm_link_sigma_m;
    res_.link_sensitivity = K;  // rpy rates -> body increments: d_body = W d_rpy
    res_.link_sensitivity.topRows<3>() = rpy_rate_matrix(rpy) * K.topRows<3>();
    // The residuals carry the links' part the camera cannot take, expected
    // var_links tr(J_links^T (I - J H^-1 J^T) J_links); counting it again as
    // pixel noise would count the arm twice (measured: 1.4x too wide
    // without pixel noise). The pixel noise is what is left (>= 0).
    const double arm_in_residuals = var_links * (J_links.squaredNorm() - (JtJl.transpose() * K).trace());
    const double noise_s2 = std::max(0.0, e.squaredNorm() - arm_in_residuals) / dof;
    res_.covariance = noise_s2 * H_inv + res_.arm_model_covariance;
  }

  const std::vector<Correspondence>& pts_;
  const camera::Viewport vp_;
  const std::string& name_;
  const std::string who_;
  const CalibrationOptions& opt_;
  CalibrationResult& res_;
  const int n_;
  const Eigen::Vector2d pp_;
  std::vector<int> idx_;  ///< the points of the current fit
  std::vector<bool> inlier_;
  std::vector<Correspondence> in_pts_;
  CamState state_{};
  int iterations_ = 0;
  camera::Camera linear_all_;
};

}  // namespace

CalibrationResult calibrate_camera(const std::vector<Correspondence>& pts, const camera::Viewport& vp, const std::string& name,
                                   const CalibrationOptions& opt) {
  check_points(pts, name);
  const std::string who = "camera '" + name + "': ";
  check_in_viewport(pts, vp, "camera '" + name + "'");
  if (!(opt.arm_link_sigma_m >= 0.0) || !std::isfinite(opt.arm_link_sigma_m))
    throw EstimationInputError(who + "the arm's link-length sd must be a finite number >= 0 m, not " +
                               std::to_string(opt.arm_link_sigma_m));
  CalibrationResult res;
  CameraFit(pts, vp, name, opt, res).run();
  return res;
}

}  // namespace foresight::calibration
