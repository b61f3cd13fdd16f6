// URDF -> RobotModel: tinyxml (what Debian's urdfdom itself uses) checks the
// XML and reads what urdfdom drops (the `acceleration` limit and line numbers
// for error messages), urdfdom builds the link tree, and our own conversion
// turns the base -> tip path into a KDL chain (Debian's kdl_parser is the ROS1
// package).

#include "foresight/common/robot_model.hpp"

#include <kdl/chain.hpp>

#include <console_bridge/console.h>
#include <tinyxml.h>
#include <urdf_parser/urdf_parser.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <map>
#include <mutex>
#include <sstream>
#include <stdexcept>

#include "foresight/common/error.hpp"
#include "foresight/common/input_limits.hpp"
#include "foresight/common/text_file.hpp"

namespace foresight {

namespace {

/// What the XML says about one <joint>: where it is and its raw attributes.
struct XmlJoint {
  int line = 0;
  std::string type;
  const TiXmlElement* limit = nullptr;
};

struct XmlIndex {
  std::map<std::string, XmlJoint> joints;
  std::map<std::string, int> link_lines;
};

std::string quoted(const std::string& s) { return "'" + s + "'"; }

std::string format_number(double v) {
  std::ostringstream os;
  os << v;
  return os.str();
}

/// 1-based line of byte `pos` in `text`.
int line_at(const std::string& text, std::size_t pos) {
  return 1 + static_cast<int>(std::count(text.begin(), text.begin() + static_cast<std::ptrdiff_t>(pos), '\n'));
}

/// Refuses XML nested deeper than limits::kMaxXmlDepth before any recursive
/// parser sees it (tinyxml and urdfdom recurse per level: 100,000 nested
/// elements exhausted the stack). A linear scan of tags that skips comments,
/// CDATA, declarations, processing instructions and quoted attribute values.
void check_xml_depth(const std::string& xml, const std::string& source) {
  int depth = 0;
  std::size_t i = 0;
  const std::size_t n = xml.size();
  while (i < n) {
    const std::size_t lt = xml.find('<', i);
    if (lt == std::string::npos) break;
    auto skip_to = [&](const char* end_marker) {
      const std::size_t e = xml.find(end_marker, lt);
      return e == std::string::npos ? n : e + std::strlen(end_marker);
    };
    if (xml.compare(lt, 4, "<!--") == 0) { i = skip_to("-->"); continue; }
    if (xml.compare(lt, 9, "<![CDATA[") == 0) { i = skip_to("]]>"); continue; }
    if (xml.compare(lt, 2, "<?") == 0) { i = skip_to("?>"); continue; }
    if (xml.compare(lt, 2, "<!") == 0) { i = skip_to(">"); continue; }
    const bool closing = lt + 1 < n && xml[lt + 1] == '/';
    std::size_t j = lt + 1;
    char quote = 0;
    for (; j < n; ++j) {  // the end of the tag, outside quoted attribute values
      const char c = xml[j];
      if (quote != 0) {
        if (c == quote) quote = 0;
      } else if (c == '"' || c == '\'') {
        quote = c;
      } else if (c == '>') {
        break;
      }
    }
    if (j >= n) break;  // unterminated: tinyxml reports it
    const bool self_closing = xml[j - 1] == '/';
    if (closing) {
      depth = std::max(0, depth - 1);
    } else if (!self_closing && ++depth > limits::kMaxXmlDepth) {
      throw InputError(source, line_at(xml, lt),
                       "XML nested deeper than " + std::to_string(limits::kMaxXmlDepth) + " elements");
    }
    i = j + 1;
  }
}

/// A URDF's links must form a tree: every link the child of at most one
/// joint, no loop. urdfdom does not check this (a link with two parents made
/// the walk from the tip to the base loop forever).
void check_tree(const TiXmlElement* robot, const std::string& source) {
  struct Parent {
    std::string joint;
    std::string link;
    int line;
  };
  std::map<std::string, Parent> parent_of;  // child link -> its joint
  for (const TiXmlElement* e = robot->FirstChildElement("joint"); e; e = e->NextSiblingElement("joint")) {
    const TiXmlElement* parent = e->FirstChildElement("parent");
    const TiXmlElement* child = e->FirstChildElement("child");
    const char* name = e->Attribute("name");
    if (parent == nullptr || child == nullptr || parent->Attribute("link") == nullptr ||
        child->Attribute("link") == nullptr || name == nullptr)
      continue;  // urdfdom reports these
    const std::string c = child->Attribute("link");
    const auto [it, fresh] = parent_of.emplace(c, Parent{name, parent->Attribute("link"), e->Row()});
    if (!fresh)
      throw InputError(source, e->Row(),
                       "joint " + quoted(name) + ": link " + quoted(c) + " already has a parent (joint " +
                           quoted(it->second.joint) + " at line " + std::to_string(it->second.line) +
                           "): the links must form a tree");
  }
  for (const auto& [link, first] : parent_of) {  // every walk up ends within as many steps as there are joints
    std::string at = link;
    for (std::size_t steps = 0;; ++steps) {
      const auto up = parent_of.find(at);
      if (up == parent_of.end()) break;
      if (steps > parent_of.size())
        throw InputError(source, first.line,
                         "link " + quoted(link) + " is its own ancestor (a loop of joints): the links must form a tree");
      at = up->second.link;
    }
  }
}

/// Parse the XML, check the things urdfdom does not (or reports without a
/// line), and index joints and links by name.
XmlIndex check_xml(const TiXmlDocument& doc, const std::string& source) {
  const TiXmlElement* robot = doc.RootElement();
  if (robot == nullptr) throw InputError(source, "malformed XML: no root element");
  if (std::string(robot->Value()) != "robot")
    throw InputError(source, robot->Row(), "root element is <" + std::string(robot->Value()) + ">, expected <robot>");
  check_tree(robot, source);
  XmlIndex index;
  for (const TiXmlElement* e = robot->FirstChildElement("link"); e; e = e->NextSiblingElement("link")) {
    const char* name = e->Attribute("name");
    if (name != nullptr) index.link_lines[name] = e->Row();
  }
  for (const TiXmlElement* e = robot->FirstChildElement("joint"); e; e = e->NextSiblingElement("joint")) {
    const char* name = e->Attribute("name");
    if (name == nullptr) throw InputError(source, e->Row(), "<joint> without a name attribute");
    XmlJoint j;
    j.line = e->Row();
    j.type = e->Attribute("type") ? e->Attribute("type") : "";
    j.limit = e->FirstChildElement("limit");
    // urdfdom refuses these too, but without saying where.
    if (j.type == "revolute" && j.limit == nullptr)
      throw InputError(source, j.line, "joint " + quoted(name) + ": revolute joint has no <limit> element");
    index.joints[name] = j;
  }
  return index;
}

/// Collects urdfdom's error messages (it reports through console_bridge).
class CaptureErrors : public console_bridge::OutputHandler {
 public:
  void log(const std::string& text, console_bridge::LogLevel level, const char*, int) override {
    if (level >= console_bridge::CONSOLE_BRIDGE_LOG_ERROR && first_error.empty()) first_error = text;
  }
  std::string first_error;
};

urdf::ModelInterfaceSharedPtr parse_with_urdfdom(const std::string& xml, const std::string& source) {
  static std::mutex mutex;  // console_bridge's handler is process-global
  const std::lock_guard<std::mutex> lock(mutex);
  CaptureErrors capture;
  console_bridge::OutputHandler* previous = console_bridge::getOutputHandler();
  console_bridge::useOutputHandler(&capture);
  urdf::ModelInterfaceSharedPtr model;
  try {
    model = urdf::parseURDF(xml);
  } catch (const std::exception& e) {
    capture.first_error = e.what();
  }
  console_bridge::useOutputHandler(previous);
  // urdfdom logs some errors and carries on (mass="nan": "Could not parse
  // inertial element", then a model with mass 0): an error logged is a refusal.
  if (!model || !capture.first_error.empty()) {
    std::string why = capture.first_error;
    while (!why.empty() && (why.back() == '\n' || why.back() == ' ')) why.pop_back();
    throw InputError(source, "URDF rejected by urdfdom: " + (why.empty() ? std::string("(no reason given)") : why));
  }
  return model;
}

KDL::Frame to_kdl(const urdf::Pose& p) {
  return KDL::Frame(KDL::Rotation::Quaternion(p.rotation.x, p.rotation.y, p.rotation.z, p.rotation.w),
                    KDL::Vector(p.position.x, p.position.y, p.position.z));
}

Pose to_pose(const urdf::Pose& p) {
  Pose T = Pose::Identity();
  T.linear() = Eigen::Quaterniond(p.rotation.w, p.rotation.x, p.rotation.y, p.rotation.z).normalized().toRotationMatrix();
  T.translation() = Eigen::Vector3d(p.position.x, p.position.y, p.position.z);
  return T;
}

/// URDF inertia is about the COM in the inertial frame; KDL wants it about the
/// COM in the link frame (same as ROS kdl_parser).
KDL::RigidBodyInertia to_kdl(const urdf::Inertial& i) {
  const KDL::Frame origin = to_kdl(i.origin);
  const KDL::RotationalInertia I_inertial(i.ixx, i.iyy, i.izz, i.ixy, i.ixz, i.iyz);
  // Rotating a RotationalInertia is only defined on RigidBodyInertia: use one with zero mass at the origin.
  const KDL::RigidBodyInertia rotated = origin.M * KDL::RigidBodyInertia(0.0, KDL::Vector::Zero(), I_inertial);
  return KDL::RigidBodyInertia(i.mass, origin.p, rotated.getRotationalInertia());
}

std::vector<VisualShape> visuals_of(const urdf::Link& link) {
  std::vector<VisualShape> out;
  for (const auto& v : link.visual_array) {
    if (!v || !v->geometry) continue;
    VisualShape s;
    switch (v->geometry->type) {
      case urdf::Geometry::BOX: {
        const auto& b = static_cast<const urdf::Box&>(*v->geometry);
        s.type = VisualShape::Type::Box;
        s.size_m = Eigen::Vector3d(b.dim.x, b.dim.y, b.dim.z);
        break;
      }
      case urdf::Geometry::CYLINDER: {
        const auto& c = static_cast<const urdf::Cylinder&>(*v->geometry);
        s.type = VisualShape::Type::Cylinder;
        s.size_m = Eigen::Vector3d(c.radius, c.length, 0.0);
        break;
      }
      case urdf::Geometry::SPHERE: {
        const auto& c = static_cast<const urdf::Sphere&>(*v->geometry);
        s.type = VisualShape::Type::Sphere;
        s.size_m = Eigen::Vector3d(c.radius, 0.0, 0.0);
        break;
      }
      default:
        continue;  // meshes are not drawn (our URDF uses primitives only)
    }
    s.link_T_shape = to_pose(v->origin);
    if (v->material) {
      const auto& c = v->material->color;
      s.rgba = Eigen::Vector4d(c.r, c.g, c.b, c.a);
    }
    out.push_back(s);
  }
  return out;
}

/// Reads limit attribute `name` of a chain joint as a positive finite number.
double positive_attribute(const XmlJoint& xj, const std::string& joint, const char* name, const std::string& source,
                          const char* meaning) {
  const int line = xj.limit->Row();
  const char* text = xj.limit->Attribute(name);
  if (text == nullptr)
    throw InputError(source, line, "joint " + quoted(joint) + ": <limit> has no " + name + " attribute (" + meaning + ")");
  char* end = nullptr;
  const double v = std::strtod(text, &end);
  while (end != nullptr && (*end == ' ' || *end == '\t')) ++end;
  if (end == text || end == nullptr || *end != '\0' || !std::isfinite(v) || !(v > 0.0))
    throw InputError(source, line,
                     "joint " + quoted(joint) + ": <limit " + name + "=\"" + text + "\"> is not a positive number");
  return v;
}

/// Physical ranges urdfdom does not check, for every link and joint in the
/// file (not only the chain): masses finite and in [0, kMaxMass_kg],
/// inertias finite, origins finite and within kMaxOffset_m.
void check_physical_ranges(const urdf::ModelInterface& model, const XmlIndex& xml, const std::string& source) {
  auto origin_ok = [](const urdf::Pose& p) {
    const double c[] = {p.position.x, p.position.y, p.position.z, p.rotation.x, p.rotation.y, p.rotation.z, p.rotation.w};
    for (double v : c)
      if (!std::isfinite(v)) return false;
    return std::abs(p.position.x) <= limits::kMaxOffset_m && std::abs(p.position.y) <= limits::kMaxOffset_m &&
           std::abs(p.position.z) <= limits::kMaxOffset_m;
  };
  auto xyz = [](const urdf::Pose& p) {
    return "(" + format_number(p.position.x) + ", " + format_number(p.position.y) + ", " +
           format_number(p.position.z) + ")";
  };
  const std::string sane = " (finite, each within " + format_number(limits::kMaxOffset_m) + " m)";
  for (const auto& [name, link] : model.links_) {
    if (!link || !link->inertial) continue;
    const int line = xml.link_lines.count(name) ? xml.link_lines.at(name) : 0;
    const urdf::Inertial& in = *link->inertial;
    if (!std::isfinite(in.mass) || in.mass < 0.0 || in.mass > limits::kMaxMass_kg)
      throw InputError(source, line,
                       "link " + quoted(name) + ": mass " + format_number(in.mass) + " kg is not in [0, " +
                           format_number(limits::kMaxMass_kg) + "] kg");
    const double I[] = {in.ixx, in.ixy, in.ixz, in.iyy, in.iyz, in.izz};
    for (double v : I)
      if (!std::isfinite(v)) throw InputError(source, line, "link " + quoted(name) + ": <inertia> has a non-finite value");
    if (!origin_ok(in.origin))
      throw InputError(source, line,
                       "link " + quoted(name) + ": <inertial> origin " + xyz(in.origin) + " out of range" + sane);
  }
  for (const auto& [name, joint] : model.joints_) {
    if (!joint) continue;
    const int line = xml.joints.count(name) ? xml.joints.at(name).line : 0;
    if (!origin_ok(joint->parent_to_joint_origin_transform))
      throw InputError(source, line,
                       "joint " + quoted(name) + ": origin " + xyz(joint->parent_to_joint_origin_transform) +
                           " m out of range" + sane);
    const double axis[] = {joint->axis.x, joint->axis.y, joint->axis.z};
    for (double v : axis)
      if (!std::isfinite(v)) throw InputError(source, line, "joint " + quoted(name) + ": <axis> has a non-finite value");
  }
}

/// Model identities: unique per built model, in any thread.
std::uint64_t next_model_id() {
  static std::atomic<std::uint64_t> next{1};
  return next.fetch_add(1, std::memory_order_relaxed);
}

}  // namespace

RobotModel RobotModel::from_file(const std::string& urdf_path, const RobotModelOptions& options) {
  return from_xml(read_text_file(urdf_path, "cannot open URDF file"), urdf_path, options);
}

RobotModel RobotModel::from_xml(const std::string& urdf_xml, const std::string& source_name,
                                const RobotModelOptions& options) {
  check_xml_depth(urdf_xml, source_name);
  TiXmlDocument doc;
  doc.Parse(urdf_xml.c_str());
  if (doc.Error())
    throw InputError(source_name, doc.ErrorRow(), std::string("malformed XML: ") + doc.ErrorDesc());
  const XmlIndex xml = check_xml(doc, source_name);
  const urdf::ModelInterfaceSharedPtr urdf_model = parse_with_urdfdom(urdf_xml, source_name);
  check_physical_ranges(*urdf_model, xml, source_name);

  const urdf::LinkConstSharedPtr base = urdf_model->getLink(options.base_link);
  if (!base) throw InputError(source_name, "base link " + quoted(options.base_link) + " not found (no <link name=\"" +
                                               options.base_link + "\">)");
  const urdf::LinkConstSharedPtr tip = urdf_model->getLink(options.tip_link);
  if (!tip) throw InputError(source_name, "tip link " + quoted(options.tip_link) + " not found (no <link name=\"" +
                                              options.tip_link + "\">)");

  // Walk up from the tip to the base.
  std::vector<urdf::LinkConstSharedPtr> path;  // tip ... base
  for (urdf::LinkConstSharedPtr l = tip; l && path.size() <= urdf_model->links_.size(); l = l->getParent()) {
    path.push_back(l);
    if (l == base) break;
  }
  if (path.back() != base)
    throw InputError(source_name, xml.link_lines.count(options.tip_link) ? xml.link_lines.at(options.tip_link) : 0,
                     "tip link " + quoted(options.tip_link) + " is not below base link " + quoted(options.base_link));
  std::reverse(path.begin(), path.end());  // base ... tip

  RobotModel m;
  m.id_ = next_model_id();
  auto chain = std::make_shared<KDL::Chain>();
  m.source_ = source_name;
  for (std::size_t k = 0; k < path.size(); ++k) {
    const urdf::Link& link = *path[k];
    const int link_line = xml.link_lines.count(link.name) ? xml.link_lines.at(link.name) : 0;
    if (k + 1 < path.size() && link.child_joints.size() > 1) {
      std::string names;
      for (const auto& j : link.child_joints) names += (names.empty() ? "" : ", ") + quoted(j->name);
      throw InputError(source_name, link_line,
                       "non-serial chain: link " + quoted(link.name) + " on the chain " + options.base_link + " -> " +
                           options.tip_link + " has " + std::to_string(link.child_joints.size()) +
                           " child joints (" + names + ")");
    }
    LinkInfo info;
    info.name = link.name;
    info.visuals = visuals_of(link);
    info.mass_kg = (k > 0 && link.inertial) ? link.inertial->mass : 0.0;
    m.links_.push_back(std::move(info));
    if (k == 0) continue;  // the base is fixed: no segment

    const urdf::Joint& joint = *link.parent_joint;
    const XmlJoint& xj = xml.joints.at(joint.name);
    const KDL::Frame parent_T_joint = to_kdl(joint.parent_to_joint_origin_transform);
    KDL::Joint kdl_joint(joint.name, KDL::Joint::None);
    if (joint.type == urdf::Joint::REVOLUTE) {
      const KDL::Vector axis(joint.axis.x, joint.axis.y, joint.axis.z);
      if (!(axis.Norm() > 1e-9)) throw InputError(source_name, xj.line, "joint " + quoted(joint.name) + ": zero <axis>");
      const urdf::JointLimits& ul = *joint.limits;
      const int limit_line = xj.limit->Row();
      if (!std::isfinite(ul.lower) || !std::isfinite(ul.upper) || ul.lower > ul.upper)
        throw InputError(source_name, limit_line,
                         "joint " + quoted(joint.name) + ": <limit> lower (" + format_number(ul.lower) +
                             ") > upper (" + format_number(ul.upper) + ")");
      JointLimits lim;
      lim.lower_rad = ul.lower;
      lim.upper_rad = ul.upper;
      lim.velocity_rad_s = positive_attribute(xj, joint.name, "velocity", source_name, "rad/s");
      lim.effort_nm = positive_attribute(xj, joint.name, "effort", source_name, "N m");
      lim.acceleration_rad_s2 =
          positive_attribute(xj, joint.name, "acceleration", source_name, "rad/s^2, required by Foresight");
      // Axis in the parent frame through the joint origin: segment pose = parent_T_joint * Rot(axis, q).
      kdl_joint = KDL::Joint(joint.name, parent_T_joint.p, parent_T_joint.M * (axis / axis.Norm()),
                             KDL::Joint::RotAxis);
      m.joint_names_.push_back(joint.name);
      m.limits_.push_back(lim);
    } else if (joint.type != urdf::Joint::FIXED) {
      throw InputError(source_name, xj.line,
                       "joint " + quoted(joint.name) + ": unsupported joint type " + quoted(xj.type) +
                           " (only revolute and fixed)");
    }
    const KDL::RigidBodyInertia inertia =
        link.inertial ? to_kdl(*link.inertial) : KDL::RigidBodyInertia::Zero();
    chain->addSegment(KDL::Segment(link.name, kdl_joint, parent_T_joint, inertia));
  }
  m.segment_count_ = static_cast<int>(chain->getNrOfSegments());
  m.chain_ = std::move(chain);
  if (m.joint_names_.empty())
    throw InputError(source_name, "no revolute joint between base link " + quoted(options.base_link) +
                                      " and tip link " + quoted(options.tip_link));
  return m;
}

RobotModel RobotModel::with_link_lengths_changed(const std::vector<double>& delta_m) const {
  const unsigned nseg = chain_->getNrOfSegments();
  if (delta_m.size() != nseg)
    throw std::invalid_argument("with_link_lengths_changed: " + std::to_string(delta_m.size()) +
                                " length changes for " + std::to_string(nseg) + " chain segments");
  RobotModel m = *this;
  m.id_ = next_model_id();
  auto chain = std::make_shared<KDL::Chain>();
  for (unsigned k = 0; k < nseg; ++k) {
    const KDL::Segment& seg = chain_->getSegment(k);
    KDL::Frame parent_T_joint = seg.getFrameToTip();  // at q = 0: the joint origin (RobotModel builds it so)
    const double length = parent_T_joint.p.Norm();
    if (length > kMinOffset_m) parent_T_joint.p = parent_T_joint.p * ((length + delta_m[k]) / length);
    const KDL::Joint& j = seg.getJoint();
    const KDL::Joint joint = j.getType() == KDL::Joint::None
                                 ? j
                                 : KDL::Joint(j.getName(), parent_T_joint.p, j.JointAxis(), KDL::Joint::RotAxis);
    chain->addSegment(KDL::Segment(seg.getName(), joint, parent_T_joint, seg.getInertia()));
  }
  m.chain_ = std::move(chain);
  return m;
}

std::vector<int> RobotModel::offset_segments() const {
  std::vector<int> out;
  for (unsigned k = 0; k < chain_->getNrOfSegments(); ++k)
    if (chain_->getSegment(k).getFrameToTip().p.Norm() > kMinOffset_m) out.push_back(static_cast<int>(k));
  return out;
}

int RobotModel::link_index(const std::string& name) const {
  for (std::size_t i = 0; i < links_.size(); ++i)
    if (links_[i].name == name) return static_cast<int>(i);
  return -1;
}

bool RobotModel::within_limits(const Eigen::Ref<const Eigen::VectorXd>& q, double tol_rad) const {
  if (q.size() != dof()) return false;
  for (int i = 0; i < dof(); ++i) {
    if (!std::isfinite(q[i])) return false;
    if (q[i] < limits_[i].lower_rad - tol_rad || q[i] > limits_[i].upper_rad + tol_rad) return false;
  }
  return true;
}

Eigen::VectorXd RobotModel::mid_configuration() const {
  Eigen::VectorXd q(dof());
  for (int i = 0; i < dof(); ++i) q[i] = 0.5 * (limits_[i].lower_rad + limits_[i].upper_rad);
  return q;
}

}  // namespace foresight
