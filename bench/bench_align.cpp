// BM_AlignCamera (in bench_estimation, issue 16): model-to-image alignment of
// one camera on one 646 x 486 synthetic frame (target < 100 ms), the camera
// 5 px off its truth. Counters: the reprojection error after alignment (px,
// link origins), the visible and matched model edge samples. A file of its
// own linked into bench_estimation (bench/CMakeLists.txt), because it needs a
// GL context and the renderer; BENCHMARK_MAIN is bench_estimation.cpp's.
#include <benchmark/benchmark.h>

#include <cmath>

#include "foresight/align/health.hpp"

#include "foresight/align/model_aligner.hpp"
#include "foresight/camera/projection.hpp"
#include "foresight/common/kinematics.hpp"
#include "foresight/render/scene_geometry.hpp"
#include "foresight/render/synthetic_camera.hpp"

using namespace foresight;

namespace {

void BM_AlignCamera(benchmark::State& state) {
  const std::string cfg = FORESIGHT_CONFIG_DIR;
  const RobotModel model = RobotModel::from_file(cfg + "/robot.urdf");
  const ObjectModel oru = ObjectModel::from_file(cfg + "/oru.yaml");
  const Scene scene = Scene::from_file(cfg + "/scene.yaml");
  KinematicsWorkspace ws(model);
  const auto ik = inverse_kinematics(model, ws, scene.base_T_object * oru.tags.at("approach_20cm"),
                                     model.mid_configuration());
  const camera::Camera truth = render::scene_camera(scene, "oblique");
  auto ctx = render::GlContext::create(render::GlBackend::OSMesa);
  render::SyntheticCamera synth(*ctx, model, oru, scene, truth.viewport);
  align::ModelAligner aligner(*ctx, model, &oru, truth.viewport);
  camera::Camera start = truth;
  start.base_T_camera.linear() =
      truth.base_T_camera.linear() * camera::exp_so3(Eigen::Vector3d(-3.0 / truth.f_px, 4.0 / truth.f_px, 0.0));
  const align::AlignView view{start, {{synth.render(truth, ik.q).image_bgr, ik.q}}};
  std::vector<Eigen::Vector3d> pts;
  for (int link = 0; link < static_cast<int>(model.links().size()); ++link)
    pts.push_back(forward_kinematics(model, ws, ik.q, link).translation());
  // Arg 1: the default (the edge bias predicted from the shaded model at the
  // fine levels); arg 0: without it, the peer that shows its cost.
  align::AlignOptions o;
  o.predict_edge_bias = state.range(0) != 0;
  align::AlignResult r;
  for (auto _ : state) {
    r = aligner.align({view}, scene.base_T_object, o);
    benchmark::DoNotOptimize(r.cameras.data());
  }
  state.counters["aligned"] = r.status == align::AlignStatus::Aligned;
  state.counters["reprojection_px"] = align::reprojection_rms_px(r.cameras[0], truth, pts);
  state.counters["start_px"] = align::reprojection_rms_px(start, truth, pts);
  state.counters["visible"] = r.visible_samples;
  state.counters["matched"] = r.matched_samples;
  state.counters["iterations"] = r.iterations;
}

// Calibration health over 1,000 frames of normal motion with sensor noise
// (issue 16: no false alarm): the arm swinging about the approach pose,
// rendered through the true camera, scored through the same (calibrated)
// camera. One iteration; counters: false alarms, the worst matched fraction
// and IoU, ms per frame (render + score).
void BM_HealthNormalMotion1000(benchmark::State& state) {
  const std::string cfg = FORESIGHT_CONFIG_DIR;
  const RobotModel model = RobotModel::from_file(cfg + "/robot.urdf");
  const ObjectModel oru = ObjectModel::from_file(cfg + "/oru.yaml");
  const Scene scene = Scene::from_file(cfg + "/scene.yaml");
  KinematicsWorkspace ws(model);
  const auto ik = inverse_kinematics(model, ws, scene.base_T_object * oru.tags.at("approach_20cm"),
                                     model.mid_configuration());
  const camera::Camera camera = render::scene_camera(scene, "oblique");
  auto ctx = render::GlContext::create(render::GlBackend::OSMesa);
  render::SyntheticOptions so;
  so.noise_sigma_dn = 2.0;
  render::SyntheticCamera synth(*ctx, model, oru, scene, camera.viewport, so);
  align::ModelAligner aligner(*ctx, model, &oru, camera.viewport);
  constexpr int kFrames = 1000;
  int false_alarms = 0, bad = 0;
  double min_fraction = 1.0, min_iou = 1.0;
  for (auto _ : state) {
    align::HealthMonitor monitor;
    for (int k = 0; k < kFrames; ++k) {
      Eigen::VectorXd q = ik.q;
      q[0] += 0.10 * std::sin(0.031 * k);
      q[1] += 0.06 * std::sin(0.023 * k + 1.0);
      q[3] += 0.08 * std::cos(0.017 * k);
      q[5] += 0.10 * std::sin(0.041 * k);
      const render::SyntheticFrame f = synth.render(camera, q);
      const auto s = aligner.score(camera, {f.image_bgr, q}, scene.base_T_object);
      const align::HealthVerdict v = monitor.update(s);
      false_alarms += v.warning ? 1 : 0;
      bad += v.bad ? 1 : 0;
      min_fraction = std::min(min_fraction, s.matched_fraction);
      min_iou = std::min(min_iou, s.iou);
    }
  }
  state.counters["frames"] = kFrames;
  state.counters["false_alarms"] = false_alarms;
  state.counters["bad_frames"] = bad;
  state.counters["min_matched_fraction"] = min_fraction;
  state.counters["min_iou"] = min_iou;
  state.counters["ms_per_frame"] = benchmark::Counter(kFrames * 1e-3, benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
}

}  // namespace

BENCHMARK(BM_AlignCamera)->Arg(1)->Arg(0)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_HealthNormalMotion1000)->Unit(benchmark::kSecond)->UseRealTime()->Iterations(1);
