// One exception root with two branches: bad input (the CLI exits 2) and a
// failed computation (the CLI exits 1).
#include <gtest/gtest.h>

#include <type_traits>

#include "foresight/common/error.hpp"
#include "foresight/common/plan.hpp"

using namespace foresight;

TEST(Error, TwoDistinctBranchesUnderOneRoot) {
  static_assert(std::is_base_of_v<std::runtime_error, Error>);
  static_assert(std::is_base_of_v<Error, InputError>);
  static_assert(std::is_base_of_v<Error, ComputationError>);
  static_assert(!std::is_base_of_v<InputError, ComputationError>);
  static_assert(!std::is_base_of_v<ComputationError, InputError>);
  static_assert(std::is_base_of_v<ComputationError, PlanError>);
  const InputError at_line("cameras.yaml", 12, "missing key 'f_px'");
  EXPECT_STREQ(at_line.what(), "cameras.yaml:12: missing key 'f_px'");
  EXPECT_EQ(at_line.file(), "cameras.yaml");
  EXPECT_EQ(at_line.line(), 12);
  EXPECT_STREQ(InputError("cameras.yaml", "cannot open").what(), "cameras.yaml: cannot open");
  const InputError no_file("5 points; the linear calibration needs at least 6");
  EXPECT_STREQ(no_file.what(), "5 points; the linear calibration needs at least 6");
  EXPECT_TRUE(no_file.file().empty());
  EXPECT_EQ(no_file.line(), 0);
  // Caught by the root, never mistaken for the other branch.
  try {
    throw PlanError("goal 'hole_entrance': IK did not converge");
  } catch (const InputError&) {
    ADD_FAILURE() << "a computation error caught as bad input";
  } catch (const Error& e) {
    EXPECT_STREQ(e.what(), "goal 'hole_entrance': IK did not converge");
  }
}
