#pragma once
// The go/no-go's settings: the `contact_check:` section of ground.yaml.
//
//   contact_check:
//     min_p_success: 0.99      # below it the verdict is no_go, in (0, 1)
//     socket_diameter_m: 0.028 # the tool's socket (the hole: the object model)
//     required_depth_m: 0.05   # how deep the step after the insert needs the tip
//     lead_in_m: 0.0015        # the rim's lead-in beyond the clearance (InsertGeometry)
//     encoder_sigma_rad: 2.0e-5  # each joint's position, 1 sigma
//     arm_link_sigma_m: 0.002  # each link length, 1 sigma, when the object pose does not say
//
// Every key is optional (these defaults). Set-up code.

#include <string>

#include "foresight/common/insert_capture.hpp"
#include "foresight/contact_check/insert_check.hpp"
#include "foresight/contact_check/tip_error.hpp"

namespace foresight::contact_check {

struct ContactCheckConfig {
  double min_p_success = kDefaultMinPSuccess;
  double socket_diameter_m = 0.028;
  double required_depth_m = 0.05;
  double lead_in_m = InsertGeometry{}.lead_in_m;
  double encoder_sigma_rad = 2.0e-5;
  double arm_link_sigma_m = 0.002;
};

/// The section from `ground_yaml` (defaults when the file or the section is
/// absent). InputError "<file>:<line>: contact_check.<key>: ..." for an
/// unknown key, a non-number, or a value out of range (min_p_success in
/// (0, 1); sizes in (0, 1] m; sigmas in [0, 0.05]).
ContactCheckConfig load_contact_check_config(const std::string& ground_yaml);

}  // namespace foresight::contact_check
