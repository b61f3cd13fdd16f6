#pragma once
// The robot arm as the calibration fixture: link-form rows of the points CSV
// (n,cam,link,lx,ly,lz,q1..qN,u,v) resolved to base coordinates with the URDF
// model and forward kinematics. Set-up code (loads the URDF, allocates).

#include <memory>
#include <optional>
#include <string>

#include "foresight/calibration/correspondence.hpp"
#include "foresight/common/kinematics.hpp"
#include "foresight/common/robot_model.hpp"

namespace foresight {

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

  const RobotModel& model() const;

 private:
  void load() const;
  std::string path_;
  mutable std::optional<RobotModel> model_;
  mutable std::unique_ptr<KinematicsWorkspace> ws_;
};

}  // namespace foresight
