#include "foresight/calibration/robot_points.hpp"

#include <cstdio>

#include "foresight/common/input_limits.hpp"

namespace foresight::calibration {

LinkLengthSensitivity::LinkLengthSensitivity(const RobotModel& model) : model_(model), ws_(model) {
  const unsigned nseg = model.segment_count();
  for (const int k : model.offset_segments()) {
    std::vector<double> d(nseg, 0.0);
    d[k] = kStep_m;
    segments_.push_back(k);
    stepped_.push_back(std::make_unique<RobotModel>(model.with_link_lengths_changed(d)));
    stepped_ws_.push_back(std::make_unique<KinematicsWorkspace>(*stepped_.back()));
  }
}

LinkLengthSensitivity::~LinkLengthSensitivity() = default;

Eigen::Matrix3Xd LinkLengthSensitivity::at(const Eigen::VectorXd& q, int link, const Eigen::Vector3d& p_link) {
  Eigen::Matrix3Xd out = Eigen::Matrix3Xd::Zero(3, model_.segment_count());
  const Eigen::Vector3d p = forward_kinematics(model_, ws_, q, link) * p_link;
  for (std::size_t j = 0; j < segments_.size(); ++j)
    out.col(segments_[j]) = (forward_kinematics(*stepped_[j], *stepped_ws_[j], q, link) * p_link - p) / kStep_m;
  return out;
}

RobotLinkPoints::RobotLinkPoints(std::string urdf_path) : path_(std::move(urdf_path)) {}

RobotLinkPoints::RobotLinkPoints(const RobotModel& model) : model_(model) {
  ws_ = std::make_unique<KinematicsWorkspace>(*model_);
}

RobotLinkPoints::~RobotLinkPoints() = default;

void RobotLinkPoints::load() const {
  if (model_) return;
  model_.emplace(RobotModel::from_file(path_));
  ws_ = std::make_unique<KinematicsWorkspace>(*model_);
}

const RobotModel& RobotLinkPoints::model() const {
  load();
  return *model_;
}

int RobotLinkPoints::dof() const { return model().dof(); }

bool RobotLinkPoints::has_link(const std::string& link) const { return model().link_index(link) >= 0; }

std::string RobotLinkPoints::link_list() const {
  std::string s;
  for (const auto& l : model().links()) s += (s.empty() ? "" : ", ") + l.name;
  return s;
}

std::optional<std::string> RobotLinkPoints::joints_out_of_range(const Eigen::VectorXd& q) const {
  const RobotModel& m = model();
  const double margin = limits::kJointLimitMargin_rad;
  for (int i = 0; i < m.dof() && i < q.size(); ++i) {
    const JointLimits& l = m.limits()[static_cast<std::size_t>(i)];
    if (!(q[i] >= l.lower_rad - margin && q[i] <= l.upper_rad + margin)) {
      char buf[200];
      std::snprintf(buf, sizeof buf, "q%d = %g rad is outside the joint's limits [%g, %g] rad (+- %g)", i + 1, q[i],
                    l.lower_rad, l.upper_rad, margin);
      return std::string(buf);
    }
  }
  return std::nullopt;
}

Eigen::Vector3d RobotLinkPoints::to_base(const std::string& link, const Eigen::Vector3d& p_link,
                                         const Eigen::VectorXd& q) const {
  const RobotModel& m = model();
  return forward_kinematics(m, *ws_, q, m.link_index(link)) * p_link;
}

Eigen::Matrix3Xd RobotLinkPoints::link_length_sensitivity(const std::string& link, const Eigen::Vector3d& p_link,
                                                          const Eigen::VectorXd& q) const {
  const RobotModel& m = model();
  if (!sensitivity_) sensitivity_ = std::make_unique<LinkLengthSensitivity>(m);
  return sensitivity_->at(q, m.link_index(link), p_link);
}

}  // namespace foresight::calibration
