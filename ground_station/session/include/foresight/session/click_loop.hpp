#pragma once
// `foresight click`'s loop: the paper's operator-interactive data entry. Two
// windows: the model (the arm at the given joints, or the ORU) with its
// selectable model points numbered, and the video frame. Click a model
// point, then where it appears in the image; each pair is a row of the
// points CSV that `calibrate` (robot: base-frame points) and `localize`
// (oru: object-frame points) read, rewritten after every change. Keys
// (either window): u / Backspace delete last, c clear all, + / - zoom in /
// out at the mouse (or the wheel), 0 reset the zoom, n / p next / previous
// model point, f fit (calibrate, or localize with the cameras) and show the
// residual arrows, q / Esc save and quit. Needs a display (X). Not
// real-time code: the operator's screen.

#include <string>

#include "foresight/session/config_path.hpp"

namespace foresight::session {

struct ClickSettings {
  std::string camera;                 ///< the cam column of the rows
  std::string image;                  ///< the video frame: an image or a video (see frame)
  int frame = 0;
  std::string model;                  ///< "robot" (the arm at the joints) or "oru"
  std::string joints, joints_deg;     ///< the arm's joints in the frame (robot: one of them)
  std::string out;                    ///< the points CSV
  bool append = false;                ///< keep the rows already in `out`
  std::string cameras;                ///< calibrated cameras, for the ORU fit
  std::string snapshot;               ///< at exit, PREFIX_model.png and PREFIX_image.png
  std::string gl = "osmesa";
  std::string robot = default_config("robot.urdf");
  std::string object = default_config("oru.yaml");
};

struct ClickSummary {
  std::size_t points = 0;             ///< clicked in this session
  std::size_t rows_in_file = 0;
  std::string fit;                    ///< the last fit's summary ("" without one)
};

/// Checks the settings (bad input, or no display: InputError /
/// std::invalid_argument before any window), then runs the two windows
/// until q; `out` is saved after every change and at the end.
ClickSummary run_click(const ClickSettings& settings);

}  // namespace foresight::session
