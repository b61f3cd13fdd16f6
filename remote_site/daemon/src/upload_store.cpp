#include "foresight/daemon/upload_store.hpp"

namespace foresight::daemon {

const UploadStore::Committed* UploadStore::committed(std::uint64_t id) const {
  const auto it = committed_.find(id);
  return it == committed_.end() ? nullptr : &it->second;
}

const std::string* UploadStore::refused(std::uint64_t id) const {
  const auto it = refused_.find(id);
  return it == refused_.end() ? nullptr : &it->second;
}

void UploadStore::commit(std::uint64_t id, std::shared_ptr<const Trajectory> trajectory, const TrajectoryHash& hash,
                         std::uint64_t running) {
  if (!committed_.count(id)) order_.push_back(id);
  committed_[id] = Committed{std::move(trajectory), hash};
  while (order_.size() > kUploadsKept) {
    const std::uint64_t old = order_.front();
    order_.pop_front();
    if (running != 0 && old == running) {
      order_.push_back(old);  // still running: keep it
      break;
    }
    committed_.erase(old);
  }
}

void UploadStore::refuse(std::uint64_t id, const std::string& why) {
  committed_.erase(id);
  if (!refused_.count(id)) refused_order_.push_back(id);
  refused_[id] = why;
  while (refused_order_.size() > kUploadsKept) {
    refused_.erase(refused_order_.front());
    refused_order_.pop_front();
  }
}

}  // namespace foresight::daemon
