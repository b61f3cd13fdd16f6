// `foresight eval insertion` (insertion_study.hpp).
#include "foresight/session/insertion_study.hpp"

#include <Eigen/Cholesky>
#include <Eigen/Geometry>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <numeric>
#include <random>
#include <stdexcept>

#include "foresight/calibration/calibrate.hpp"
#include "foresight/common/error.hpp"
#include "foresight/common/input_limits.hpp"
#include "foresight/common/kinematics.hpp"
#include "foresight/common/object_model.hpp"
#include "foresight/common/robot_model.hpp"
#include "foresight/common/scene.hpp"
#include "foresight/contact_check/insert_check.hpp"
#include "foresight/contact_check/tip_error.hpp"
#include "foresight/localization/accuracy_study.hpp"
#include "foresight/localization/localize.hpp"
#include "foresight/session/processes.hpp"

namespace foresight::session {

namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;
using nlohmann::json;

constexpr int kMaxTrials = 10000;  // the runner's batch limit (simulate_insertions.hpp)
constexpr int kMaxRedraws = 50;    // draws of one trial before the study gives up

void check_request(const InsertionStudyRequest& a) {
  if (a.trials < 1) throw std::invalid_argument("--trials must be at least 1");
  if (a.trials > kMaxTrials) throw std::invalid_argument("--trials must be at most " + std::to_string(kMaxTrials));
  if (a.seed < 0) throw std::invalid_argument("--seed must be a non-negative integer");
  if (!(a.noise_px > 0.0 && a.noise_px <= limits::kMaxPixelNoise_px))
    throw std::invalid_argument("--noise-px must be a number in (0, " +
                                std::to_string(static_cast<int>(limits::kMaxPixelNoise_px)) + "] px");
  if (!(a.arm_error_mm >= 0.0 && a.arm_error_mm <= 50.0))
    throw std::invalid_argument("--arm-error-mm must be a number in [0, 50]");
  if (!(a.arm_sigma_mm >= 0.0 && a.arm_sigma_mm <= 50.0))
    throw std::invalid_argument("--arm-sigma-mm must be a number in [0, 50]");
  if (!(a.arm_error_max_mm == 0.0 || (a.arm_error_max_mm <= 50.0 && a.arm_error_mm > 0.0 && a.arm_error_max_mm > a.arm_error_mm)))
    throw std::invalid_argument("--arm-error-max-mm must be 0 (off) or in (--arm-error-mm, 50]");
  if (!(a.encoder_sigma_rad >= 0.0 && a.encoder_sigma_rad <= 0.01))
    throw std::invalid_argument("--encoder-sigma-rad must be a number in [0, 0.01]");
  if (!(a.min_p_success > 0.0 && a.min_p_success < 1.0))
    throw std::invalid_argument("--min-p must be a number in (0, 1)");
  if (a.bins < 1 || a.bins > 100) throw std::invalid_argument("--bins must be in [1, 100]");
  if (!(a.depth_m > 0.0 && a.depth_m <= 0.5)) throw std::invalid_argument("--depth-m must be a number in (0, 0.5]");
  if (!(a.standoff_m >= 0.0 && a.standoff_m <= 0.05)) throw std::invalid_argument("--standoff-m must be a number in [0, 0.05]");
}

/// What every trial shares.
struct Site {
  Scene scene;
  ObjectModel object;
  RobotModel robot;
  localization::StudySetup setup;
  std::vector<std::vector<Eigen::Matrix3Xd>> dp_dlinks;
  Pose object_T_hole = Pose::Identity(), object_T_start = Pose::Identity();
  InsertParams params;
  InsertCapture capture;
};

/// A trial's draw and prediction, and the true start for the plant.
struct Drawn {
  InsertionTrialRecord record;
  Pose hole_T_tip = Pose::Identity();  ///< the true start, in the true hole frame
};

/// Whether the start error e (hole_T_tip's) is in the capture region
/// (common/insert_capture.hpp): the tilt in its cone, and the lateral within
/// the clearance with the hole's axial window or in the rest of the disc
/// with the face's.
bool in_capture_region(const contact_check::Vector6& e, const InsertCapture& c) {
  const double lateral = e.segment<2>(3).norm(), z = e[5];
  if (e.head<2>().norm() > c.tilt_rad || lateral > c.lateral_m || z < c.axial_min_m) return false;
  return z <= c.axial_max_m || (lateral <= c.clearance_m && z <= std::max(c.axial_max_m, c.axial_max_in_hole_m));
}

/// Mahalanobis^2 of d under C (pseudo-inverse on a singular C).
template <int N>
double mahalanobis2(const Eigen::Matrix<double, N, 1>& d, const Eigen::Matrix<double, N, N>& C) {
  const Eigen::LDLT<Eigen::Matrix<double, N, N>> ldlt(C);
  if (ldlt.info() != Eigen::Success) return std::nan("");
  return d.dot(ldlt.solve(d));
}

/// One draw of trial `id` (attempt `attempt`): std::nullopt-like false when
/// the ground could not produce a prediction (a calibration or the
/// localization failed, or IK cannot reach the estimated start).
bool draw_trial(const Site& site, const InsertionStudyRequest& a, int id, int attempt, Drawn& out) {
  std::seed_seq seq{static_cast<std::uint32_t>(a.seed & 0xffffffff), static_cast<std::uint32_t>(a.seed >> 32),
                    static_cast<std::uint32_t>(id), static_cast<std::uint32_t>(attempt)};
  std::mt19937_64 rng(seq);
  const int nv = static_cast<int>(site.setup.views.size());
  // The views: 1..nv of them, uniform in number, then which.
  std::vector<int> all(static_cast<std::size_t>(nv));
  std::iota(all.begin(), all.end(), 0);
  const int k = std::uniform_int_distribution<int>(1, nv)(rng);
  std::shuffle(all.begin(), all.end(), rng);
  std::vector<int> views(all.begin(), all.begin() + k);
  std::sort(views.begin(), views.end());
  // The true arm, and what the ground believes of it.
  double error_mm = a.arm_error_mm, sigma_mm = a.arm_sigma_mm;
  if (a.arm_error_max_mm > 0.0)
    sigma_mm = error_mm =
        std::exp(std::uniform_real_distribution<double>(std::log(a.arm_error_mm), std::log(a.arm_error_max_mm))(rng));
  out.record.arm_error_mm = error_mm;
  std::normal_distribution<double> link_error(0.0, error_mm * 1e-3);
  std::vector<double> delta(static_cast<std::size_t>(site.robot.segment_count()), 0.0);
  double link2 = 0.0;
  const std::vector<int> links = site.robot.offset_segments();
  for (const int s : links) {
    delta[static_cast<std::size_t>(s)] = error_mm > 0.0 ? link_error(rng) : 0.0;
    link2 += delta[static_cast<std::size_t>(s)] * delta[static_cast<std::size_t>(s)];
  }
  const RobotModel true_arm = site.robot.with_link_lengths_changed(delta);
  // Clicks, calibration (the nominal arm believed, its link sigma), localization.
  std::normal_distribution<double> noise(0.0, a.noise_px);
  calibration::CalibrationOptions co;
  co.arm_link_sigma_m = sigma_mm * 1e-3;
  localization::LocalizationResult lr;
  try {
    const localization::ClickCalibration cc = localization::calibrate_from_arm_clicks(
        site.setup, views, true_arm, site.dp_dlinks, co, [&] { return noise(rng); });
    localization::LocalizationOptions lo;
    for (const int v : views) lo.views.push_back(site.setup.views[static_cast<std::size_t>(v)].truth.name);
    lo.camera_covariance = cc.noise_covariance;
    if (co.arm_link_sigma_m > 0.0) {
      lo.camera_link_sensitivity = cc.link_sensitivity;
      lo.arm_link_sigma_m = co.arm_link_sigma_m;
    }
    lr = localization::localize_object(cc.object, cc.cameras, lo);
  } catch (const Error&) {  // an estimation that failed: the operator would click again
    return false;
  }
  // The prediction at the approach's end, and the approach's joints (IK on
  // the nominal arm to the estimated start).
  contact_check::ObjectEstimate est;
  est.base_T_object = lr.base_T_object;
  est.covariance = lr.covariance;
  est.arm_link_sensitivity = lr.arm_link_sensitivity;
  est.arm_link_sigma_m = lr.arm_link_sensitivity.size() > 0 ? co.arm_link_sigma_m : 0.0;
  const contact_check::ArmUncertainty arm{sigma_mm * 1e-3, a.encoder_sigma_rad};
  contact_check::ToolTip tool;
  try {
    tool = contact_check::tool_tip_uncertainty(site.robot, est.base_T_object * site.object_T_start, arm);
  } catch (const std::runtime_error&) {
    return false;
  }
  const contact_check::LocalCovariance tip =
      contact_check::tip_error_at_hole(est, site.object_T_hole, site.object_T_start, tool, arm);
  const contact_check::InsertPrediction p = contact_check::predict_insert(tip, site.capture, a.min_p_success);
  // A diagnostic beside p: the mass of the same Gaussian in the same region
  // by sampling, every cross term kept (predict_insert integrates lateral
  // and axial jointly but takes the tilt as independent of them).
  double p_joint = 0.0;
  {
    const Eigen::LLT<contact_check::Matrix6> llt(tip.covariance + 1e-18 * contact_check::Matrix6::Identity());
    const contact_check::Matrix6 L = llt.matrixL();
    std::mt19937_64 mc(static_cast<std::uint64_t>(id) * 7919u + 17u);
    std::normal_distribution<double> z(0.0, 1.0);
    constexpr int kSamples = 20000;
    int in = 0;
    for (int i = 0; i < kSamples; ++i) {
      contact_check::Vector6 u;
      for (int k = 0; k < 6; ++k) u[k] = z(mc);
      const contact_check::Vector6 x = tip.mean + L * u;
      in += in_capture_region(x, site.capture) ? 1 : 0;
    }
    p_joint = static_cast<double>(in) / kSamples;
  }
  // The truth: the true arm at the commanded joints (with the encoders'
  // error), relative to the true hole.
  std::normal_distribution<double> encoder(0.0, a.encoder_sigma_rad);
  Eigen::VectorXd q = tool.q;
  for (Eigen::Index j = 0; j < q.size(); ++j) q[j] += a.encoder_sigma_rad > 0.0 ? encoder(rng) : 0.0;
  KinematicsWorkspace ws(true_arm);
  const Pose base_T_tip = forward_kinematics(true_arm, ws, q);
  out.hole_T_tip = (site.setup.base_T_object * site.object_T_hole).inverse() * base_T_tip;
  const contact_check::Vector6 e = contact_check::pose_error_vector(out.hole_T_tip);
  const contact_check::Vector6 d = e - tip.mean;
  InsertionTrialRecord& r = out.record;
  r.m2_lateral = mahalanobis2<2>(Eigen::Vector2d(d.segment<2>(3)), Eigen::Matrix2d(tip.covariance.block<2, 2>(3, 3)));
  r.m2_tilt = mahalanobis2<2>(Eigen::Vector2d(d.head<2>()), Eigen::Matrix2d(tip.covariance.topLeftCorner<2, 2>()));
  r.m2_axial = d[5] * d[5] / std::max(tip.covariance(5, 5), 1e-300);
  r.m2_all = mahalanobis2<6>(d, tip.covariance);
  r.id = id;
  r.views = views;
  r.p_success = p.p_success;
  r.p_lateral = p.p_lateral;
  r.p_tilt = p.p_tilt;
  r.p_axial = p.p_axial;
  r.p_joint = p_joint;
  r.lateral95_m = p.lateral95_m;
  r.axial95_m = p.axial95_m;
  r.tilt95_deg = p.tilt95_deg;
  r.go = p.go;
  r.true_lateral_m = out.hole_T_tip.translation().head<2>().norm();
  r.true_axial_m = out.hole_T_tip.translation().z();
  r.true_tilt_deg = std::acos(std::clamp(out.hole_T_tip.linear()(2, 2), -1.0, 1.0)) * 180.0 / M_PI;
  r.in_capture = in_capture_region(e, site.capture);
  r.estimate_position_error_m = (lr.base_T_object.translation() - site.setup.base_T_object.translation()).norm();
  r.link_error_rms_m = links.empty() ? 0.0 : std::sqrt(link2 / static_cast<double>(links.size()));
  r.redrawn = attempt;
  return true;
}

json pose_rows(const Pose& T) {
  json rows = json::array();
  for (int i = 0; i < 4; ++i) rows.push_back({T.matrix()(i, 0), T.matrix()(i, 1), T.matrix()(i, 2), T.matrix()(i, 3)});
  return rows;
}

/// A fresh directory for the batch; removed with the object unless kept.
struct WorkDir {
  std::string path;
  bool remove = false;
  explicit WorkDir(const std::string& given) {
    if (!given.empty()) {
      fs::create_directories(given);
      path = given;
      return;
    }
    std::string pattern = (fs::temp_directory_path() / "foresight_eval_insertion_XXXXXX").string();
    if (::mkdtemp(pattern.data()) == nullptr) throw ComputationError("cannot create a directory under " + fs::temp_directory_path().string());
    path = pattern;
    remove = true;
  }
  ~WorkDir() {
    std::error_code ec;
    if (remove) fs::remove_all(path, ec);
  }
  WorkDir(const WorkDir&) = delete;
  WorkDir& operator=(const WorkDir&) = delete;
};

/// foresight-remote: --remote, or the one beside this executable.
std::string remote_path(const InsertionStudyRequest& a) {
  const std::string remote = a.remote.empty() ? executable_dir() + "/foresight-remote" : a.remote;
  if (!fs::exists(remote))
    throw InputError(remote + ": not found (foresight-remote runs the insertions on the simulated plant; build it "
                              "beside foresight or give --remote)");
  return remote;
}

/// The plant's insertions: `foresight-remote simulate-insertions` on one
/// batch; its parsed output.
json run_plant(const InsertionStudyRequest& a, const Site& site, const std::vector<Drawn>& drawn, double* elapsed_s) {
  const std::string remote = remote_path(a);
  const WorkDir dir(a.work_dir);
  json batch = {{"object", fs::absolute(a.object).string()},
                {"tag", a.hole_tag},
                {"params", {{"depth_m", site.params.depth_m}}},
                {"trials", json::array()}};
  for (const Drawn& d : drawn) batch["trials"].push_back({{"id", d.record.id}, {"tag_T_tip", pose_rows(d.hole_T_tip)}});
  const std::string batch_path = dir.path + "/batch.json", out_path = dir.path + "/results.json",
                    err_path = dir.path + "/runner.err";
  {
    std::ofstream f(batch_path);
    f.precision(17);
    f << batch.dump() << "\n";
    if (!f) throw ComputationError(batch_path + ": cannot write the batch");
  }
  const auto t0 = Clock::now();
  const pid_t pid = spawn({remote, "simulate-insertions", "--batch", batch_path, "--json"}, out_path, err_path);
  const double timeout_s = 120.0 + 2.0 * static_cast<double>(drawn.size());
  const int rc = wait_for(pid, timeout_s);
  *elapsed_s = since(t0);
  if (rc == -1) {
    stop_child(pid, 2.0);
    throw ComputationError("foresight-remote simulate-insertions did not finish within " + std::to_string(static_cast<int>(timeout_s)) + " s");
  }
  if (rc != 0)
    throw ComputationError("foresight-remote simulate-insertions failed (exit " + std::to_string(rc) + "): " +
                           read_log(err_path));
  json out;
  try {
    out = json::parse(read_log(out_path));
  } catch (const json::exception& e) {
    throw ComputationError(std::string("foresight-remote simulate-insertions: its output is not JSON: ") + e.what());
  }
  if (!out.contains("results") || !out["results"].is_array())
    throw ComputationError("foresight-remote simulate-insertions: its output has no \"results\" array");
  return out;
}

void summarize(const InsertionStudyRequest& a, InsertionStudy& s) {
  const int nb = a.bins;
  std::vector<InsertionBin> bins(static_cast<std::size_t>(nb));
  std::vector<double> sum_p(static_cast<std::size_t>(nb), 0.0), successes(static_cast<std::size_t>(nb), 0.0),
      sum_joint(static_cast<std::size_t>(nb), 0.0), in_capture(static_cast<std::size_t>(nb), 0.0);
  double brier = 0.0, sum_p_all = 0.0;
  int ok = 0;
  for (const InsertionTrialRecord& r : s.records) {
    const int b = std::min(nb - 1, static_cast<int>(std::floor(r.p_success * nb)));
    const auto bi = static_cast<std::size_t>(std::max(0, b));
    ++bins[bi].n;
    sum_p[bi] += r.p_success;
    successes[bi] += r.success ? 1.0 : 0.0;
    sum_joint[bi] += r.p_joint;
    in_capture[bi] += r.in_capture ? 1.0 : 0.0;
    const double outcome = r.success ? 1.0 : 0.0;
    brier += (r.p_success - outcome) * (r.p_success - outcome);
    sum_p_all += r.p_success;
    ok += r.success ? 1 : 0;
    if (r.go) {
      ++s.go;
      s.go_failures += r.success ? 0 : 1;
    } else {
      ++s.no_go;
      s.no_go_failures += r.success ? 0 : 1;
    }
  }
  for (int b = 0; b < nb; ++b) {
    InsertionBin& bin = bins[static_cast<std::size_t>(b)];
    bin.lo = static_cast<double>(b) / nb;
    bin.hi = static_cast<double>(b + 1) / nb;
    if (bin.n == 0) continue;
    bin.p_predicted = sum_p[static_cast<std::size_t>(b)] / bin.n;
    bin.observed_success = successes[static_cast<std::size_t>(b)] / bin.n;
    bin.se = std::sqrt(bin.p_predicted * (1.0 - bin.p_predicted) / bin.n);
    bin.p_joint = sum_joint[static_cast<std::size_t>(b)] / bin.n;
    bin.in_capture = in_capture[static_cast<std::size_t>(b)] / bin.n;
    s.bins.push_back(bin);
  }
  const double n = static_cast<double>(s.records.size());
  s.brier = brier / n;
  s.success_rate = ok / n;
  s.mean_p_success = sum_p_all / n;
  s.go_failure_rate = s.go > 0 ? static_cast<double>(s.go_failures) / s.go : 0.0;
  s.no_go_precision = s.no_go > 0 ? static_cast<double>(s.no_go_failures) / s.no_go : 0.0;
}

}  // namespace

InsertionStudy study_insertion(const InsertionStudyRequest& a, const std::function<void(int done, int total)>& progress) {
  check_request(a);
  remote_path(a);  // before the trials: it must be there
  const auto t0 = Clock::now();
  Site site{Scene::from_file(a.scene), ObjectModel::from_file(a.object), RobotModel::from_file(a.robot), {}, {},
            Pose::Identity(), Pose::Identity(), {}, {}};
  const auto hole = site.object.tags.find(a.hole_tag);
  if (hole == site.object.tags.end())
    throw InputError(a.object + ": tag '" + a.hole_tag + "' is not in the object model '" + site.object.name + "'");
  site.object_T_hole = hole->second;
  site.object_T_start = site.object_T_hole * Pose(Eigen::Translation3d(0.0, 0.0, -a.standoff_m));
  site.setup = localization::make_study_setup(site.scene, site.object, {});
  localization::choose_calibration_points(site.setup, localization::arm_calibration_poses(site.robot));
  site.dp_dlinks = localization::calibration_link_sensitivities(site.setup, site.robot);
  site.params.depth_m = a.depth_m;
  InsertGeometry geometry;
  geometry.hole_diameter_m = site.object.hole_diameter_m;
  geometry.hole_depth_m = site.object.hole_depth_m;
  site.capture = insert_capture(site.params, geometry);

  InsertionStudy s;
  s.capture = site.capture;
  std::vector<Drawn> drawn(static_cast<std::size_t>(a.trials));
  for (int t = 0; t < a.trials; ++t) {
    int attempt = 0;
    while (!draw_trial(site, a, t, attempt, drawn[static_cast<std::size_t>(t)]))
      if (++attempt >= kMaxRedraws)
        throw ComputationError("trial " + std::to_string(t) + ": " + std::to_string(kMaxRedraws) +
                               " draws in a row gave no prediction (calibration, localization or the approach's IK failed)");
    s.redrawn += attempt;
    if (progress) progress(t + 1, a.trials);
  }
  s.ground_s = since(t0);
  const json plant = run_plant(a, site, drawn, &s.plant_s);
  s.plant_compute_s = plant.value("compute_s", 0.0);
  std::map<std::int64_t, const json*> by_id;
  for (const json& r : plant["results"]) by_id[r.value("id", std::int64_t{-1})] = &r;
  for (std::size_t t = 0; t < drawn.size(); ++t) {
    InsertionTrialRecord r = drawn[t].record;
    const auto it = by_id.find(r.id);
    if (it == by_id.end())
      throw ComputationError("foresight-remote simulate-insertions: no result for trial " + std::to_string(r.id));
    const json& j = *it->second;
    r.success = j.value("success", false);
    r.completed = j.value("completed", false);
    r.in_hole = j.value("in_hole", false);
    r.searched = j.value("searched", false);
    r.reason = j.value("reason", std::string());
    r.peak_force_n = j.value("peak_force_n", 0.0);
    r.sim_s = j.value("sim_s", 0.0);
    s.records.push_back(std::move(r));
  }
  summarize(a, s);
  return s;
}

nlohmann::json insertion_study_json(const InsertionStudyRequest& a, const InsertionStudy& s) {
  json bins = json::array();
  bool bins_ok = true;
  double worst_gap = 0.0;
  int checked = 0;
  for (const InsertionBin& b : s.bins) {
    const double gap = std::abs(b.p_predicted - b.observed_success);
    bins.push_back({{"p_predicted", b.p_predicted},
                    {"observed_success", b.observed_success},
                    {"n", b.n},
                    {"p_range", {b.lo, b.hi}},
                    {"binomial_se", b.se},
                    {"p_joint", b.p_joint},
                    {"in_capture", b.in_capture},
                    {"gap", gap}});
    if (b.n >= 20) {
      ++checked;
      worst_gap = std::max(worst_gap, gap);
      bins_ok = bins_ok && gap <= 0.05;
    }
  }
  // By number of views: where p comes from.
  json by_views = json::array();
  for (int k = 1; k <= 4; ++k) {
    int n = 0, ok = 0;
    double sp = 0.0;
    for (const auto& r : s.records)
      if (static_cast<int>(r.views.size()) == k) {
        ++n;
        ok += r.success ? 1 : 0;
        sp += r.p_success;
      }
    if (n > 0) by_views.push_back({{"views", k}, {"n", n}, {"mean_p_predicted", sp / n}, {"observed_success", static_cast<double>(ok) / n}});
  }
  // The covariance's honesty beside the decision's: the mean Mahalanobis^2
  // of the true start's error under the predicted covariance.
  double m2[4] = {0.0, 0.0, 0.0, 0.0};
  for (const auto& r : s.records) {
    m2[0] += r.m2_lateral;
    m2[1] += r.m2_tilt;
    m2[2] += r.m2_axial;
    m2[3] += r.m2_all;
  }
  const double nr = std::max<double>(1.0, static_cast<double>(s.records.size()));
  const json covariance_check = {{"mean_m2_lateral", m2[0] / nr}, {"mean_m2_tilt", m2[1] / nr},
                                 {"mean_m2_axial", m2[2] / nr}, {"mean_m2_all", m2[3] / nr},
                                 {"honest", {2, 2, 1, 6}}};
  std::map<std::string, int> reasons;
  for (const auto& r : s.records) ++reasons[r.success ? std::string("success") : r.reason];
  json records = json::array();
  for (const auto& r : s.records)
    records.push_back({{"id", r.id},
                       {"views", r.views},
                       {"arm_error_mm", r.arm_error_mm},
                       {"p_success", r.p_success},
                       {"p_lateral", r.p_lateral},
                       {"p_tilt", r.p_tilt},
                       {"p_axial", r.p_axial},
                       {"p_joint", r.p_joint},
                       {"in_capture", r.in_capture},
                       {"lateral95_m", r.lateral95_m},
                       {"axial95_m", r.axial95_m},
                       {"tilt95_deg", r.tilt95_deg},
                       {"verdict", r.go ? "go" : "no_go"},
                       {"true_lateral_m", r.true_lateral_m},
                       {"true_axial_m", r.true_axial_m},
                       {"true_tilt_deg", r.true_tilt_deg},
                       {"m2", {r.m2_lateral, r.m2_tilt, r.m2_axial, r.m2_all}},
                       {"estimate_position_error_m", r.estimate_position_error_m},
                       {"link_error_rms_m", r.link_error_rms_m},
                       {"redrawn", r.redrawn},
                       {"success", r.success},
                       {"completed", r.completed},
                       {"in_hole", r.in_hole},
                       {"searched", r.searched},
                       {"reason", r.reason},
                       {"peak_force_n", r.peak_force_n},
                       {"sim_s", r.sim_s}});
  return {{"trials", static_cast<int>(s.records.size())},
          {"bins", bins},
          {"brier", s.brier},
          {"no_go_precision", s.no_go_precision},
          {"go_failure_rate", s.go_failure_rate},
          {"go", s.go},
          {"go_failures", s.go_failures},
          {"no_go", s.no_go},
          {"no_go_failures", s.no_go_failures},
          {"success_rate", s.success_rate},
          {"mean_p_predicted", s.mean_p_success},
          {"targets",
           {{"bins_within_0_05", {{"met", checked > 0 && bins_ok}, {"bins_with_20", checked}, {"worst_gap", worst_gap}}},
            {"go_failure_rate_at_most_0_01", {{"met", s.go > 0 && s.go_failure_rate <= 0.01}, {"go", s.go}}},
            {"no_go_precision_at_least_0_5", {{"met", s.no_go > 0 && s.no_go_precision >= 0.5}, {"no_go", s.no_go}}}}},
          {"by_views", by_views},
          {"covariance_check", covariance_check},
          {"outcomes", reasons},
          {"settings",
           {{"seed", a.seed},
            {"noise_px", a.noise_px},
            {"arm_error_mm", a.arm_error_mm},
            {"arm_sigma_mm", a.arm_sigma_mm},
            {"arm_error_max_mm", a.arm_error_max_mm},
            {"encoder_sigma_rad", a.encoder_sigma_rad},
            {"min_p_success", a.min_p_success},
            {"depth_m", a.depth_m},
            {"standoff_m", a.standoff_m},
            {"hole_tag", a.hole_tag},
            {"capture",
             {{"lateral_m", s.capture.lateral_m},
              {"tilt_deg", s.capture.tilt_rad * 180.0 / M_PI},
              {"axial_min_m", s.capture.axial_min_m},
              {"axial_max_m", s.capture.axial_max_m},
              {"axial_max_in_hole_m", s.capture.axial_max_in_hole_m},
              {"clearance_m", s.capture.clearance_m}}}}},
          {"redrawn", s.redrawn},
          {"elapsed_s", {{"ground", s.ground_s}, {"plant", s.plant_s}, {"plant_compute", s.plant_compute_s}}},
          {"trial_records", records}};
}

}  // namespace foresight::session
