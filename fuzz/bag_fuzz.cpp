// Fuzz target: avp replay's bag reader (ros/bag/bag_reader.h BagReader over OpenBag) on any bytes,
// as an MCAP file or, when the bytes begin as SQLite's do, as a rosbag2 .db3 file.
//
// The seeds (fuzz/corpus/bag) are small real bags: a RealSense robot bag (3 frames of 8 x 8 with
// CameraInfo, /tf and /tf_static; ros/bag/test/make_robot_bag), the same with zstd chunks, and
// the same written in Humble's SQLite 3 storage (ros/bag/test/write_humble_db3.py --from-mcap).
// max_file_bytes is 64 MB here, so a chunk or record that claims more is refused rather than
// allocated. Property: no crash, every error a Status, and every view handed out is a whole
// frame: colour, depth and intrinsics of one size, a finite pose.

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <string_view>

#include <avp/core/limits.h>
#include <avp/io/file.h>
#include <avp/ros/bag/bag_reader.h>

#include "fuzz_target.h"

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  (void)avp::io::MaxFileBytes();  // registers the limit
  if (const avp::Status s = avp::SetLimit("max_file_bytes", 64'000'000); !s.ok()) {
    avp::fuzz::Fail("SetLimit: " + s.ToString());
  }
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace avp;
  const std::string_view bytes(reinterpret_cast<const char*>(data), size);
  const bool sqlite = bytes.starts_with("SQLite format 3");
  const auto path = fuzz::ScratchDir() / (sqlite ? "bag.db3" : "bag.mcap");
  fuzz::WriteFile(path, bytes);
  Result<std::unique_ptr<ros::bag::BagReader>> reader = ros::bag::BagReader::Open(path);
  if (!reader.ok()) return 0;
  ros::bag::FrameSelection every;
  every.fps = 0.0;
  if (!(*reader)->SetSelection(every).ok()) fuzz::Fail("SetSelection refused a valid selection");
  for (int i = 0; i < 64; ++i) {
    Result<std::optional<ros::bag::BagView>> view = (*reader)->Next();
    if (!view.ok() || !*view) break;
    const RgbdFrame& f = (*view)->observation.frame;
    if (!f.rgb.SameSizeAs(f.depth_m) || f.K.width != f.rgb.width() ||
        f.K.height != f.rgb.height()) {
      fuzz::Fail("a view whose colour, depth and intrinsics differ in size");
    }
    if (!f.X_WC.translation().allFinite() || !f.X_WC.rotation().allFinite()) {
      fuzz::Fail("a view with a non-finite pose");
    }
  }
  return 0;
}
