#pragma once

// A Cyclone DDS type whose samples are opaque serialised bytes (the CDR encapsulation header
// included), the way rmw_cyclonedds carries ROS messages: avp's own encoder (ros::msg::Encode)
// produces what goes on the wire, and received bytes reach ros::msg::Decode unchanged.
//
// Why not idlc's descriptors with dds_writecdr: Cyclone 0.10.2 has no dds_get_entity_sertype, so
// the sertype of a topic made from a descriptor cannot be reached through the public API, and its
// default serdata validates received bytes against the descriptor, dropping anything it rejects
// before avp can count it. The IDL under ros2/idl/ still documents the layout and is compiled by
// idlc for the tests' independent, descriptor-typed reader and writer.

#include <cstddef>
#include <cstdint>
#include <span>
#include <string>

#include <dds/dds.h>

struct ddsi_sertype;
struct ddsi_serdata;

namespace avp::ros::dds::internal {

/// A new sertype named `dds_type_name` (e.g. "sensor_msgs::msg::dds_::Image_"), keyless, XCDR1.
/// The caller hands it to dds_create_topic_sertype, or frees it with FreeRawSertype on failure.
ddsi_sertype* NewRawSertype(const std::string& dds_type_name);
void FreeRawSertype(ddsi_sertype* sertype);

/// A serdata holding a copy of `bytes` for dds_writecdr (which takes the reference).
ddsi_serdata* NewRawSerdata(const ddsi_sertype* sertype, std::span<const uint8_t> bytes);

/// The serialised bytes of a received serdata (header included, possibly followed by up to three
/// padding bytes: RTPS pads payloads to a multiple of 4).
std::span<const uint8_t> RawSerdataBytes(const ddsi_serdata* serdata);

}  // namespace avp::ros::dds::internal
