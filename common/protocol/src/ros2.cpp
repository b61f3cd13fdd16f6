#include "foresight/protocol/ros2.hpp"

namespace foresight::protocol::ros2 {

Qos default_qos() { return std::move(Qos().reliable(0.1).keep_last(10).volatile_durability()); }

void set_stamp(builtin_interfaces_msg_dds__Time_& stamp, std::int64_t stamp_ns) noexcept {
  std::int64_t sec = stamp_ns / 1'000'000'000;
  std::int64_t nsec = stamp_ns % 1'000'000'000;
  if (nsec < 0) {
    nsec += 1'000'000'000;
    --sec;
  }
  stamp.sec = static_cast<std::int32_t>(sec);
  stamp.nanosec = static_cast<std::uint32_t>(nsec);
}

void set_frame_id(std_msgs_msg_dds__Header_& header, const std::string& frame_id) {
  if (header.frame_id != nullptr && frame_id == header.frame_id) return;
  dds_free(header.frame_id);
  header.frame_id = dds_string_dup(frame_id.c_str());
}

void set_names(JointState& state, const std::vector<std::string>& names) {
  auto& seq = state.name;
  bool same = seq._length == names.size() && seq._buffer != nullptr;
  for (std::size_t i = 0; same && i < names.size(); ++i) same = names[i] == seq._buffer[i];
  if (same) return;
  if (seq._release && seq._buffer != nullptr) {
    for (std::uint32_t i = 0; i < seq._length; ++i) dds_free(seq._buffer[i]);
    dds_free(seq._buffer);
  }
  const auto n = static_cast<std::uint32_t>(names.size());
  seq._buffer = n > 0 ? static_cast<char**>(dds_alloc(n * sizeof(char*))) : nullptr;
  for (std::uint32_t i = 0; i < n; ++i) seq._buffer[i] = dds_string_dup(names[i].c_str());
  seq._length = seq._maximum = n;
  seq._release = n > 0;
}

}  // namespace foresight::protocol::ros2
