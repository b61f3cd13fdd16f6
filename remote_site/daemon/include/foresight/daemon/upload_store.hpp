#pragma once
// The committed uploads a RUN may name, and why recent ones were refused.
//
// The last kUploadsKept committed trajectories are kept by id with their
// hash (the one running is kept whatever its age); the reasons of the last
// kUploadsKept refused ones are kept so a RUN waiting for one fails with it.

#include <cstdint>
#include <deque>
#include <map>
#include <memory>
#include <string>

#include "foresight/common/trajectory.hpp"

namespace foresight::daemon {

class UploadStore {
 public:
  static constexpr std::size_t kUploadsKept = 8;

  struct Committed {
    std::shared_ptr<const Trajectory> trajectory;
    TrajectoryHash hash{};
  };
  /// The committed upload `id`; null when there is none.
  const Committed* committed(std::uint64_t id) const;
  /// Why upload `id` was refused; null when it was not (or long ago).
  const std::string* refused(std::uint64_t id) const;

  /// `running`: the id of the trajectory the arm runs now (0: none), never evicted.
  void commit(std::uint64_t id, std::shared_ptr<const Trajectory> trajectory, const TrajectoryHash& hash,
              std::uint64_t running);
  /// Rejected or discarded: forgotten as committed, remembered as refused.
  void refuse(std::uint64_t id, const std::string& why);

 private:
  std::map<std::uint64_t, Committed> committed_;
  std::deque<std::uint64_t> order_;
  std::map<std::uint64_t, std::string> refused_;
  std::deque<std::uint64_t> refused_order_;
};

}  // namespace foresight::daemon
