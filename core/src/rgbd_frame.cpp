#include <fmt/format.h>

#include <avp/core/rgbd_frame.h>

namespace avp {

Status RgbdFrame::Validate() const {
  AVP_RETURN_IF_ERROR(K.Validate().WithContext("RGB-D frame"));
  if (!rgb.SameSizeAs(K.width, K.height)) {
    return InvalidArgumentError(
        fmt::format("RGB-D frame: rgb size {}x{} differs from intrinsics {}x{}", rgb.width(),
                    rgb.height(), K.width, K.height));
  }
  if (!depth_m.SameSizeAs(K.width, K.height)) {
    return InvalidArgumentError(
        fmt::format("RGB-D frame: depth size {}x{} differs from intrinsics {}x{}", depth_m.width(),
                    depth_m.height(), K.width, K.height));
  }
  return Status::Ok();
}

}  // namespace avp
