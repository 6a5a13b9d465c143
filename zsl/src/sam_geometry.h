#pragma once
// Internal to avp_zsl (zsl/src, not installed): used by its sources and unit tests.

#include <array>
#include <span>
#include <vector>

#include <avp/core/image.h>
#include <avp/core/segmentation.h>

namespace avp::zsl {

/// The image and prompt geometry of an EfficientViT-SAM run (design/zero-shot-models.md §4.3).
/// Two frames, both "long side resized to a size L, top-left aligned, zero-padded to L x L", with
/// sizes int(x·scale + 0.5) as the reference `get_preprocess_shape`:
///  - the encoder input, L = encoder_size S (512 for L0–L2, 1024 for XL0/XL1);
///  - the prompt/mask frame, L = prompt_frame (1024 for every model, including the 512-input
///    ones): box prompts are given in it and the decoder's masks cover it.
struct SamTransform {
  int src_w = 0;               ///< source image width, pixels
  int src_h = 0;               ///< source image height, pixels
  int encoder_size = 0;        ///< S: the encoder input is [3, S, S]
  double encoder_scale = 1.0;  ///< S / max(src_w, src_h)
  int encoder_resized_w = 0;   ///< int(src_w·encoder_scale + 0.5), at least 1
  int encoder_resized_h = 0;   ///< int(src_h·encoder_scale + 0.5), at least 1
  int prompt_frame = 1024;     ///< the prompt/mask frame's long side
  double prompt_scale = 1.0;   ///< prompt_frame / max(src_w, src_h)
  int prompt_resized_w = 0;    ///< int(src_w·prompt_scale + 0.5), at least 1
  int prompt_resized_h = 0;    ///< int(src_h·prompt_scale + 0.5), at least 1

  /// @throws avp::Error unless all sizes are > 0.
  static SamTransform Compute(int src_w, int src_h, int encoder_size, int prompt_frame = 1024);
};

/// The labels of a box prompt's two points: 2 = top-left corner, 3 = bottom-right corner.
inline constexpr std::array<float, 2> kSamBoxPromptLabels = {2.f, 3.f};

/// The encoder input for `rgb`: CHW float32 [3, S, S], R, G, B order (element (c, y, x) at
/// (c·S + y)·S + x). The image is resized to encoder_resized_w x encoder_resized_h (bilinear,
/// cv::INTER_LINEAR on the 8-bit image; no resize when the long side already is S), normalised
/// per channel as (v − mean) / std with mean (123.675, 116.28, 103.53) and std (58.395, 57.12,
/// 57.375), and zero-padded at the bottom/right.
/// Note: the Python reference resizes with torchvision `resize`, which antialiases when it
/// shrinks; INTER_LINEAR does not, so shrunk images differ slightly from the reference.
/// @throws avp::Error unless rgb is t.src_w x t.src_h.
std::vector<float> SamEncoderTensor(const ImageRgb8& rgb, const SamTransform& t);

/// A source-pixel box as the decoder's `point_coords` for one box, {x0, y0, x1, y1} in the prompt
/// frame (labels kSamBoxPromptLabels). Each axis is scaled by prompt_resized / src, as the
/// reference `apply_coords` (new_w / old_w, new_h / old_h): the same as prompt_scale up to
/// rounding of the resized size, and exactly the inverse of the mask chain's final resize. The
/// graph itself adds 0.5 and divides by 1024.
std::array<float, 4> SamBoxPromptCoords(const PixelBox& box, const SamTransform& t);

/// The decoder's low-res mask logits (`masks` [1, 1, low_res, low_res], row-major) as a binary
/// mask of the source image: bilinear upsampling low_res → prompt_frame x prompt_frame
/// (align_corners=False, i.e. cv::INTER_LINEAR on float), crop to prompt_resized_w x
/// prompt_resized_h, bilinear resize to src_w x src_h, then 255 where the logit > threshold,
/// else 0.
/// @throws avp::Error unless low_res > 0 and logits.size() == low_res².
MaskImage SamLowResLogitsToMask(std::span<const float> logits, int low_res, const SamTransform& t,
                                float threshold = 0.f);

}  // namespace avp::zsl
