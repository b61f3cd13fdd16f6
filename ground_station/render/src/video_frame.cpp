#include "foresight/render/video_frame.hpp"

#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>

#include "foresight/common/error.hpp"

namespace foresight::render {

namespace {
std::string size_text(int w, int h) { return std::to_string(w) + "x" + std::to_string(h); }
}  // namespace

cv::Mat read_video_frame(const std::string& path, int frame_index) {
  if (frame_index < 0) throw InputError(path, "frame index " + std::to_string(frame_index) + " is negative");
  if (!std::ifstream(path).good()) throw InputError(path, "cannot read image or video");
  cv::Mat img;
  if (frame_index == 0 && cv::haveImageReader(path)) img = cv::imread(path, cv::IMREAD_COLOR);
  if (!img.empty()) return img;
  cv::VideoCapture cap;
  try {
    cap.open(path, cv::CAP_FFMPEG);
  } catch (const cv::Exception&) {
  }
  if (!cap.isOpened()) throw InputError(path, "cannot read image or video");
  cv::Mat frame;
  int k = 0;
  for (; k <= frame_index; ++k)
    if (!cap.read(frame) || frame.empty()) break;
  if (k <= frame_index) {
    if (k == 0) throw InputError(path, "cannot read image or video");
    throw InputError(path, "video has only " + std::to_string(k) + " frames; frame " + std::to_string(frame_index) +
                               " requested");
  }
  if (frame.channels() == 1) cv::cvtColor(frame, frame, cv::COLOR_GRAY2BGR);
  if (frame.channels() == 4) cv::cvtColor(frame, frame, cv::COLOR_BGRA2BGR);
  return frame;
}

cv::Mat fit_to_viewport(const cv::Mat& frame, const std::string& path, const camera::Camera& camera, bool scale) {
  const int w = camera.viewport.width_px, h = camera.viewport.height_px;
  if (frame.cols == w && frame.rows == h) return frame;
  if (!scale)
    throw InputError(path, "image is " + size_text(frame.cols, frame.rows) + " but camera '" + camera.name + "' has a " +
                               size_text(w, h) + " viewport (pass --scale-image to resize it)");
  cv::Mat out;
  cv::resize(frame, out, cv::Size(w, h), 0, 0, cv::INTER_AREA);
  return out;
}

void write_image(const std::string& path, const cv::Mat& image, const std::string& cannot_write) {
  bool written = false;
  try {
    written = cv::imwrite(path, image);
  } catch (const cv::Exception&) {
  }
  if (!written) throw InputError(path, cannot_write);
}

}  // namespace foresight::render
