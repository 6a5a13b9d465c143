#pragma once

// sensor_msgs/Image and sensor_msgs/CameraInfo to and from avp's images and intrinsics: the one
// reading that `avp live` (ros::live::Ros2RgbdSource) and `avp replay` (ros::bag::ReadBag) share,
// so that a camera one accepts the other accepts too, and the one writing that the recorder and
// `avp sim ros2` share (docs/ros2.md "Images avp accepts").
//
// Colour: rgb8, bgr8, rgba8, bgra8 (alpha dropped), mono8 (grey copied to the three channels).
// Depth: 16UC1 (or its alias mono16) in millimetres, 32FC1 in metres; either byte order.
// The depth rule: a pixel is a depth (metres, > 0) or 0 = no return. 16UC1's 0 is no return;
// a 32FC1 NaN, +inf, -inf or 0 is no return (REP 118's "no return", "too far", "too close",
// RealSense's 0); a finite negative or subnormal 32FC1 value is no depth any camera sends: the
// image is refused, naming the pixel and the value. A positive 32FC1 depth is kept bit for bit.

#include <cstdint>
#include <string>
#include <string_view>

#include <avp/core/camera.h>
#include <avp/core/image.h>
#include <avp/core/simulator_labels.h>
#include <avp/core/status.h>
#include <avp/ros/msg/messages.h>

namespace avp::ros::msg {

/// The largest image side accepted (either way), pixels.
inline constexpr uint32_t kMaxImageSide = 16384;
/// The encodings accepted, as the errors list them.
inline constexpr std::string_view kColorEncodings = "rgb8, bgr8, rgba8, bgra8, mono8";
inline constexpr std::string_view kDepthEncodings = "16UC1 in millimetres, 32FC1 in metres";

/// An image's size (1..kMaxImageSide), step (at least a row of `bytes_per_pixel` pixels) and data
/// length (step x height). InvalidArgument naming `topic` and the values.
Status CheckImageLayout(const Image& msg, std::string_view topic, int bytes_per_pixel);

/// A colour image's encoding and layout (the check on arrival: no pixel is read).
Status CheckColorImage(const Image& msg, std::string_view topic);
/// A depth image's encoding and layout, and for 32FC1 every value by the depth rule (above).
Status CheckDepthImage(const Image& msg, std::string_view topic);

/// The colour image as rgb. InvalidArgument naming `topic` and the value: an encoding not
/// accepted (listing those that are), a size, step or data length that does not fit.
Result<ImageRgb8> ColorFromImage(const Image& msg, std::string_view topic);
/// The depth image in metres by the depth rule (above). InvalidArgument as ColorFromImage, and
/// for a negative or subnormal 32FC1 value (naming the pixel, the value and the stamp).
Result<DepthImage> DepthFromImage(const Image& msg, std::string_view topic);
/// Simulator instance ids (16UC1 / mono16) and classes (mono8 / 8UC1), either byte order.
Result<InstanceImage> InstanceIdsFromImage(const Image& msg, std::string_view topic);
Result<ClassImage> ClassIdsFromImage(const Image& msg, std::string_view topic);
/// Both label images, which must be width x height (the colour image's size); fruits empty.
Result<SimulatorLabels> LabelsFromImages(const Image& instance, const Image& classes, int width,
                                         int height, std::string_view prefix);

/// rgb8, step 3·width.
Image ToColorImage(const ImageRgb8& rgb, const Header& header);
/// Depth as 32FC1 metres (little-endian floats, bit for bit; step 4·width) or as 16UC1
/// millimetres (rounded, clamped to 65535; no return, non-finite or <= 0, as 0; step 2·width).
enum class DepthEncoding { k32FC1, k16UC1 };
Image ToDepthImage(const DepthImage& depth_m, const Header& header,
                   DepthEncoding encoding = DepthEncoding::k32FC1);
/// Instance ids as a little-endian uint16 image ("16UC1" or "mono16"), step 2·width.
Image ToInstanceIdImage(const InstanceImage& ids, std::string_view encoding, const Header& header);
/// Classes as mono8, step width.
Image ToClassIdImage(const ClassImage& classes, const Header& header);

/// K as CameraInfo: plumb_bob with zero distortion, R = I, P = [K | 0]. The one builder of the
/// recorder and `avp sim ros2`.
CameraInfo ToCameraInfo(const CameraIntrinsics& K, const Header& header);
/// Intrinsics from a CameraInfo (its size, K's fx, fy, cx, cy) with the given depth range (a
/// CameraInfo carries none). InvalidArgument naming the frame and the values: a size outside
/// 1..kMaxImageSide, intrinsics that do not validate, binning or a region of interest.
/// Reads K only: distortion_model, d, R and P are the lens model's (lens.h:
/// LensModelFromCameraInfo, and Rectifier to remap raw images to the rectified camera).
Result<CameraIntrinsics> FromCameraInfo(const CameraInfo& info, double min_depth_m,
                                        double max_depth_m);

}  // namespace avp::ros::msg
