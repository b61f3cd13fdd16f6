#pragma once
// The robot arm as the calibration fixture: link-form rows of the points CSV
// (n,cam,link,lx,ly,lz,q1..qN,u,v) resolved to base coordinates with the URDF
// model and forward kinematics. Set-up code (loads the URDF, allocates).

#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "foresight/calibration/correspondence.hpp"
#include "foresight/common/kinematics.hpp"
#include "foresight/common/robot_model.hpp"

namespace foresight::calibration {

/// How a point fixed on an arm link moves in base when the arm's link
/// lengths change: 3 x (chain segments), column k the point's motion per
/// metre of segment k's offset (RobotModel::with_link_lengths_changed);
/// zero for segments without an offset and those beyond the link. Forward
/// kinematics is linear in the offsets at fixed q, so the difference over a
/// 1 mm step is exact. The calibration's arm-model uncertainty
/// (CalibrationOptions::arm_link_sigma_m) uses it.
class LinkLengthSensitivity {
 public:
  explicit LinkLengthSensitivity(const RobotModel& model);  // the model outlives this
  ~LinkLengthSensitivity();
  Eigen::Matrix3Xd at(const Eigen::VectorXd& q, int link, const Eigen::Vector3d& p_link);

 private:
  static constexpr double kStep_m = 1e-3;
  const RobotModel& model_;
  KinematicsWorkspace ws_;
  // Per segment with an offset: the model with it stepped, and its workspace.
  std::vector<int> segments_;
  std::vector<std::unique_ptr<RobotModel>> stepped_;
  std::vector<std::unique_ptr<KinematicsWorkspace>> stepped_ws_;
};

class RobotLinkPoints : public LinkPointResolver {
 public:
  /// Loads the URDF on first use (a points file with only x,y,z rows never
  /// needs it); a bad URDF throws InputError then.
  explicit RobotLinkPoints(std::string urdf_path);
  /// Uses an already loaded model.
  explicit RobotLinkPoints(const RobotModel& model);
  ~RobotLinkPoints() override;

  int dof() const override;
  bool has_link(const std::string& link) const override;
  std::string link_list() const override;
  std::optional<std::string> joints_out_of_range(const Eigen::VectorXd& q) const override;
  Eigen::Vector3d to_base(const std::string& link, const Eigen::Vector3d& p_link,
                          const Eigen::VectorXd& q) const override;
  Eigen::Matrix3Xd link_length_sensitivity(const std::string& link, const Eigen::Vector3d& p_link,
                                           const Eigen::VectorXd& q) const override;

  const RobotModel& model() const;

 private:
  void load() const;
  std::string path_;
  mutable std::optional<RobotModel> model_;
  mutable std::unique_ptr<KinematicsWorkspace> ws_;
  mutable std::unique_ptr<LinkLengthSensitivity> sensitivity_;  // built on first use
};

}  // namespace foresight::calibration
