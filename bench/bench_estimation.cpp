// Estimation benchmarks: camera calibration (30 clicks), multi-view object
// localization (4 views x 8 clicks), and OpenCV solvePnP on the same single
// view's clicks, all on synthetic data from config/scene.yaml with 1 px noise.
// Targets (issue 3): calibration < 200 us, localization < 300 us.

#include <benchmark/benchmark.h>

#include <random>

#include "foresight/calibration/calibrate.hpp"
#include "foresight/common/scene.hpp"
#include "foresight/localization/localize.hpp"
#include "foresight/localization/peers.hpp"

using namespace foresight;

namespace {

struct Data {
  std::vector<camera::Camera> cameras;
  std::map<std::string, camera::Camera> camera_map;
  std::vector<calibration::Correspondence> calibration;  // 30 clicks of the first (side) camera
  std::vector<calibration::Correspondence> object;       // 8 clicks in each view
  std::vector<calibration::Correspondence> object_view1; // the first view's 8
};

const Data& data() {
  static const Data d = [] {
    Data d;
    const Scene scene = Scene::from_file(FORESIGHT_CONFIG_DIR "/scene.yaml");
    for (const auto& name : scene.camera_order) {
      const SceneCamera& c = scene.cameras.at(name);
      d.cameras.push_back(camera::Camera::look_at(name, {c.width_px, c.height_px}, c.f_px, c.position_m, c.look_at_m, c.up));
      d.camera_map[name] = d.cameras.back();
    }
    std::mt19937 rng(1);
    std::normal_distribution<double> noise(0.0, 1.0);
    std::uniform_real_distribution<double> x(0.35, 0.95), y(-0.35, 0.55), z(0.2, 1.0), o(-0.25, 0.25);
    const camera::Camera& side = d.cameras[0];
    while (d.calibration.size() < 30) {
      const Eigen::Vector3d p(x(rng), y(rng), z(rng));
      if (!side.in_front(p) || !side.in_view(side.project(p))) continue;
      calibration::Correspondence c;
      c.n = static_cast<int>(d.calibration.size()) + 1;
      c.cam = side.name;
      c.p_m = p;
      c.uv_px = side.project(p) + Eigen::Vector2d(noise(rng), noise(rng));
      d.calibration.push_back(c);
    }
    // 8 model points seen by every view (so triangulation has them all).
    std::vector<Eigen::Vector3d> model;
    while (model.size() < 8) {
      const Eigen::Vector3d p(o(rng), o(rng), o(rng));
      const Eigen::Vector3d pb = scene.base_T_object * p;
      bool seen = true;
      for (const camera::Camera& cam : d.cameras) seen = seen && cam.in_front(pb) && cam.in_view(cam.project(pb));
      if (seen) model.push_back(p);
    }
    for (const camera::Camera& cam : d.cameras)
      for (std::size_t i = 0; i < model.size(); ++i) {
        calibration::Correspondence c;
        c.n = static_cast<int>(i) + 1;
        c.cam = cam.name;
        c.p_m = model[i];
        c.uv_px = cam.project(scene.base_T_object * model[i]) + Eigen::Vector2d(noise(rng), noise(rng));
        d.object.push_back(c);
        if (&cam == &d.cameras[0]) d.object_view1.push_back(c);
      }
    return d;
  }();
  return d;
}

void BM_Calibrate30(benchmark::State& state) {
  const Data& d = data();
  for (auto _ : state) {
    calibration::CalibrationResult r = calibration::calibrate_camera(d.calibration, d.cameras[0].viewport, d.cameras[0].name);
    benchmark::DoNotOptimize(r.camera.f_px);
  }
}
BENCHMARK(BM_Calibrate30)->Unit(benchmark::kMicrosecond);

void BM_CalibrateLinear30(benchmark::State& state) {
  const Data& d = data();
  for (auto _ : state) {
    camera::Camera c = calibration::calibrate_camera_linear(d.calibration, d.cameras[0].viewport, d.cameras[0].name);
    benchmark::DoNotOptimize(c.f_px);
  }
}
BENCHMARK(BM_CalibrateLinear30)->Unit(benchmark::kMicrosecond);

void BM_Localize4x8(benchmark::State& state) {
  const Data& d = data();
  for (auto _ : state) {
    localization::LocalizationResult r = localization::localize_object(d.object, d.camera_map);
    benchmark::DoNotOptimize(r.rms_px);
  }
}
BENCHMARK(BM_Localize4x8)->Unit(benchmark::kMicrosecond);

void BM_Localize1x8(benchmark::State& state) {
  const Data& d = data();
  for (auto _ : state) {
    localization::LocalizationResult r = localization::localize_object(d.object_view1, d.camera_map);
    benchmark::DoNotOptimize(r.rms_px);
  }
}
BENCHMARK(BM_Localize1x8)->Unit(benchmark::kMicrosecond);

void BM_OpenCvSolvePnP(benchmark::State& state, localization::PnpMethod m) {
  const Data& d = data();
  for (auto _ : state) {
    auto T = localization::solve_pnp_opencv(d.object_view1, d.cameras[0], m);
    benchmark::DoNotOptimize(T);
  }
}
BENCHMARK_CAPTURE(BM_OpenCvSolvePnP, SQPNP, localization::PnpMethod::Sqpnp)->Unit(benchmark::kMicrosecond);
BENCHMARK_CAPTURE(BM_OpenCvSolvePnP, ITERATIVE, localization::PnpMethod::Iterative)->Unit(benchmark::kMicrosecond);

void BM_TriangulateAlign4x8(benchmark::State& state) {
  const Data& d = data();
  for (auto _ : state) {
    auto T = localization::triangulate_and_align(d.object, d.camera_map);
    benchmark::DoNotOptimize(T);
  }
}
BENCHMARK(BM_TriangulateAlign4x8)->Unit(benchmark::kMicrosecond);

}  // namespace

BENCHMARK_MAIN();
