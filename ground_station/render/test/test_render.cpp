// Renderer tests on both GL back ends: projection consistency with
// Camera::project, render modes, compositing, bad input.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cstdio>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>

#include "foresight/common/error.hpp"
#include "foresight/common/object_model.hpp"
#include "foresight/common/scene.hpp"
#include "foresight/render/gl_context.hpp"
#include "foresight/render/renderer.hpp"
#include "foresight/render/scene_geometry.hpp"
#include "foresight/render/video_frame.hpp"

using namespace foresight;
using namespace foresight::render;

namespace {

const std::string kConfig = FORESIGHT_CONFIG_DIR;

class BackendTest : public ::testing::TestWithParam<GlBackend> {};

// A flat square of side s_m centred on p_base, parallel to the camera's image
// plane and turned 0.5 rad about the optical axis, so the pixel quantization
// of its edges averages out over the rows (an axis-aligned square's centroid
// is quantized to whole pixels).
Mesh facing_square(const camera::Camera& cam, const Eigen::Vector3d& p_base, double s_m) {
  Mesh m;
  const Eigen::Matrix3d R = cam.base_T_camera.linear() * Eigen::AngleAxisd(0.5, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  const double h = s_m / 2.0;
  const Eigen::Vector3d offsets[4] = {{-h, -h, 0}, {h, -h, 0}, {h, h, 0}, {-h, h, 0}};
  for (const auto& o : offsets) {
    Vertex v{};
    const Eigen::Vector3d p = p_base + R * o;
    for (int i = 0; i < 3; ++i) v.position[i] = static_cast<float>(p[i]);
    v.normal[2] = 1.0f;
    for (float& c : v.rgba) c = 1.0f;
    m.vertices.push_back(v);
  }
  m.triangles = {0, 1, 2, 0, 2, 3};
  return m;
}

// Centroid of the drawn pixels (alpha > 0), pixel (i, j) centred at (i + 0.5, j + 0.5).
Eigen::Vector2d drawn_centroid(const cv::Mat& layer, int& count) {
  double sx = 0.0, sy = 0.0;
  count = 0;
  for (int r = 0; r < layer.rows; ++r)
    for (int c = 0; c < layer.cols; ++c)
      if (layer.at<cv::Vec4b>(r, c)[3] > 0) {
        sx += c + 0.5;
        sy += r + 0.5;
        ++count;
      }
  return count ? Eigen::Vector2d(sx / count, sy / count) : Eigen::Vector2d(-1, -1);
}

int drawn_pixels(const cv::Mat& layer) {
  std::vector<cv::Mat> ch;
  cv::split(layer, ch);
  return cv::countNonZero(ch[3]);
}

}  // namespace

TEST_P(BackendTest, CreatesCoreContext) {
  auto ctx = GlContext::create(GetParam());
  EXPECT_EQ(ctx->backend(), GetParam());
  Renderer r(*ctx, {646, 486});
  const std::string d = r.gl_description();
  EXPECT_NE(d.find("Core Profile"), std::string::npos) << d;
}

// A marker's rendered pixels are centred where Camera::project puts its centre:
// the GL projection and the calibration math agree (one source of truth).
TEST_P(BackendTest, ProjectionMatchesCameraWithinHalfPixel) {
  auto ctx = GlContext::create(GetParam());
  const Scene scene = Scene::from_file(kConfig + "/scene.yaml");
  double worst_px = 0.0;
  for (const std::string name : {"side", "oblique", "overhead_wide", "overhead_zoom"}) {
    const camera::Camera cam = scene_camera(scene, name);
    Renderer r(*ctx, cam.viewport);
    // Markers spread over the image: back-project grid pixels to 1.2-2.5 m depth.
    const std::vector<Eigen::Vector2d> targets = {{40.3, 35.7}, {323.0, 243.0}, {600.2, 450.9}, {100.6, 420.1}, {580.4, 60.2}};
    int k = 0;
    for (const auto& uv : targets) {
      const double depth = 1.2 + 0.3 * (k++);
      const Eigen::Vector3d p_cam((uv.x() - cam.viewport.width_px / 2.0) * depth / cam.f_px,
                                  (uv.y() - cam.viewport.height_px / 2.0) * depth / cam.f_px, depth);
      const Eigen::Vector3d p_base = cam.base_T_camera * p_cam;
      const double side_m = 20.0 * depth / cam.f_px;  // ~20 px
      const int body = r.add_body(facing_square(cam, p_base, side_m));
      DrawList list;
      list.bodies.push_back({body, Pose::Identity(), kArmWireRgba, std::nullopt});
      cv::Mat layer;
      r.render(cam, list, {}, layer);
      int n = 0;
      const Eigen::Vector2d c = drawn_centroid(layer, n);
      const Eigen::Vector2d expected = cam.project(p_base);
      EXPECT_NEAR(n, 400, 40) << name;
      const double err = (c - expected).norm();
      worst_px = std::max(worst_px, err);
      EXPECT_LT(err, 0.5) << name << " marker at " << expected.transpose() << " drawn at " << c.transpose();
    }
  }
  // A half-pixel convention slip would show as ~0.5-0.7 px; the exact match is far below.
  EXPECT_LT(worst_px, 0.15);
  RecordProperty("worst_marker_error_px", std::to_string(worst_px));
  std::printf("worst marker error %s: %.3f px\n", to_string(GetParam()), worst_px);
}

// Hidden-line removal draws fewer edge pixels than the plain wire-frame, and
// only pixels the wire-frame also draws.
TEST_P(BackendTest, HiddenLinesDrawFewerEdgePixelsThanWire) {
  auto ctx = GlContext::create(GetParam());
  const Scene scene = Scene::from_file(kConfig + "/scene.yaml");
  const ObjectModel oru = ObjectModel::from_file(kConfig + "/oru.yaml");
  const camera::Camera cam = scene_camera(scene, "oblique");
  Renderer r(*ctx, cam.viewport);
  const int body = add_object_body(r, oru);
  DrawList list;
  list.bodies.push_back({body, scene.base_T_object, kObjectWireRgba, std::nullopt});
  cv::Mat wire, hidden;
  RenderSettings st;
  st.mode = RenderMode::Wire;
  r.render(cam, list, st, wire);
  st.mode = RenderMode::Hidden;
  r.render(cam, list, st, hidden);
  const int n_wire = drawn_pixels(wire), n_hidden = drawn_pixels(hidden);
  EXPECT_GT(n_hidden, 300);
  EXPECT_LT(n_hidden, 0.85 * n_wire) << "wire " << n_wire << " hidden " << n_hidden;
  std::vector<cv::Mat> wc, hc;
  cv::split(wire, wc);
  cv::split(hidden, hc);
  cv::Mat both;
  cv::bitwise_and(wc[3], hc[3], both);
  EXPECT_GT(cv::countNonZero(both), 0.97 * n_hidden);
}

// Ghost mode: out = alpha * model + (1 - alpha) * video where the model is,
// the video untouched elsewhere.
TEST_P(BackendTest, GhostBlendsAsConfigured) {
  auto ctx = GlContext::create(GetParam());
  const Scene scene = Scene::from_file(kConfig + "/scene.yaml");
  const ObjectModel oru = ObjectModel::from_file(kConfig + "/oru.yaml");
  const camera::Camera cam = scene_camera(scene, "side");
  Renderer r(*ctx, cam.viewport);
  const int body = add_object_body(r, oru);
  DrawList list;
  const Eigen::Vector4d model_rgba(0.8, 0.4, 0.2, 1.0);  // unlit: exactly these values
  list.bodies.push_back({body, scene.base_T_object, kObjectWireRgba, model_rgba});
  RenderSettings st;
  st.mode = RenderMode::Ghost;
  st.lighting = false;
  cv::Mat layer;
  r.render(cam, list, st, layer);
  cv::Mat video(cam.viewport.height_px, cam.viewport.width_px, CV_8UC3);
  cv::randu(video, 0, 256);
  const cv::Mat original = video.clone();
  const double alpha = 0.35;
  composite(layer, mode_opacity(st.mode, alpha), video);
  const Eigen::Vector2d centre = cam.project(scene.base_T_object * oru.oru_T_box.translation());
  int checked_model = 0, checked_video = 0;
  for (int row = 0; row < video.rows; row += 7)
    for (int col = 0; col < video.cols; col += 7) {
      const bool model = layer.at<cv::Vec4b>(row, col)[3] > 0;
      const cv::Vec3b v0 = original.at<cv::Vec3b>(row, col), v1 = video.at<cv::Vec3b>(row, col);
      for (int k = 0; k < 3; ++k) {
        const double m = 255.0 * model_rgba[2 - k];  // BGR
        const double expected = model ? alpha * m + (1.0 - alpha) * v0[k] : v0[k];
        ASSERT_NEAR(v1[k], expected, 1.0) << "pixel " << col << "," << row;
      }
      (model ? checked_model : checked_video)++;
    }
  EXPECT_GT(checked_model, 100);
  EXPECT_GT(checked_video, 1000);
  EXPECT_GT(layer.at<cv::Vec4b>(static_cast<int>(centre.y()), static_cast<int>(centre.x()))[3], 0);
}

TEST(Render, BackendsAgree) {
  const Scene scene = Scene::from_file(kConfig + "/scene.yaml");
  const ObjectModel oru = ObjectModel::from_file(kConfig + "/oru.yaml");
  const camera::Camera cam = scene_camera(scene, "oblique");
  cv::Mat layers[2];
  int i = 0;
  for (GlBackend b : {GlBackend::OSMesa, GlBackend::Egl}) {
    auto ctx = GlContext::create(b);
    Renderer r(*ctx, cam.viewport);
    const int body = add_object_body(r, oru);
    DrawList list;
    list.bodies.push_back({body, scene.base_T_object, kObjectWireRgba, std::nullopt});
    r.render(cam, list, {}, layers[i++]);
  }
  cv::Mat diff;
  cv::absdiff(layers[0], layers[1], diff);
  cv::Mat diff1 = diff.reshape(1);
  EXPECT_LT(cv::countNonZero(diff1 > 2), 0.001 * diff1.total());
  EXPECT_GT(drawn_pixels(layers[0]), 5000);
}

TEST(Render, TriadAndPathLines) {
  auto ctx = GlContext::create(GlBackend::OSMesa);
  const Scene scene = Scene::from_file(kConfig + "/scene.yaml");
  const camera::Camera cam = scene_camera(scene, "side");
  Renderer r(*ctx, cam.viewport);
  DrawList list;
  append_triad(list, scene.base_T_object, 0.1);
  ASSERT_EQ(list.lines.size(), 3u);
  cv::Mat layer;
  r.render(cam, list, {}, layer);
  // The x axis end is drawn red.
  const Eigen::Vector2d uv = cam.project(scene.base_T_object * Eigen::Vector3d(0.09, 0, 0));
  bool red_near = false;
  for (int dr = -1; dr <= 1; ++dr)
    for (int dc = -1; dc <= 1; ++dc) {
      const cv::Vec4b p = layer.at<cv::Vec4b>(static_cast<int>(uv.y()) + dr, static_cast<int>(uv.x()) + dc);
      red_near |= (p[3] > 0 && p[2] > 200 && p[1] < 50);
    }
  EXPECT_TRUE(red_near);
}

TEST(RenderBadInput, UnsupportedGlVersion) {
  try {
    GlContext::create(GlBackend::OSMesa, {9, 9});
    FAIL() << "no error";
  } catch (const std::runtime_error& e) {
    EXPECT_STREQ(e.what(), "cannot create an OSMesa context for OpenGL 9.9 core profile");
  }
  try {
    GlContext::create(GlBackend::Egl, {9, 9});
    FAIL() << "no error";
  } catch (const std::runtime_error& e) {
    EXPECT_EQ(std::string(e.what()).rfind("cannot create an EGL context for OpenGL 9.9 core profile: ", 0), 0u) << e.what();
  }
}

TEST(RenderBadInput, ViewportBeyondGlLimit) {
  auto ctx = GlContext::create(GlBackend::OSMesa);
  try {
    Renderer r(*ctx, {100000, 486});
    FAIL() << "no error";
  } catch (const std::runtime_error& e) {
    EXPECT_EQ(std::string(e.what()).rfind("viewport 100000x486 cannot be rendered: the osmesa GL limit is ", 0), 0u)
        << e.what();
  }
}

TEST(RenderBadInput, CameraViewportDiffersFromRenderer) {
  auto ctx = GlContext::create(GlBackend::OSMesa);
  Renderer r(*ctx, {646, 486});
  camera::Camera cam;
  cam.name = "small";
  cam.viewport = {320, 240};
  cv::Mat layer;
  try {
    r.render(cam, {}, {}, layer);
    FAIL() << "no error";
  } catch (const std::invalid_argument& e) {
    EXPECT_STREQ(e.what(), "camera 'small' viewport 320x240 differs from the renderer's 646x486");
  }
}

TEST(RenderBadInput, NamesAndModes) {
  EXPECT_EQ(parse_render_mode("hidden"), RenderMode::Hidden);
  EXPECT_EQ(parse_gl_backend("egl"), GlBackend::Egl);
  try {
    parse_render_mode("xray");
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_STREQ(e.what(), "render mode 'xray' is not one of: wire, solid, hidden, ghost");
  }
  try {
    parse_gl_backend("vulkan");
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_STREQ(e.what(), "GL back end 'vulkan' is not one of: osmesa, egl");
  }
  const Scene scene = Scene::from_file(kConfig + "/scene.yaml");
  try {
    scene_camera(scene, "front", "scene.yaml");
    FAIL();
  } catch (const InputError& e) {
    EXPECT_STREQ(e.what(), "scene.yaml: no camera 'front' (known: oblique, overhead_wide, overhead_zoom, side)");
  }
}

INSTANTIATE_TEST_SUITE_P(Backends, BackendTest, ::testing::Values(GlBackend::OSMesa, GlBackend::Egl),
                         [](const auto& info) { return std::string(to_string(info.param)); });

// The video frame: a still image, or frame K of a video file.
TEST(VideoFrame, ReadsTheRequestedFrameOfAVideo) {
  char tmpl[] = "/tmp/foresight_video_XXXXXX";
  const int fd = mkstemp(tmpl);
  close(fd);
  std::remove(tmpl);
  const std::string path = std::string(tmpl) + ".avi";
  {
    cv::VideoWriter w(path, cv::VideoWriter::fourcc('M', 'J', 'P', 'G'), 10.0, cv::Size(64, 48));
    ASSERT_TRUE(w.isOpened());
    for (int k = 0; k < 5; ++k) w.write(cv::Mat(48, 64, CV_8UC3, cv::Scalar(40 * k + 20, 40 * k + 20, 40 * k + 20)));
  }
  for (int k : {0, 3, 4}) {
    const cv::Mat f = read_video_frame(path, k);
    ASSERT_EQ(f.type(), CV_8UC3);
    EXPECT_NEAR(cv::mean(f)[1], 40 * k + 20, 3.0) << "frame " << k;
  }
  try {
    read_video_frame(path, 7);
    FAIL();
  } catch (const InputError& e) {
    EXPECT_EQ(std::string(e.what()), path + ": video has only 5 frames; frame 7 requested");
  }
  camera::Camera cam;
  cam.name = "side";
  cam.viewport = {64, 48};
  EXPECT_EQ(fit_to_viewport(read_video_frame(path, 1), path, cam, false).cols, 64);
  cam.viewport = {128, 96};
  try {
    fit_to_viewport(read_video_frame(path, 1), path, cam, false);
    FAIL();
  } catch (const InputError& e) {
    EXPECT_EQ(std::string(e.what()),
              path + ": image is 64x48 but camera 'side' has a 128x96 viewport (pass --scale-image to resize it)");
  }
  const cv::Mat scaled = fit_to_viewport(read_video_frame(path, 1), path, cam, true);
  EXPECT_EQ(scaled.cols, 128);
  EXPECT_EQ(scaled.rows, 96);
  std::remove(path.c_str());
  try {
    read_video_frame(path);
    FAIL();
  } catch (const InputError& e) {
    EXPECT_EQ(std::string(e.what()), path + ": cannot read image or video");
  }
}
