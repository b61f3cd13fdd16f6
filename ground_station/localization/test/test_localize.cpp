#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "../../calibration/test/synthetic.hpp"
#include "foresight/localization/localize.hpp"

using namespace foresight;
using foresight::testing::random_camera;

namespace {

struct Scenario {
  std::map<std::string, Camera> cameras;
  Pose base_T_object;
  std::vector<Correspondence> exact;  // object-frame points, exact pixels
};

/// `views` cameras around a random object pose; `per_view` random model
/// points (object frame, in a 0.5 m box; planar: all on z = 0) seen by each.
Scenario make_setup(std::mt19937& rng, int views, int per_view, bool planar = false) {
  Scenario s;
  std::uniform_real_distribution<double> a(-M_PI, M_PI), u(-0.25, 0.25);
  s.base_T_object = make_pose(Eigen::Vector3d(1.0, 0.2, 0.5) + Eigen::Vector3d(u(rng), u(rng), u(rng)),
                              Eigen::Vector3d(a(rng), a(rng) / 2, a(rng)));
  const Eigen::Vector3d centre = s.base_T_object.translation();
  for (int v = 0; v < views; ++v) {
    Camera cam = random_camera(rng, centre, 1.5 + 0.5 * v, 500.0 + 150.0 * v);
    cam.name = "cam" + std::to_string(v + 1);
    int n = 0;
    for (int tries = 0; tries < 10000 && n < per_view; ++tries) {
      const Eigen::Vector3d p(u(rng), u(rng), planar ? 0.0 : u(rng));
      const Eigen::Vector3d pb = s.base_T_object * p;
      if (!cam.in_front(pb) || !cam.in_view(cam.project(pb))) continue;
      Correspondence c;
      c.n = ++n;
      c.cam = cam.name;
      c.p_m = p;
      c.uv_px = cam.project(pb);
      c.line = static_cast<int>(s.exact.size()) + 2;
      s.exact.push_back(c);
    }
    s.cameras[cam.name] = cam;
  }
  return s;
}

std::vector<Correspondence> noisy(std::mt19937& rng, std::vector<Correspondence> pts, double sd) {
  std::normal_distribution<double> g(0.0, sd);
  for (auto& c : pts) c.uv_px += Eigen::Vector2d(g(rng), g(rng));
  return pts;
}

/// (roll, pitch, yaw, x, y, z) error of an estimate, rotation error mapped
/// into rpy rates at the truth.
Eigen::Matrix<double, 6, 1> pose_error(const Pose& est, const Pose& truth) {
  Eigen::Matrix<double, 6, 1> d;
  const Eigen::AngleAxisd aa(truth.linear().transpose() * est.linear());
  d.head<3>() = rpy_rate_matrix(rpy_from_rotation(truth.linear())).inverse() * (aa.angle() * aa.axis());
  d.tail<3>() = est.translation() - truth.translation();
  return d;
}

std::string error_of(const std::vector<Correspondence>& pts, const std::map<std::string, Camera>& cams,
                     const std::vector<std::string>& views = {}) {
  LocalizationOptions opt;
  opt.views = views;
  try {
    localize_object(pts, cams, opt);
  } catch (const Error& e) {  // EstimationInputError or EstimationError
    return e.what();
  }
  return "(no error)";
}

}  // namespace

TEST(Localize, NoiseFreeRecoversPoseFromOneToFourViews) {
  std::mt19937 rng(21);
  for (int trial = 0; trial < 24; ++trial) {
    const int views = 1 + trial % 4;
    const bool planar = trial % 3 == 2;
    const Scenario s = make_setup(rng, views, 8, planar);
    const LocalizationResult r = localize_object(s.exact, s.cameras);
    const auto d = pose_error(r.base_T_object, s.base_T_object);
    EXPECT_LT(d.cwiseAbs().maxCoeff(), 1e-6) << "trial " << trial << " views " << views << " planar " << planar;
    EXPECT_LT(r.rms_px, 1e-6);
    EXPECT_EQ(static_cast<int>(r.views.size()), views);
    // The linear stage (eq. 7-8) alone is exact on exact data.
    const auto dl = pose_error(localize_object_linear(s.exact, s.cameras), s.base_T_object);
    EXPECT_LT(dl.cwiseAbs().maxCoeff(), 1e-6) << "linear, trial " << trial;
  }
}

TEST(Localize, NoisyWithinThreeSigmaAndSigmaMatchesSpread) {
  std::mt19937 rng(5);
  for (const int views : {1, 3}) {
    const Scenario s = make_setup(rng, views, 10);
    const int trials = 300;
    Eigen::Matrix<double, 6, 1> sum_sq = Eigen::Matrix<double, 6, 1>::Zero(), sum_sigma = sum_sq;
    int within = 0;
    for (int t = 0; t < trials; ++t) {
      LocalizationOptions opt;
      opt.outliers.enabled = false;
      const LocalizationResult r = localize_object(noisy(rng, s.exact, 1.0), s.cameras, opt);
      const auto d = pose_error(r.base_T_object, s.base_T_object);
      Eigen::Matrix<double, 6, 1> sd;
      sd << r.sigma_rpy_rad, r.sigma_position_m;
      sum_sq += d.cwiseAbs2();
      sum_sigma += sd;
      if ((d.cwiseAbs().array() < 3.0 * sd.array()).all()) ++within;
    }
    const Eigen::Matrix<double, 6, 1> spread = (sum_sq / trials).cwiseSqrt();
    for (int i = 0; i < 6; ++i)
      EXPECT_NEAR(sum_sigma[i] / trials / spread[i], 1.0, 0.2) << views << " views, parameter " << i;
    EXPECT_GE(within, static_cast<int>(0.95 * trials)) << views << " views";
  }
}

TEST(Localize, PlantedOutliersFlaggedAndFitUnharmed) {
  std::mt19937 rng(8);
  const Scenario s = make_setup(rng, 3, 10);
  auto pts = noisy(rng, s.exact, 0.5);
  std::vector<Correspondence> clean;
  for (std::size_t i = 0; i < pts.size(); ++i)
    if (i != 3 && i != 14) clean.push_back(pts[i]);
  pts[3].uv_px += Eigen::Vector2d(30.0, 0.0);
  pts[14].uv_px += Eigen::Vector2d(-12.0, 15.0);
  const LocalizationResult r = localize_object(pts, s.cameras);
  EXPECT_EQ(r.outliers, (std::vector<int>{pts[3].n, pts[14].n}));
  EXPECT_TRUE(r.residuals[3].outlier && r.residuals[14].outlier);
  EXPECT_GT(r.residuals[3].px, 25.0);
  LocalizationOptions off;
  off.outliers.enabled = false;
  const LocalizationResult ref = localize_object(clean, s.cameras, off);
  const auto d = pose_error(r.base_T_object, ref.base_T_object);
  EXPECT_LT(d.head<3>().cwiseAbs().maxCoeff(), 1e-3 * ref.sigma_rpy_rad.minCoeff());
  EXPECT_LT(d.tail<3>().cwiseAbs().maxCoeff(), 1e-3 * ref.sigma_position_m.minCoeff());
}

TEST(Localize, ViewSelection) {
  std::mt19937 rng(9);
  const Scenario s = make_setup(rng, 3, 8);
  LocalizationOptions opt;
  opt.views = {"cam3", "cam1"};
  const LocalizationResult r = localize_object(s.exact, s.cameras, opt);
  EXPECT_EQ(r.views, (std::vector<std::string>{"cam1", "cam3"}));
  EXPECT_EQ(r.n_points, 16);
  EXPECT_LT(pose_error(r.base_T_object, s.base_T_object).cwiseAbs().maxCoeff(), 1e-6);
}

TEST(LocalizeBadInput, PointBehindItsCamera) {
  // Projection is algebraic: a model point behind the camera still "projects";
  // the exact fit reproduces it and then shows it behind its camera.
  std::mt19937 rng(12);
  const Scenario s = make_setup(rng, 2, 8);
  auto pts = s.exact;
  const Camera& cam = s.cameras.at("cam1");
  Correspondence c = pts[0];
  c.n = 42;
  c.line = 20;
  c.p_m = s.base_T_object.inverse() * (cam.base_T_camera * Eigen::Vector3d(0.1, 0.05, -0.3));
  c.uv_px = cam.project_camera(cam.to_camera(s.base_T_object * c.p_m));
  pts.push_back(c);
  EXPECT_EQ(error_of(pts, s.cameras), "points behind their camera at the fitted pose: n=42 in view 'cam1' (line 20)");
}

TEST(LocalizeBadInput, EveryBadInputHasItsMessage) {
  std::mt19937 rng(10);
  const Scenario s = make_setup(rng, 2, 8);
  auto pts = s.exact;
  pts[2].cam = "top";
  pts[2].line = 4;
  EXPECT_EQ(error_of(pts, s.cameras), "point n=3 (line 4): unknown camera 'top' (known cameras: cam1, cam2)");
  EXPECT_EQ(error_of(s.exact, s.cameras, {"cam1", "cam9"}), "unknown view 'cam9' (known cameras: cam1, cam2)");
  auto only1 = s.exact;
  only1.resize(8);  // the first view's points
  EXPECT_EQ(error_of(only1, s.cameras, {"cam1", "cam2"}), "view 'cam2' has no points");
  auto five = s.exact;
  five.resize(5);
  EXPECT_EQ(error_of(five, s.cameras), "localization needs at least 6 clicked points over all views, got 5");
  auto nan = s.exact;
  nan[1].p_m.y() = std::nan("");
  nan[1].line = 3;
  EXPECT_EQ(error_of(nan, s.cameras), "point n=2 in view 'cam1' (line 3) has a non-finite coordinate");
  auto three = s.exact;  // 16 clicks of only 3 distinct model points
  for (std::size_t i = 0; i < three.size(); ++i) {
    const Eigen::Vector3d corners[3] = {{0, 0, 0}, {0.1, 0, 0}, {0, 0.1, 0}};
    three[i].p_m = corners[i % 3];
    three[i].uv_px = s.cameras.at(three[i].cam).project(s.base_T_object * three[i].p_m);
  }
  EXPECT_EQ(error_of(three, s.cameras), "localization needs at least 4 distinct model points, got 3");
  auto line = s.exact;
  for (std::size_t i = 0; i < line.size(); ++i) {
    line[i].p_m = Eigen::Vector3d(0.03 * static_cast<double>(i % 8), 0.0, 0.0);
    line[i].uv_px = s.cameras.at(line[i].cam).project(s.base_T_object * line[i].p_m);
  }
  EXPECT_EQ(error_of(line, s.cameras),
            "the 8 distinct model points are collinear: the object's rotation about that line is undetermined");
}

TEST(Localize, JointRefinementWithCameraPriors) {
  // Cameras calibrated from noisy clicks: the joint fit (pose + cameras under
  // their calibration prior) reports a sigma that includes the cameras'
  // uncertainty, matching the Monte Carlo spread; the paper's 6-parameter
  // fit takes the cameras as exact and under-reports.
  std::mt19937 rng(31);
  const Scenario s = make_setup(rng, 3, 8);
  std::map<std::string, std::vector<Correspondence>> cal_exact;
  for (const auto& [name, cam] : s.cameras) {
    cal_exact[name] = foresight::testing::random_points(rng, cam, s.base_T_object.translation(), 0.6, 20, 0.0);
    for (auto& c : cal_exact[name]) c.cam = name;
  }
  // Noise-free: exact, with or without priors.
  {
    LocalizationOptions opt;
    for (const auto& [name, pts] : cal_exact)
      opt.camera_information[name] = calibrate_camera(pts, s.cameras.at(name).viewport, name).information;
    const LocalizationResult r = localize_object(s.exact, s.cameras, opt);
    EXPECT_TRUE(r.camera_uncertainty);
    EXPECT_EQ(r.refined_cameras.size(), 3u);
    EXPECT_LT(pose_error(r.base_T_object, s.base_T_object).cwiseAbs().maxCoeff(), 1e-6);
  }
  const int trials = 200;
  Eigen::Matrix<double, 6, 1> sq_joint = Eigen::Matrix<double, 6, 1>::Zero(), sig_joint = sq_joint, sig_plain = sq_joint;
  for (int t = 0; t < trials; ++t) {
    std::map<std::string, Camera> cams;
    LocalizationOptions joint, plain;
    joint.outliers.enabled = plain.outliers.enabled = false;
    for (const auto& [name, pts] : cal_exact) {
      CalibrationOptions co;
      co.outliers.enabled = false;
      const CalibrationResult c = calibrate_camera(noisy(rng, pts, 1.0), s.cameras.at(name).viewport, name, co);
      cams[name] = c.camera;
      joint.camera_information[name] = c.information;
    }
    const auto clicks = noisy(rng, s.exact, 1.0);
    const LocalizationResult rj = localize_object(clicks, cams, joint);
    const LocalizationResult rp = localize_object(clicks, cams, plain);
    sq_joint += pose_error(rj.base_T_object, s.base_T_object).cwiseAbs2();
    Eigen::Matrix<double, 6, 1> a, b;
    a << rj.sigma_rpy_rad, rj.sigma_position_m;
    b << rp.sigma_rpy_rad, rp.sigma_position_m;
    sig_joint += a;
    sig_plain += b;
  }
  const Eigen::Matrix<double, 6, 1> spread = (sq_joint / trials).cwiseSqrt();
  for (int i = 0; i < 6; ++i) {
    EXPECT_NEAR(sig_joint[i] / trials / spread[i], 1.0, 0.2) << "parameter " << i;
    EXPECT_LT(sig_plain[i], sig_joint[i]) << "parameter " << i;
  }
}
