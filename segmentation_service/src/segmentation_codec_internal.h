#pragma once

// Private to segmentation_service/: what the segmentation codec's translation units share. The
// codec is split by concept:
//   segmentation_codec.cpp           metadata (the tensors' names and types) and these helpers
//   segmentation_budget.cpp          a request's size against the server's budget, before decoding
//   segmentation_request_codec.cpp   SegmentationRequest <-> InferRequest
//   segmentation_response_codec.cpp  Segmentation <-> InferResponse
//   compact_masks.cpp                the masks as RLE or one instance-id image (mask_format)
// docs/segmentation-service.md describes the protocol.

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include <avp/core/image.h>
#include <avp/core/segmentation.h>
#include <avp/core/status.h>
#include <avp/segmentation_service/segmentation_codec.h>
#include <avp/segmentation_service/tensor.h>

namespace avp::segmentation_service::codec {

/// Largest image side accepted from the wire.
inline constexpr int64_t kMaxSide = 1 << 15;

inline constexpr const char* kBothImages =
    "inputs 'rgb' and 'image' are both given: send the colour image once, as 'rgb' UINT8 "
    "[H, W, 3] or as 'image' BYTES [1] (PNG or JPEG)";

/// The specs' names joined by ", ".
std::string JoinNames(const std::vector<TensorSpec>& specs);

/// The tensor has `datatype` and `shape` (-1 = any size in that dimension); InvalidArgument names
/// the `role` ("input", "output"), the expectation ("FP32 [H, W] = [120, 160]") and what came.
Status ExpectTensor(const Tensor& t, std::string_view role, DataType datatype,
                    const std::vector<int64_t>& shape, std::string_view symbolic,
                    std::string_view meaning = "");

/// The little-endian 32-bit value at `pos` of `d`.
uint32_t ReadU32LeAt(std::string_view d, size_t pos);

// --- compact_masks.cpp --------------------------------------------------------------------------

/// The outputs of `format` (not dense) for `segmentation`'s masks: 'mask_rle' or 'mask_ids', then
/// 'image_size' and 'mask_on' (each mask's foreground value).
std::vector<Tensor> CompactMaskOutputs(const Segmentation& segmentation, MaskFormat format);

/// Instance `i`'s mask from its RLE bytes, of foreground value `on`.
Result<MaskImage> MaskFromRle(const std::string& bytes, size_t i, int width, int height,
                              uint8_t on);

/// The masks of `instances` (each already width x height) filled from 'mask_ids', each pixel of
/// id k set to mask_on[k - 1].
Status FillMasksFromIds(const Tensor& ids_t, const std::vector<uint8_t>& mask_on, int width,
                        std::vector<InstanceMask>& instances);

}  // namespace avp::segmentation_service::codec
