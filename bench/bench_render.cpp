// bench_render: overlay frames per second at 646 x 486 for the arm and the
// ORU in each render mode (render + read-back + composite over a video
// frame), on both GL back ends. Counters: fps, triangles of the arm + ORU
// meshes (the hidden-line mode draws them into depth only, wire-frame not at all).
// Target (issue 4): >= 60 fps in every mode on the 2-core machines.
#include <benchmark/benchmark.h>

#include <opencv2/core.hpp>

#include "foresight/common/object_model.hpp"
#include "foresight/common/scene.hpp"
#include "foresight/render/renderer.hpp"
#include "foresight/render/scene_geometry.hpp"

using namespace foresight;
using namespace foresight::render;

namespace {

void BM_Overlay(benchmark::State& state, GlBackend backend, RenderMode mode) {
  const std::string cfg = FORESIGHT_CONFIG_DIR;
  const RobotModel model = RobotModel::from_file(cfg + "/robot.urdf");
  const ObjectModel oru = ObjectModel::from_file(cfg + "/oru.yaml");
  const Scene scene = Scene::from_file(cfg + "/scene.yaml");
  const camera::Camera camera = scene_camera(scene, "oblique");
  auto ctx = GlContext::create(backend);
  Renderer renderer(*ctx, camera.viewport);
  ArmGeometry arm(renderer, model);
  const int oru_body = add_object_body(renderer, oru);
  cv::Mat video(camera.viewport.height_px, camera.viewport.width_px, CV_8UC3);
  cv::randu(video, 0, 256);
  cv::Mat frame, layer;
  RenderSettings st;
  st.mode = mode;
  DrawList list;
  Eigen::VectorXd q = model.mid_configuration();
  const int triangles = arm.triangles() + renderer.body_triangles(oru_body);  // of the scene, whatever the mode draws
  long frames = 0;
  for (auto _ : state) {
    q[0] = 0.3 * std::sin(0.01 * static_cast<double>(frames++));  // the arm moves: FK every frame
    list.clear();
    arm.append(q, list);
    list.bodies.push_back({oru_body, scene.base_T_object, kObjectWireRgba, std::nullopt});
    renderer.render(camera, list, st, layer);
    video.copyTo(frame);
    composite(layer, mode_opacity(mode, 0.5), frame);
    benchmark::DoNotOptimize(frame.data);
  }
  state.counters["fps"] = benchmark::Counter(static_cast<double>(state.iterations()), benchmark::Counter::kIsRate);
  state.counters["triangles"] = triangles;
  state.SetLabel(renderer.gl_description());
}

}  // namespace

BENCHMARK_CAPTURE(BM_Overlay, osmesa_wire, GlBackend::OSMesa, RenderMode::Wire)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK_CAPTURE(BM_Overlay, osmesa_solid, GlBackend::OSMesa, RenderMode::Solid)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK_CAPTURE(BM_Overlay, osmesa_hidden, GlBackend::OSMesa, RenderMode::Hidden)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK_CAPTURE(BM_Overlay, osmesa_ghost, GlBackend::OSMesa, RenderMode::Ghost)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK_CAPTURE(BM_Overlay, egl_wire, GlBackend::Egl, RenderMode::Wire)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK_CAPTURE(BM_Overlay, egl_solid, GlBackend::Egl, RenderMode::Solid)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK_CAPTURE(BM_Overlay, egl_hidden, GlBackend::Egl, RenderMode::Hidden)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK_CAPTURE(BM_Overlay, egl_ghost, GlBackend::Egl, RenderMode::Ghost)->Unit(benchmark::kMillisecond)->UseRealTime();

BENCHMARK_MAIN();
