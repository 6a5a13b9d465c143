#pragma once

// A small rendered RGB-D frame with simulator labels, and helpers to compare segmentations, for
// the interop tests.

#include <cstdint>
#include <string>

#include <gtest/gtest.h>

#include <avp/core/camera.h>
#include <avp/core/rgbd_frame.h>
#include <avp/core/segmentation.h>
#include <avp/segmentation/segmenter.h>
#include <avp/sim/rgbd_renderer.h>
#include <avp/sim/scenario.h>

namespace avp::segmentation_service::test {

/// The default scenario's start view at a quarter of the D435's resolution (160 x 120).
struct TestFrame {
  RgbdFrame frame;
  SimulatorLabels labels;

  explicit TestFrame(uint64_t scene_seed = 3, double scale = 0.25) {
    Result<sim::Scene> scene = sim::MakeScenario(sim::DefaultScenarioName(), scene_seed);
    EXPECT_TRUE(scene.ok()) << scene.status().ToString();
    const sim::RgbdRenderer renderer(*scene);
    sim::RenderedFrame r = renderer.Render(CameraIntrinsics::RealSenseD435().Scaled(scale),
                                           scene->X_WC_start, /*stamp_ns=*/123456789);
    frame = std::move(r.rgbd);
    frame.frame_id = "test_camera";
    labels.instance_ids = std::move(r.instance_ids);
    labels.class_ids = std::move(r.class_ids);
    for (const sim::FruitTruth& f : scene->Fruits()) {
      labels.fruits.push_back({f.instance_id, f.center_W, f.mean_radius_m()});
    }
  }

  segmentation::SegmentationRequest Request(uint64_t frame_index = 0, std::string prompt = "tomato",
                                            float score_threshold = 0.0f) const {
    segmentation::SegmentationRequest r;
    r.frame = &frame;
    r.prompt = std::move(prompt);
    r.score_threshold = score_threshold;
    r.labels = &labels;
    r.frame_index = frame_index;
    return r;
  }
};

/// Every field of two segmentations, exactly (timings included).
inline void ExpectSameSegmentation(const Segmentation& a, const Segmentation& b,
                                   const std::string& where = "") {
  ASSERT_EQ(a.width, b.width) << where;
  ASSERT_EQ(a.height, b.height) << where;
  ASSERT_EQ(a.instances.size(), b.instances.size()) << where;
  for (size_t i = 0; i < a.instances.size(); ++i) {
    const InstanceMask& x = a.instances[i];
    const InstanceMask& y = b.instances[i];
    EXPECT_TRUE(x.mask == y.mask) << where << " instance " << i;
    EXPECT_EQ(x.semantic_class, y.semantic_class) << where << " instance " << i;
    EXPECT_EQ(x.confidence, y.confidence) << where << " instance " << i;
    EXPECT_EQ(x.label, y.label) << where << " instance " << i;
    EXPECT_EQ(x.box, y.box) << where << " instance " << i;
    EXPECT_EQ(x.mask_score, y.mask_score) << where << " instance " << i;
  }
  ASSERT_EQ(a.timings.size(), b.timings.size()) << where;
  for (size_t i = 0; i < a.timings.size(); ++i) {
    EXPECT_EQ(a.timings[i].stage, b.timings[i].stage) << where << " timing " << i;
    EXPECT_EQ(a.timings[i].ms, b.timings[i].ms) << where << " timing " << i;
  }
}

}  // namespace avp::segmentation_service::test
