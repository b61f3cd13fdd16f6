#include <gtest/gtest.h>

#include "foresight/calibration/correspondence.hpp"
#include "foresight/common/error.hpp"
#include "foresight/common/pose.hpp"

using namespace foresight;

namespace {

/// A 2-joint "arm": link "l1" rotates about z by q1 at the origin, link "l2"
/// is l1 translated 1 m along its x and rotated by q2 about z.
class FakeArm : public calibration::LinkPointResolver {
 public:
  int dof() const override { return 2; }
  bool has_link(const std::string& l) const override { return l == "base" || l == "l1" || l == "l2"; }
  std::string link_list() const override { return "base, l1, l2"; }
  Eigen::Vector3d to_base(const std::string& l, const Eigen::Vector3d& p, const Eigen::VectorXd& q) const override {
    const Pose T1 = make_pose(Eigen::Vector3d::Zero(), Eigen::Vector3d(0, 0, q[0]));
    const Pose T2 = T1 * make_pose(Eigen::Vector3d(1, 0, 0), Eigen::Vector3d(0, 0, q[1]));
    if (l == "base") return p;
    return (l == "l1" ? T1 : T2) * p;
  }
};

std::string error_of(const std::string& text, const calibration::LinkPointResolver* robot = nullptr) {
  try {
    calibration::parse_correspondences_csv(text, "pts.csv", robot);
  } catch (const InputError& e) {
    return e.what();
  }
  return "(no error)";
}

}  // namespace

TEST(PointsCsv, ParsesBaseRowsWithLineNumbers) {
  const auto pts = calibration::parse_correspondences_csv("# clicks\nn,cam,x,y,z,u,v\n\n1, side, 0.5, -0.25, 1e-1, 320.5, 240\n2,top,1,2,3,4,5\n",
                                             "pts.csv");
  ASSERT_EQ(pts.size(), 2u);
  EXPECT_EQ(pts[0].n, 1);
  EXPECT_EQ(pts[0].cam, "side");
  EXPECT_EQ(pts[0].line, 4);
  EXPECT_EQ(pts[0].p_m, Eigen::Vector3d(0.5, -0.25, 0.1));
  EXPECT_EQ(pts[0].uv_px, Eigen::Vector2d(320.5, 240));
  EXPECT_EQ(pts[1].line, 5);
  EXPECT_EQ(calibration::select_camera(pts, "top").size(), 1u);
  // Round trip.
  const auto again = calibration::parse_correspondences_csv(calibration::to_csv(pts), "x.csv");
  EXPECT_EQ(again[1].p_m, pts[1].p_m);
}

TEST(PointsCsv, LinkRowsGoThroughForwardKinematics) {
  FakeArm arm;
  const auto pts = calibration::parse_correspondences_csv(
      "n,cam,link,lx,ly,lz,q1,q2,u,v\n1,side,l2,0.5,0,0,1.5707963267948966,0,10,20\n2,side,0.1,0.2,0.3,30,40\n", "pts.csv",
      &arm);
  ASSERT_EQ(pts.size(), 2u);
  EXPECT_EQ(pts[0].link, "l2");
  EXPECT_NEAR((pts[0].p_m - Eigen::Vector3d(0, 1.5, 0)).norm(), 0.0, 1e-12);
  EXPECT_EQ(pts[1].p_m, Eigen::Vector3d(0.1, 0.2, 0.3));  // both row forms in one file
  EXPECT_EQ(pts[1].link, "");
}

TEST(PointsCsv, BadInputsNameFileAndLine) {
  FakeArm arm;
  EXPECT_EQ(error_of(""), "pts.csv: empty file: header must be 'n,cam,x,y,z,u,v' or 'n,cam,link,lx,ly,lz,q1,...,qN,u,v'");
  EXPECT_EQ(error_of("n,cam,x,y,z,u,v\n"), "pts.csv: no points (only a header)");
  EXPECT_EQ(error_of("n,cam,x,y,u,v\n"),
            "pts.csv:1: header must be 'n,cam,x,y,z,u,v' or 'n,cam,link,lx,ly,lz,q1,...,qN,u,v', got 'n,cam,x,y,u,v'");
  EXPECT_EQ(error_of("n,cam,x,y,z,u,v\n1,side,1,2,3,4\n"),
            "pts.csv:2: expected 7 fields n,cam,x,y,z,u,v (or n,cam,link,lx,ly,lz,q1..qN,u,v), got 6");
  EXPECT_EQ(error_of("n,cam,x,y,z,u,v\n1,side,1,2,3,4,5,6\n"), "pts.csv:2: expected 7 fields n,cam,x,y,z,u,v, got 8");
  EXPECT_EQ(error_of("n,cam,x,y,z,u,v\n1,side,1,2,3,4,5\n\n2,side,1,2,abc,4,5\n"),
            "pts.csv:4: field 'z' is not a number: 'abc'");
  EXPECT_EQ(error_of("n,cam,x,y,z,u,v\n1,side,1,2,3,nan,5\n"), "pts.csv:2: field 'u' is not finite: 'nan'");
  EXPECT_EQ(error_of("n,cam,x,y,z,u,v\n1,side,1,2,3,4,inf\n"), "pts.csv:2: field 'v' is not finite: 'inf'");
  EXPECT_EQ(error_of("n,cam,x,y,z,u,v\n1.5,side,1,2,3,4,5\n"),
            "pts.csv:2: field 'n' must be an integer point number that fits an int, got '1.5'");
  EXPECT_EQ(error_of("n,cam,x,y,z,u,v\n1,,1,2,3,4,5\n"), "pts.csv:2: field 'cam' is empty");
  // A link row under the base-form header (the header names x,y,z columns).
  EXPECT_EQ(error_of("n,cam,x,y,z,u,v\n1,side,0.1,0.2,0.3,30,40\n2,side,l1,0,0,0,0,0,1,2\n", &arm),
            "pts.csv:3: a point on link 'l1' (link form) under the header 'n,cam,x,y,z,u,v': give the link-form "
            "header 'n,cam,link,lx,ly,lz,q1,...,qN,u,v'");
  EXPECT_EQ(error_of("n,cam,link,lx,ly,lz,q1,q2,u,v\n1,side,l9,0,0,0,0,0,1,2\n", &arm),
            "pts.csv:2: unknown link 'l9' (the robot's links: base, l1, l2)");
  EXPECT_EQ(error_of("n,cam,link,lx,ly,lz,q1,q2,u,v\n1,side,l1,0,0,0,0,1,2\n", &arm),
            "pts.csv:2: point on link 'l1' needs 2 joint angles q1..q2, got 1");
  EXPECT_EQ(error_of("n,cam,link,lx,ly,lz,q1,q2,u,v\n1,side,l1,0,0,0,0,0,0,1,2\n", &arm),
            "pts.csv:2: point on link 'l1' needs 2 joint angles q1..q2, got 3");
  EXPECT_EQ(error_of("n,cam,link,lx,ly,lz,q1,q2,u,v\n1,side,l1,0,0,0,0,nan,1,2\n", &arm),
            "pts.csv:2: field 'q2' is not finite: 'nan'");
  EXPECT_EQ(error_of("n,cam,x,y,z,u,v\n1,side,l1,0,0,0,0,0,1,2\n"),
            "pts.csv:2: point on link 'l1' but no robot model here: arm-link rows are for calibrate; give x,y,z in the "
            "object frame");
}
