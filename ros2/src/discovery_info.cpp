#include "discovery_info.h"

#include <algorithm>

namespace avp::ros2::internal {

rosmsg::Gid GidOf(const std::array<uint8_t, 16>& guid) {
  rosmsg::Gid gid;
  std::copy(guid.begin(), guid.end(), gid.data.begin());
  return gid;
}

std::vector<uint8_t> EncodeDiscoveryInfo(rosmsg::RosDistro distro,
                                         const std::array<uint8_t, 16>& participant_guid,
                                         const std::string& node_namespace,
                                         const std::string& node_name,
                                         const std::vector<std::array<uint8_t, 16>>& readers,
                                         const std::vector<std::array<uint8_t, 16>>& writers) {
  rosmsg::NodeEntitiesInfo node;
  node.node_namespace = node_namespace;
  node.node_name = node_name;
  for (const auto& guid : readers) node.reader_gid_seq.push_back(GidOf(guid));
  for (const auto& guid : writers) node.writer_gid_seq.push_back(GidOf(guid));
  rosmsg::ParticipantEntitiesInfo info;
  info.gid = GidOf(participant_guid);
  info.node_entities_info_seq.push_back(std::move(node));
  return rosmsg::Encode(info, distro);
}

}  // namespace avp::ros2::internal
