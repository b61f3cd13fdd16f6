#pragma once
// The video frame an overlay is composited on: a still image or one frame of
// a video file (OpenCV), checked against the camera's viewport. Set-up code;
// throws InputError naming the file.

#include <opencv2/core.hpp>
#include <string>

#include "foresight/camera/camera.hpp"

namespace foresight::render {

/// A still image (PNG, JPEG, ...) or, when the file is not an image, frame
/// `frame_index` (0-based) of a video file, as 8-bit BGR. Throws InputError:
/// "cannot read image or video" (missing, unreadable, not an image or
/// video), "video has only N frames; frame K requested".
cv::Mat read_video_frame(const std::string& path, int frame_index = 0);

/// Returns `frame` when its size equals the camera's viewport. Otherwise,
/// with `scale` it is resized to the viewport; without, throws InputError
/// "image is WxH but camera 'NAME' has a WxH viewport (pass --scale-image to
/// resize it)".
cv::Mat fit_to_viewport(const cv::Mat& frame, const std::string& path, const camera::Camera& camera, bool scale);

/// Writes `image` to `path` (format from the extension). Throws InputError
/// "<path>: <cannot_write>" when OpenCV cannot write it.
void write_image(const std::string& path, const cv::Mat& image, const std::string& cannot_write = "cannot write image");

}  // namespace foresight::render
