// bench_align: model-to-image alignment of one camera on one 646 x 486
// synthetic frame (issue 16; target < 100 ms), the camera 4 px off its truth.
// Counters: the reprojection error after alignment (px, link origins), the
// visible and matched model edge samples. It lives in its own executable
// (not bench_estimation) because it needs a GL context and the renderer,
// which the estimation libraries do not link.
#include <benchmark/benchmark.h>

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
  const Camera truth = render::scene_camera(scene, "oblique");
  auto ctx = render::GlContext::create(render::GlBackend::OSMesa);
  render::SyntheticCamera synth(*ctx, model, oru, scene, truth.viewport);
  align::ModelAligner aligner(*ctx, model, &oru, truth.viewport);
  Camera start = truth;
  start.base_T_camera.linear() =
      truth.base_T_camera.linear() * exp_so3(Eigen::Vector3d(-3.0 / truth.f_px, 4.0 / truth.f_px, 0.0));
  const align::AlignView view{start, {{synth.render(truth, ik.q).image_bgr, ik.q}}};
  std::vector<Eigen::Vector3d> pts;
  for (int link = 0; link < static_cast<int>(model.links().size()); ++link)
    pts.push_back(forward_kinematics(model, ws, ik.q, link).translation());
  align::AlignResult r;
  for (auto _ : state) {
    r = aligner.align({view}, scene.base_T_object);
    benchmark::DoNotOptimize(r.cameras.data());
  }
  state.counters["aligned"] = r.status == align::AlignStatus::Aligned;
  state.counters["reprojection_px"] = align::reprojection_rms_px(r.cameras[0], truth, pts);
  state.counters["start_px"] = align::reprojection_rms_px(start, truth, pts);
  state.counters["visible"] = r.visible_samples;
  state.counters["matched"] = r.matched_samples;
  state.counters["iterations"] = r.iterations;
}

}  // namespace

BENCHMARK(BM_AlignCamera)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK_MAIN();
