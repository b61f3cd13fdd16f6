// One insertion on config/'s simulated plant (sim_insertion::run_insertion:
// control::Controller's insert against sim::Plant) against known answers:
// the 28 mm socket into the 30 mm hole (1 mm radial clearance), the tip 1 cm
// in front of the hole entrance, the insert's defaults (depth 60 mm, spiral
// out to 5 mm).
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cstring>
#include <memory>
#include <optional>

#include "foresight/sim_insertion/sim_insertion.hpp"

namespace {

using namespace foresight;

class SimInsertion : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    world_ = std::make_unique<sim_insertion::World>(sim_insertion::default_files(FORESIGHT_CONFIG_DIR));
  }
  static void TearDownTestSuite() { world_.reset(); }

  /// The insert from the tip at (x, y, z) in the hole entrance frame (the ORU frame).
  static sim_insertion::Outcome insert_from(double x, double y, double z) {
    const std::optional<Eigen::VectorXd> q0 =
        world_->start_joints(world_->base_T_oru * Pose(Eigen::Translation3d(x, y, z)));
    EXPECT_TRUE(q0.has_value());
    if (!q0) return {};
    return sim_insertion::run_insertion(*world_, *q0, sim_insertion::InsertSpec{});
  }

  static std::unique_ptr<sim_insertion::World> world_;
};

std::unique_ptr<sim_insertion::World> SimInsertion::world_;

TEST_F(SimInsertion, CentredStartGoesStraightIn) {
  const sim_insertion::Outcome o = insert_from(0.0, 0.0, -0.01);
  EXPECT_TRUE(o.completed) << o.text.data();
  EXPECT_TRUE(o.in_hole);
  EXPECT_TRUE(o.success());
  EXPECT_FALSE(o.searched);
  EXPECT_FALSE(o.touched_face);
  EXPECT_EQ(o.code, control::Reason::None);
  EXPECT_LT(o.peak_force_n, 1.0);  // never touches: 60 mm at 5 mm/s
  EXPECT_NEAR(o.sim_s, 12.0, 0.1);
  EXPECT_NE(std::strstr(o.text.data(), "depth 60.0 mm reached"), nullptr) << o.text.data();
  EXPECT_GE(world_->plant->truth().tip_depth_m, world_->params.grasp_depth_m);
}

// 3 mm off: the end face lands on the rim, which guides it in like a chamfer
// (the penalty contact): no spiral.
TEST_F(SimInsertion, ThreeMillimetresOffSlidesInOverTheRim) {
  const sim_insertion::Outcome o = insert_from(0.003, 0.0, -0.01);
  EXPECT_TRUE(o.success()) << o.text.data();
  EXPECT_TRUE(o.touched_face);
  EXPECT_FALSE(o.searched);
  EXPECT_GT(o.peak_force_n, 15.0);
  EXPECT_LT(o.peak_force_n, 40.0);
}

// 4.5 mm off: the end face stalls on the face; the spiral finds the hole.
TEST_F(SimInsertion, FourAndAHalfMillimetresOffNeedsTheSpiral) {
  const sim_insertion::Outcome o = insert_from(0.0045, 0.0, -0.01);
  EXPECT_TRUE(o.success()) << o.text.data();
  EXPECT_TRUE(o.searched);
  EXPECT_TRUE(o.touched_face);
  EXPECT_NE(std::strstr(o.text.data(), "search radius 2.0 mm"), nullptr) << o.text.data();
}

// 12 mm off: beyond the spiral's 5 mm (and the clearance and the rim): the
// search ends at its radius, Unreachable; the tip is not in the hole.
TEST_F(SimInsertion, TwelveMillimetresOffFailsAtTheSearchRadius) {
  const sim_insertion::Outcome o = insert_from(0.012, 0.0, -0.01);
  EXPECT_FALSE(o.completed);
  EXPECT_FALSE(o.in_hole);
  EXPECT_FALSE(o.success());
  EXPECT_TRUE(o.searched);
  EXPECT_EQ(o.code, control::Reason::Unreachable);
  EXPECT_STREQ(o.text.data(), "insert: not entered within search radius 5.0 mm");
}

}  // namespace
