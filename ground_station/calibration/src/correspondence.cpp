#include "foresight/calibration/correspondence.hpp"

#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <iomanip>
#include <optional>
#include <sstream>

#include "foresight/common/error.hpp"
#include "foresight/common/input_limits.hpp"
#include "foresight/common/number_list.hpp"
#include "foresight/common/text_file.hpp"

namespace foresight::calibration {

namespace {

std::string trim(const std::string& s) {
  const auto b = s.find_first_not_of(" \t\r");
  if (b == std::string::npos) return "";
  const auto e = s.find_last_not_of(" \t\r");
  return s.substr(b, e - b + 1);
}

std::vector<std::string> split(const std::string& line) {
  std::vector<std::string> out;
  for (const std::string_view field : split_commas(line)) out.push_back(trim(std::string(field)));
  return out;
}

/// Parses a number; false when the text is not one. Non-finite values parse
/// (std::strtod accepts nan/inf) and are reported by the caller.
bool to_double(const std::string& text, double& value) {
  if (text.empty()) return false;
  char* end = nullptr;
  errno = 0;
  value = std::strtod(text.c_str(), &end);
  return end == text.c_str() + text.size();
}

const char* kHeaderHelp = "header must be 'n,cam,x,y,z,u,v' or 'n,cam,link,lx,ly,lz,q1,...,qN,u,v'";

}  // namespace

std::vector<Correspondence> parse_correspondences_csv(const std::string& text, const std::string& source,
                                                      const LinkPointResolver* robot) {
  std::vector<Correspondence> out;
  std::istringstream in(text);
  LineReader reader(in, source);
  std::string raw;
  bool header_seen = false;
  int header_q = -1;  // joint angles the header names (link form), -1: base form
  while (reader.next(raw)) {
    const int line_no = reader.line_no();
    const std::string line = trim(raw);
    if (line.empty() || line[0] == '#') continue;
    const std::vector<std::string> f = split(line);
    if (!header_seen) {
      header_seen = true;
      const bool base_form = f.size() == 7 && f[0] == "n" && f[1] == "cam" && f[2] == "x" && f[3] == "y" &&
                             f[4] == "z" && f[5] == "u" && f[6] == "v";
      bool link_form = f.size() >= 9 && f[0] == "n" && f[1] == "cam" && f[2] == "link" && f[3] == "lx" &&
                       f[4] == "ly" && f[5] == "lz" && f[f.size() - 2] == "u" && f.back() == "v";
      for (std::size_t i = 6; link_form && i + 2 < f.size(); ++i)
        link_form = f[i] == "q" + std::to_string(i - 5);
      if (!base_form && !link_form) throw InputError(source, line_no, kHeaderHelp + std::string(", got '") + line + "'");
      if (link_form) header_q = static_cast<int>(f.size()) - 8;
      continue;
    }
    if (static_cast<int>(out.size()) >= limits::kMaxPointRows)
      throw InputError(source, line_no,
                       "more than " + std::to_string(limits::kMaxPointRows) + " points (the most a points file may have)");
    Correspondence c;
    c.line = line_no;
    double number = 0.0;
    if (f.size() < 7)
      throw InputError(source, line_no,
                       "expected 7 fields n,cam,x,y,z,u,v (or n,cam,link,lx,ly,lz,q1..qN,u,v), got " +
                           std::to_string(f.size()));
    if (!to_double(f[0], number) || !limits::fits_int(number))
      throw InputError(source, line_no, "field 'n' must be an integer point number that fits an int, got '" + f[0] + "'");
    c.n = static_cast<int>(number);
    if (f[1].empty()) throw InputError(source, line_no, "field 'cam' is empty");
    c.cam = f[1];
    const bool link_row = !to_double(f[2], number);
    auto num = [&](std::size_t i, const std::string& name) {
      double v = 0.0;
      if (!to_double(f[i], v)) throw InputError(source, line_no, "field '" + name + "' is not a number: '" + f[i] + "'");
      if (!std::isfinite(v)) throw InputError(source, line_no, "field '" + name + "' is not finite: '" + f[i] + "'");
      return v;
    };
    if (!link_row) {
      if (f.size() != 7)
        throw InputError(source, line_no, "expected 7 fields n,cam,x,y,z,u,v, got " + std::to_string(f.size()));
      c.p_m = {num(2, "x"), num(3, "y"), num(4, "z")};
      c.uv_px = {num(5, "u"), num(6, "v")};
    } else {
      c.link = f[2];
      if (robot == nullptr)
        throw InputError(source, line_no,
                         "point on link '" + c.link + "' but no robot model here: arm-link rows are for calibrate; " +
                             "give x,y,z in the object frame");
      // A base-form header names x,y,z columns: a link row under it is read
      // against names it does not have (the link-form header may also carry
      // x,y,z rows: points known in the base frame).
      if (header_q < 0)
        throw InputError(source, line_no,
                         "a point on link '" + c.link + "' (link form) under the header 'n,cam,x,y,z,u,v': give the "
                         "link-form header 'n,cam,link,lx,ly,lz,q1,...,qN,u,v'");
      if (!robot->has_link(c.link))
        throw InputError(source, line_no, "unknown link '" + c.link + "' (the robot's links: " + robot->link_list() + ")");
      const int dof = robot->dof();
      const int n_q = static_cast<int>(f.size()) - 8;
      if (header_q >= 0 && header_q != dof)
        throw InputError(source, line_no,
                         "the header names " + std::to_string(header_q) + " joint angles, the robot has " +
                             std::to_string(dof) + " joints (q1..q" + std::to_string(dof) + ")");
      if (n_q != dof)
        throw InputError(source, line_no,
                         "point on link '" + c.link + "' needs " + std::to_string(dof) + " joint angles q1..q" +
                             std::to_string(dof) + ", got " + std::to_string(std::max(n_q, 0)));
      const Eigen::Vector3d p_link(num(3, "lx"), num(4, "ly"), num(5, "lz"));
      Eigen::VectorXd q(dof);
      for (int i = 0; i < dof; ++i) q[i] = num(6 + i, "q" + std::to_string(i + 1));
      if (const std::optional<std::string> why = robot->joints_out_of_range(q))
        throw InputError(source, line_no, "point on link '" + c.link + "': " + *why);
      c.uv_px = {num(6 + dof, "u"), num(7 + dof, "v")};
      c.p_m = robot->to_base(c.link, p_link, q);
      c.dp_dlinks = robot->link_length_sensitivity(c.link, p_link, q);
    }
    out.push_back(std::move(c));
  }
  if (!header_seen) throw InputError(source, "empty file: " + std::string(kHeaderHelp));
  if (out.empty()) throw InputError(source, "no points (only a header)");
  return out;
}

std::vector<Correspondence> read_correspondences_csv(const std::string& path, const LinkPointResolver* robot) {
  return parse_correspondences_csv(read_text_file(path, "cannot open points file"), path, robot);
}

void check_in_viewport(const std::vector<Correspondence>& points, const camera::Viewport& vp, const std::string& source) {
  const double m = limits::kViewportMarginFraction * std::max(vp.width_px, vp.height_px);
  for (const auto& c : points) {
    const double u = c.uv_px.x(), v = c.uv_px.y();
    if (u >= -m && v >= -m && u <= vp.width_px + m && v <= vp.height_px + m) continue;
    std::ostringstream m;
    m << "point n=" << c.n << ": pixel (" << u << ", " << v << ") is outside the " << vp.width_px << "x"
      << vp.height_px << " viewport of camera '" << c.cam << "'";
    throw InputError(source, c.line, m.str());
  }
}

std::vector<Correspondence> select_camera(const std::vector<Correspondence>& points, const std::string& cam) {
  std::vector<Correspondence> out;
  for (const auto& p : points)
    if (p.cam == cam) out.push_back(p);
  return out;
}

std::string to_csv(const std::vector<Correspondence>& points) {
  std::ostringstream s;
  s << std::setprecision(17) << "n,cam,x,y,z,u,v\n";
  for (const auto& p : points)
    s << p.n << ',' << p.cam << ',' << p.p_m.x() << ',' << p.p_m.y() << ',' << p.p_m.z() << ',' << p.uv_px.x() << ','
      << p.uv_px.y() << '\n';
  return s.str();
}

}  // namespace foresight::calibration
