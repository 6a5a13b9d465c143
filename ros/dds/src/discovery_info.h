#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include <avp/ros/msg/messages.h>

namespace avp::ros::dds::internal {

/// The ros_discovery_info sample (rmw_dds_common/ParticipantEntitiesInfo) announcing one node of a
/// participant with its readers and writers; GIDs are the 16-byte DDS GUIDs, zero-padded to 24
/// bytes on the wire for Humble.
std::vector<uint8_t> EncodeDiscoveryInfo(ros::msg::RosDistro distro,
                                         const std::array<uint8_t, 16>& participant_guid,
                                         const std::string& node_namespace,
                                         const std::string& node_name,
                                         const std::vector<std::array<uint8_t, 16>>& readers,
                                         const std::vector<std::array<uint8_t, 16>>& writers);

ros::msg::Gid GidOf(const std::array<uint8_t, 16>& guid);

}  // namespace avp::ros::dds::internal
