#pragma once
// The one bound on the number of joints.

#include <cstddef>

namespace foresight {

/// Joints any part of the system carries (the arm has 7): the fixed-size
/// buffers of the real-time loop, the drive master and the journal, and the
/// protocol's sequence bound (MAX_JOINTS in the IDL, checked equal).
inline constexpr std::size_t kMaxJoints = 16;

}  // namespace foresight
