// The ywes and lsam segmenters on real exports (opt-in, design §8.3): with AVP_ZSL_MODEL_DIR set to
// a complete model directory (docs/zero-shot-models.md) and AVP_ZSL_TEST_IMAGE to a photo that
// shows what AVP_ZSL_TEST_PROMPT names (default "tomato"), each backend must find at least one
// instance with a sane mask. Without them every test skips, saying what to set.
#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>

#include <fmt/format.h>
#include <gtest/gtest.h>

#include <avp/core/camera.h>
#include <avp/core/rgbd_frame.h>
#include <avp/io/image_codec.h>
#include <avp/zsl/lsam_segmenter.h>
#include <avp/zsl/ywes_segmenter.h>

#include "manifest.h"

namespace avp::zsl {
namespace {

namespace fs = std::filesystem;

std::optional<std::string> Env(const char* name) {
  const char* v = std::getenv(name);
  if (v == nullptr || *v == '\0') return std::nullopt;
  return std::string(v);
}

/// The model directory and the test image, or a reason to skip.
struct RealSetup {
  fs::path model_dir;
  ImageRgb8 image;
  std::string prompt;
  std::string skip;
};

RealSetup LoadRealSetup(const char* backend) {
  RealSetup s;
  const std::optional<fs::path> dir = ModelDirFromEnvironment();
  if (!dir) {
    s.skip =
        "AVP_ZSL_MODEL_DIR is not set: set it to a model directory with a manifest.json "
        "(docs/zero-shot-models.md, \"Model directory and manifest\") to run the real models";
    return s;
  }
  s.model_dir = *dir;
  Result<Manifest> manifest = ReadManifest(*dir);
  if (!manifest.ok()) {
    s.skip = fmt::format("{}: {}", dir->string(), manifest.status().ToString());
    return s;
  }
  Result<std::vector<std::string>> roles = BackendRoles(backend, *manifest);
  if (!roles.ok()) {
    s.skip = roles.status().ToString();
    return s;
  }
  for (const std::string& role : *roles) {
    const ModelEntry* entry = manifest->Find(role);
    if (entry == nullptr || !fs::exists(entry->file.path)) {
      s.skip = fmt::format("{} has no complete {} set (role '{}' is missing)", dir->string(),
                           backend, role);
      return s;
    }
  }
  const std::optional<std::string> image = Env("AVP_ZSL_TEST_IMAGE");
  if (!image) {
    s.skip =
        "AVP_ZSL_TEST_IMAGE is not set: set it to a JPEG/PNG showing the prompt's object "
        "(AVP_ZSL_TEST_PROMPT, default \"tomato\")";
    return s;
  }
  Result<ImageRgb8> rgb = io::ReadImageFile(*image);
  if (!rgb.ok()) {
    s.skip = rgb.status().ToString();
    return s;
  }
  s.image = std::move(rgb).value();
  s.prompt = Env("AVP_ZSL_TEST_PROMPT").value_or("tomato");
  return s;
}

RuntimeOptions SessionFromEnvironment() {
  RuntimeOptions o;
  Result<Device> device = DeviceFromEnvironment();
  o.device = device.ok() ? *device : Device::kAuto;
  return o;
}

/// Sanity of a real result: valid, at least one instance, each mask non-empty and at least 80 %
/// inside its box grown by 10 %, scores in range, the stages timed.
void ExpectSane(const Segmentation& seg, int w, int h) {
  ASSERT_TRUE(seg.ValidateFor(w, h).ok()) << seg.ValidateFor(w, h).ToString();
  ASSERT_GE(seg.instances.size(), 1u) << "no instance found";
  for (const InstanceMask& m : seg.instances) {
    ASSERT_TRUE(m.box.has_value());
    const PixelBox& b = *m.box;
    EXPECT_TRUE(b.x0 >= 0 && b.y0 >= 0 && b.x1 <= w && b.y1 <= h && b.x1 > b.x0 && b.y1 > b.y0);
    const float gx = 0.1f * (b.x1 - b.x0), gy = 0.1f * (b.y1 - b.y0);
    size_t on = 0, inside = 0;
    for (int v = 0; v < h; ++v) {
      for (int u = 0; u < w; ++u) {
        if (m.mask.at(u, v) == 0) continue;
        ++on;
        inside += u >= b.x0 - gx && u < b.x1 + gx && v >= b.y0 - gy && v < b.y1 + gy;
      }
    }
    EXPECT_GT(on, 0u);
    EXPECT_GE(static_cast<double>(inside), 0.8 * static_cast<double>(on)) << m.label;
    EXPECT_GT(m.mask_score, -1.f);
    std::fprintf(stderr, "  %s %.3f (mask %.3f) box (%.0f, %.0f)-(%.0f, %.0f), %zu px\n",
                 m.label.c_str(), m.confidence, m.mask_score, b.x0, b.y0, b.x1, b.y1, on);
  }
  EXPECT_FALSE(seg.timings.empty());
  for (const StageTiming& t : seg.timings)
    std::fprintf(stderr, "  %s %.1f ms\n", t.stage.c_str(), t.ms);
}

RgbdFrame FrameOf(const ImageRgb8& image) {
  RgbdFrame f;
  f.rgb = image;
  f.depth_m = DepthImage(image.width(), image.height(), 0.f);
  f.K = CameraIntrinsics::FromHorizontalFov(image.width(), image.height(), 60.0);
  return f;
}

TEST(RealModelsTest, YwesSegmentsTheTestImage) {
  const RealSetup s = LoadRealSetup(kBackendYwes);
  if (!s.skip.empty()) GTEST_SKIP() << s.skip;
  YwesOptions o;
  o.session = SessionFromEnvironment();
  Result<std::unique_ptr<YwesSegmenter>> seg = YwesSegmenter::Create(s.model_dir, o);
  ASSERT_TRUE(seg.ok()) << seg.status().ToString();
  const RgbdFrame frame = FrameOf(s.image);
  segmentation::SegmentationRequest r;
  r.frame = &frame;
  r.prompt = s.prompt;
  Result<Segmentation> out = (*seg)->Segment(r);
  ASSERT_TRUE(out.ok()) << out.status().ToString();
  ExpectSane(*out, frame.rgb.width(), frame.rgb.height());
}

TEST(RealModelsTest, LsamSegmentsTheTestImage) {
  const RealSetup s = LoadRealSetup(kBackendLsam);
  if (!s.skip.empty()) GTEST_SKIP() << s.skip;
  LsamOptions o;
  o.session = SessionFromEnvironment();
  Result<std::unique_ptr<LsamSegmenter>> seg = LsamSegmenter::Create(s.model_dir, o);
  ASSERT_TRUE(seg.ok()) << seg.status().ToString();
  const RgbdFrame frame = FrameOf(s.image);
  segmentation::SegmentationRequest r;
  r.frame = &frame;
  r.prompt = s.prompt;
  Result<Segmentation> out = (*seg)->Segment(r);
  ASSERT_TRUE(out.ok()) << out.status().ToString();
  ExpectSane(*out, frame.rgb.width(), frame.rgb.height());
}

}  // namespace
}  // namespace avp::zsl
