// The compact forms of a segmentation's masks (request parameter mask_format): 'mask_rle' (each
// mask as COCO run lengths, UINT32 little-endian) or 'mask_ids' (one UINT16 image, the earliest
// instance keeping a pixel), with 'image_size' (H, W) and 'mask_on' (each mask's foreground
// value, so that the client rebuilds the very bytes).

#include <algorithm>
#include <array>
#include <cstdint>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include <fmt/format.h>

#include <avp/io/mask_codec.h>
#include <avp/segmentation_service/segmentation_codec.h>

#include "segmentation_codec_internal.h"

namespace avp::segmentation_service::codec {

namespace {

/// 'mask_rle' BYTES [N]: each mask's run lengths.
Tensor RleMasks(const Segmentation& segmentation) {
  const size_t n = segmentation.instances.size();
  std::vector<std::string> runs(n);
  for (size_t i = 0; i < n; ++i) {
    const std::vector<uint32_t> counts = io::MaskToRle(segmentation.instances[i].mask);
    runs[i].resize(counts.size() * sizeof(uint32_t));
    internal::CopyLittleEndian(runs[i].data(), counts.data(), counts.size(), sizeof(uint32_t));
  }
  return MakeBytesTensor(std::string(names::kMaskRle), runs);
}

/// 'mask_ids' UINT16 [H, W]: the earliest instance (the best-scoring, as segmenters order them)
/// keeps a pixel.
Tensor InstanceIdMasks(const Segmentation& segmentation) {
  const int w = segmentation.width;
  const int h = segmentation.height;
  const size_t pixels = static_cast<size_t>(w) * static_cast<size_t>(h);
  std::vector<uint16_t> ids(pixels, 0);
  for (size_t i = segmentation.instances.size(); i-- > 0;) {
    const auto& data = segmentation.instances[i].mask.data();
    for (size_t p = 0; p < pixels; ++p) {
      if (data[p] != 0) ids[p] = static_cast<uint16_t>(i + 1);
    }
  }
  return MakeTensor<uint16_t>(std::string(names::kMaskIds), DataType::kUint16, {h, w},
                              std::span<const uint16_t>(ids));
}

/// 'mask_on' UINT8 [N]: each mask's foreground value (masks are "nonzero = instance": 1 from the
/// oracle, 255 from the networks; 255 for an empty mask).
Tensor MaskOnValues(const Segmentation& segmentation) {
  const size_t n = segmentation.instances.size();
  std::vector<uint8_t> on(n, 255);
  for (size_t i = 0; i < n; ++i) {
    const auto& data = segmentation.instances[i].mask.data();
    const auto it = std::find_if(data.begin(), data.end(), [](uint8_t v) { return v != 0; });
    if (it != data.end()) on[i] = *it;
  }
  return MakeTensor<uint8_t>(std::string(names::kMaskOn), DataType::kUint8,
                             {static_cast<int64_t>(n)}, std::span<const uint8_t>(on));
}

}  // namespace

std::vector<Tensor> CompactMaskOutputs(const Segmentation& segmentation, MaskFormat format) {
  std::vector<Tensor> outputs;
  outputs.push_back(format == MaskFormat::kRle ? RleMasks(segmentation)
                                               : InstanceIdMasks(segmentation));
  const std::array<int32_t, 2> size = {segmentation.height, segmentation.width};
  outputs.push_back(MakeTensor<int32_t>(std::string(names::kImageSize), DataType::kInt32, {2},
                                        std::span<const int32_t>(size)));
  outputs.push_back(MaskOnValues(segmentation));
  return outputs;
}

Result<MaskImage> MaskFromRle(const std::string& bytes, size_t i, int width, int height,
                              uint8_t on) {
  if (bytes.size() % sizeof(uint32_t) != 0) {
    return InvalidArgumentError(fmt::format(
        "output 'mask_rle'[{}] has {} bytes: not whole UINT32 run lengths", i, bytes.size()));
  }
  std::vector<uint32_t> counts(bytes.size() / sizeof(uint32_t));
  internal::CopyLittleEndian(counts.data(), bytes.data(), counts.size(), sizeof(uint32_t));
  Result<MaskImage> mask = io::RleToMask(counts, width, height);
  if (!mask.ok()) {
    return InvalidArgumentError(
        fmt::format("output 'mask_rle'[{}]: {}", i, mask.status().message()));
  }
  if (on != 255) {
    for (uint8_t& v : mask->data()) v = v != 0 ? on : 0;
  }
  return std::move(*mask);
}

Status FillMasksFromIds(const Tensor& ids_t, const std::vector<uint8_t>& mask_on, int width,
                        std::vector<InstanceMask>& instances) {
  AVP_ASSIGN_OR_RETURN(const std::vector<uint16_t> ids, ReadValues<uint16_t>(ids_t));
  const size_t w = static_cast<size_t>(width);
  for (size_t p = 0; p < ids.size(); ++p) {
    if (ids[p] == 0) continue;
    if (ids[p] > instances.size()) {
      return InvalidArgumentError(
          fmt::format("output 'mask_ids' holds id {} at pixel ({}, {}), but there are {} instances",
                      ids[p], p % w, p / w, instances.size()));
    }
    instances[ids[p] - 1].mask.data()[p] = mask_on[ids[p] - 1];
  }
  return Status::Ok();
}

}  // namespace avp::segmentation_service::codec
