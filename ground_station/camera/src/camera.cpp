#include "foresight/camera/camera.hpp"

#include <yaml-cpp/yaml.h>

#include <chrono>
#include <cmath>
#include <fstream>
#include <stdexcept>

#include "foresight/common/atomic_file.hpp"
#include "foresight/common/error.hpp"
#include "foresight/common/input_limits.hpp"
#include "foresight/common/yaml_util.hpp"

namespace foresight::camera {

namespace {
constexpr int kMaxViewportPx = 1 << 15;  ///< a viewport side (pixels)
}  // namespace

Viewport parse_viewport(const std::string& text) {
  const auto x = text.find('x');
  try {
    if (x == std::string::npos) throw std::invalid_argument("no 'x'");
    std::size_t end_w = 0, end_h = 0;
    const int w = std::stoi(text.substr(0, x), &end_w);
    const int h = std::stoi(text.substr(x + 1), &end_h);
    if (end_w != x || end_h != text.size() - x - 1 || w <= 0 || h <= 0 || w > kMaxViewportPx || h > kMaxViewportPx)
      throw std::invalid_argument("bad");
    return {w, h};
  } catch (const std::exception&) {
    throw std::invalid_argument("viewport '" + text + "' is not WIDTHxHEIGHT in positive pixels (e.g. 646x486)");
  }
}

Eigen::Vector2d Camera::project_camera(const Eigen::Vector3d& p) const {
  return principal_point() + f_px * Eigen::Vector2d(p.x() / p.z(), p.y() / p.z());
}

bool Camera::in_view(const Eigen::Vector2d& uv) const {
  return uv.x() >= 0.0 && uv.y() >= 0.0 && uv.x() < viewport.width_px && uv.y() < viewport.height_px;
}

double Camera::fovy_rad() const { return 2.0 * std::atan(viewport.height_px / (2.0 * f_px)); }

Eigen::Matrix4d Camera::gl_projection(double near_m, double far_m) const {
  Eigen::Matrix4d P = Eigen::Matrix4d::Zero();
  P(0, 0) = 2.0 * f_px / viewport.width_px;
  P(1, 1) = 2.0 * f_px / viewport.height_px;
  P(2, 2) = -(far_m + near_m) / (far_m - near_m);
  P(2, 3) = -2.0 * far_m * near_m / (far_m - near_m);
  P(3, 2) = -1.0;
  return P;
}

Eigen::Matrix4d Camera::gl_view() const {
  Eigen::Matrix4d eye_T_camera = Eigen::Vector4d(1.0, -1.0, -1.0, 1.0).asDiagonal();
  return eye_T_camera * base_T_camera.inverse().matrix();
}

Camera Camera::look_at(const std::string& name, const Viewport& vp, double f_px, const Eigen::Vector3d& position,
                       const Eigen::Vector3d& target, const Eigen::Vector3d& up) {
  const Eigen::Vector3d z = (target - position).normalized();
  Eigen::Vector3d x = z.cross(up);  // image right = forward x up... with y down
  if (x.norm() < 1e-9) throw std::invalid_argument("camera '" + name + "': up is parallel to the viewing direction");
  x.normalize();
  const Eigen::Vector3d y = z.cross(x);  // down in the image
  Camera c;
  c.name = name;
  c.viewport = vp;
  c.f_px = f_px;
  c.base_T_camera.linear().col(0) = x;
  c.base_T_camera.linear().col(1) = y;
  c.base_T_camera.linear().col(2) = z;
  c.base_T_camera.translation() = position;
  return c;
}

namespace {

constexpr int kMaxMatrixColumns = 64;

// R rows of C numbers; C = Eigen::Dynamic: as many as the first row has (1 to 64), every row alike.
template <int R, int C>
Eigen::Matrix<double, R, C> read_matrix(const YAML::Node& n, const std::string& file, const std::string& what) {
  Eigen::Matrix<double, R, C> M;
  if (!n || !n.IsSequence() || static_cast<int>(n.size()) != R)
    throw InputError(file, yaml::line_of(n), what + " must be a list of " + std::to_string(R) + " rows");
  int cols = C;
  if constexpr (C == Eigen::Dynamic) {
    cols = n[0].IsSequence() ? static_cast<int>(n[0].size()) : 0;
    if (cols < 1 || cols > kMaxMatrixColumns)
      throw InputError(file, yaml::line_of(n[0]),
                       what + " row 1 must have 1 to " + std::to_string(kMaxMatrixColumns) + " numbers");
  }
  M.resize(R, cols);
  for (int r = 0; r < R; ++r) {
    if (!n[r].IsSequence() || static_cast<int>(n[r].size()) != cols)
      throw InputError(file, yaml::line_of(n[r]),
                       what + " row " + std::to_string(r + 1) + " must have " + std::to_string(cols) + " numbers");
    for (int c = 0; c < cols; ++c) {
      try {
        M(r, c) = n[r][c].as<double>();
      } catch (const YAML::Exception&) {
        throw InputError(file, yaml::line_of(n[r]),
                         what + " row " + std::to_string(r + 1) + " element " + std::to_string(c + 1) +
                             " is not a number");
      }
      if (!std::isfinite(M(r, c)))
        throw InputError(file, yaml::line_of(n[r]), what + " row " + std::to_string(r + 1) + " has a non-finite number");
    }
  }
  return M;
}

template <int R, int C>
YAML::Node write_matrix(const Eigen::Matrix<double, R, C>& M) {
  YAML::Node n;
  for (int r = 0; r < M.rows(); ++r) {
    YAML::Node row;
    row.SetStyle(YAML::EmitterStyle::Flow);
    for (int c = 0; c < M.cols(); ++c) row.push_back(M(r, c));
    n.push_back(row);
  }
  return n;
}

}  // namespace

std::map<std::string, CameraRecord> load_cameras(const std::string& path) {
  const YAML::Node root = yaml::load_file(path, "cannot open camera file");
  if (!root.IsMap()) throw InputError(path, "expected a map from camera name to camera");
  if (root.size() > static_cast<std::size_t>(limits::kMaxCameras))
    throw InputError(path, std::to_string(root.size()) + " cameras, at most " + std::to_string(limits::kMaxCameras) +
                               " allowed");
  std::map<std::string, CameraRecord> out;
  for (const auto& kv : root) {
    if (!kv.first.IsScalar() || kv.first.Scalar().empty())
      throw InputError(path, yaml::line_of(kv.first), "a camera name must be a non-empty string");
    const std::string name = kv.first.Scalar();
    const YAML::Node& n = kv.second;
    const std::string where = "camera '" + name + "'";
    if (!n.IsMap()) throw InputError(path, yaml::line_of(n), where + ": expected a map (viewport, f_px, base_T_camera)");
    try {
      CameraRecord rec;
      rec.camera.name = name;
      if (!n["viewport"] || n["viewport"].size() != 2) throw InputError(path, where + ": viewport must be [W, H]");
      rec.camera.viewport = {n["viewport"][0].as<int>(), n["viewport"][1].as<int>()};
      if (rec.camera.viewport.width_px <= 0 || rec.camera.viewport.height_px <= 0 ||
          rec.camera.viewport.width_px > kMaxViewportPx || rec.camera.viewport.height_px > kMaxViewportPx)
        throw InputError(path, yaml::line_of(n["viewport"]),
                         where + ": viewport must be positive and at most " + std::to_string(kMaxViewportPx) + " px");
      if (!n["f_px"]) throw InputError(path, where + ": missing f_px");
      rec.camera.f_px = n["f_px"].as<double>();
      if (!(rec.camera.f_px > 0.0) || !std::isfinite(rec.camera.f_px))
        throw InputError(path, where + ": f_px must be a positive number");
      const Eigen::Matrix4d T = read_matrix<4, 4>(n["base_T_camera"], path, where + ": base_T_camera");
      const Eigen::Matrix3d R = T.topLeftCorner<3, 3>();
      const int t_line = yaml::line_of(n["base_T_camera"]);
      if ((R.transpose() * R - Eigen::Matrix3d::Identity()).norm() > 1e-6 || R.determinant() < 0.0)
        throw InputError(path, t_line, where + ": base_T_camera rotation is not orthonormal");
      if (T.row(3) != Eigen::RowVector4d(0.0, 0.0, 0.0, 1.0))
        throw InputError(path, t_line, where + ": base_T_camera last row must be [0, 0, 0, 1]");
      if (T.topRightCorner<3, 1>().cwiseAbs().maxCoeff() > limits::kMaxOffset_m)
        throw InputError(path, t_line, where + ": base_T_camera position is farther than " +
                                           std::to_string(static_cast<int>(limits::kMaxOffset_m)) + " m from the base");
      rec.camera.base_T_camera.matrix() = T;
      if (const YAML::Node c = n["calibration"]) {
        CameraCalibrationInfo info;
        if (c["covariance"]) info.covariance = read_matrix<7, 7>(c["covariance"], path, where + ": covariance");
        // Absent: 0; present: a number (a text used to read as 0 silently), not negative.
        const std::string cal = where + ": calibration.";
        info.rms_px = yaml::number_or(c, "rms_px", 0.0, path, cal);
        info.max_px = yaml::number_or(c, "max_px", 0.0, path, cal);
        info.n_points = yaml::integer_or(c, "n_points", 0, path, cal);
        if (!(info.rms_px >= 0.0 && info.max_px >= 0.0 && std::isfinite(info.rms_px) && std::isfinite(info.max_px)))
          throw InputError(path, yaml::line_of(c), cal + "rms_px and max_px must be finite and not negative");
        if (info.n_points < 0 || info.n_points > limits::kMaxPointRows)
          throw InputError(path, yaml::line_of(c["n_points"]),
                           cal + "n_points " + std::to_string(info.n_points) + " is outside 0.." +
                               std::to_string(limits::kMaxPointRows));
        if (c["outliers"] && !c["outliers"].IsNull()) info.outliers = c["outliers"].as<std::vector<int>>();
        info.date = c["date"].as<std::string>("");
        if (c["arm_link_sensitivity"] || c["arm_link_sigma_m"]) {
          info.arm_link_sigma_m = c["arm_link_sigma_m"].as<double>(-1.0);
          if (!(info.arm_link_sigma_m > 0.0) || !std::isfinite(info.arm_link_sigma_m))
            throw InputError(path, yaml::line_of(c), where + ": arm_link_sigma_m must be a positive number beside arm_link_sensitivity");
          info.arm_link_sensitivity = read_matrix<7, Eigen::Dynamic>(c["arm_link_sensitivity"], path, where + ": arm_link_sensitivity");
        }
        rec.calibration = info;
      }
      out.emplace(name, std::move(rec));
    } catch (const YAML::Exception& e) {  // "bad conversion": name the line (the node's, when the mark has none)
      throw InputError(path, e.mark.line >= 0 ? e.mark.line + 1 : yaml::line_of(n), where + ": " + e.msg);
    }
  }
  return out;
}

void save_cameras(const std::string& path, const std::map<std::string, CameraRecord>& cameras) {
  YAML::Node root;
  for (const auto& [name, rec] : cameras) {
    YAML::Node n;
    YAML::Node vp;
    vp.SetStyle(YAML::EmitterStyle::Flow);
    vp.push_back(rec.camera.viewport.width_px);
    vp.push_back(rec.camera.viewport.height_px);
    n["viewport"] = vp;
    n["f_px"] = rec.camera.f_px;
    n["fovy_deg"] = rec.camera.fovy_rad() * 180.0 / M_PI;
    n["base_T_camera"] = write_matrix<4, 4>(rec.camera.base_T_camera.matrix());
    if (rec.calibration) {
      const auto& c = *rec.calibration;
      YAML::Node cn;
      cn["rms_px"] = c.rms_px;
      cn["max_px"] = c.max_px;
      cn["n_points"] = c.n_points;
      YAML::Node outl(YAML::NodeType::Sequence);  // an empty list, not null
      outl.SetStyle(YAML::EmitterStyle::Flow);
      for (int o : c.outliers) outl.push_back(o);
      cn["outliers"] = outl;
      cn["date"] = c.date;
      cn["covariance_order"] = "roll_rad, pitch_rad, yaw_rad, x_m, y_m, z_m, f_px";
      cn["covariance"] = write_matrix<7, 7>(c.covariance);
      if (c.arm_link_sensitivity.size() > 0) {
        cn["arm_link_sigma_m"] = c.arm_link_sigma_m;
        cn["arm_link_sensitivity"] = write_matrix<7, Eigen::Dynamic>(c.arm_link_sensitivity);
      }
      n["calibration"] = cn;
    }
    root[name] = n;
  }
  YAML::Emitter em;
  em.SetDoublePrecision(12);
  em << root;
  write_file_atomic(path, std::string("# Foresight calibrated cameras (camera frame: x right, y down, z forward)\n") +
                              em.c_str() + "\n");
}

}  // namespace foresight::camera
