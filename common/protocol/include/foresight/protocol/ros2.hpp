#pragma once
// ROS 2 visibility (optional): sensor_msgs/JointState and
// geometry_msgs/WrenchStamped as ROS 2 puts them on DDS (rosidl's module
// names and trailing underscores, topics prefixed "rt/"), generated from
// idl/ros2_msgs.idl. Writer<ros2::JointState> w(participant) publishes on
// rt/joint_states with ROS 2's default QoS (reliable, keep-last 10,
// volatile), so `ros2 topic echo /joint_states`, RViz and Foxglove read it
// with no bridge.
//
// Not real-time. set_ros2_names() allocates (once per joint count).

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "foresight/protocol/dds.hpp"
#include "ros2_msgs.h"

namespace foresight::protocol {

namespace ros2 {
using JointState = sensor_msgs_msg_dds__JointState_;
using WrenchStamped = geometry_msgs_msg_dds__WrenchStamped_;
inline constexpr const char* kJointStatesTopic = "rt/joint_states";
inline constexpr const char* kWrenchTopic = "rt/wrench";
/// ROS 2's default QoS (rmw_qos_profile_default): reliable, keep-last 10, volatile.
Qos default_qos();

/// Fills a builtin_interfaces/Time from protocol nanoseconds.
void set_stamp(builtin_interfaces_msg_dds__Time_& stamp, std::int64_t stamp_ns) noexcept;
/// Sets header.frame_id (allocates with dds_string_dup; freed by Sample).
void set_frame_id(std_msgs_msg_dds__Header_& header, const std::string& frame_id);
/// Sets the joint names, only when their count changed (allocates then).
void set_names(JointState& state, const std::vector<std::string>& names);
}  // namespace ros2

template <>
struct MessageTraits<ros2::JointState> {
  static const dds_topic_descriptor_t* descriptor() noexcept { return &sensor_msgs_msg_dds__JointState__desc; }
  static constexpr const char* type_name = "sensor_msgs::msg::dds_::JointState_";
  static constexpr const char* topic = ros2::kJointStatesTopic;
  static Qos qos() { return ros2::default_qos(); }
};

template <>
struct MessageTraits<ros2::WrenchStamped> {
  static const dds_topic_descriptor_t* descriptor() noexcept {
    return &geometry_msgs_msg_dds__WrenchStamped__desc;
  }
  static constexpr const char* type_name = "geometry_msgs::msg::dds_::WrenchStamped_";
  static constexpr const char* topic = ros2::kWrenchTopic;
  static Qos qos() { return ros2::default_qos(); }
};

}  // namespace foresight::protocol
