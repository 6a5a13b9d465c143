#include "discovery_info.h"

#include <algorithm>

namespace avp::ros::dds::internal {

ros::msg::Gid GidOf(const std::array<uint8_t, 16>& guid) {
  ros::msg::Gid gid;
  std::copy(guid.begin(), guid.end(), gid.data.begin());
  return gid;
}

std::vector<uint8_t> EncodeDiscoveryInfo(ros::msg::RosDistro distro,
                                         const std::array<uint8_t, 16>& participant_guid,
                                         const std::string& node_namespace,
                                         const std::string& node_name,
                                         const std::vector<std::array<uint8_t, 16>>& readers,
                                         const std::vector<std::array<uint8_t, 16>>& writers) {
  ros::msg::NodeEntitiesInfo node;
  node.node_namespace = node_namespace;
  node.node_name = node_name;
  for (const auto& guid : readers) node.reader_gid_seq.push_back(GidOf(guid));
  for (const auto& guid : writers) node.writer_gid_seq.push_back(GidOf(guid));
  ros::msg::ParticipantEntitiesInfo info;
  info.gid = GidOf(participant_guid);
  info.node_entities_info_seq.push_back(std::move(node));
  return ros::msg::Encode(info, distro);
}

}  // namespace avp::ros::dds::internal
