#include <array>
#include <cmath>
#include <map>

#include <fmt/format.h>

#include <avp/core/segmentation.h>

namespace avp {

Status Segmentation::Validate() const {
  if (width < 0 || height < 0) {
    return InvalidArgumentError(fmt::format("segmentation size {}x{} is negative", width, height));
  }
  for (size_t i = 0; i < instances.size(); ++i) {
    const InstanceMask& m = instances[i];
    if (!m.mask.SameSizeAs(width, height)) {
      return InvalidArgumentError(
          fmt::format("segmentation instance {}: mask is {}x{}, expected {}x{}", i, m.mask.width(),
                      m.mask.height(), width, height));
    }
    if (!std::isfinite(m.confidence) || m.confidence < 0.0f || m.confidence > 1.0f) {
      return InvalidArgumentError(
          fmt::format("segmentation instance {}: confidence ({}) must be finite and in [0, 1]", i,
                      m.confidence));
    }
    if (static_cast<int>(m.semantic_class) >= kNumSemanticClasses) {
      return InvalidArgumentError(fmt::format("segmentation instance {}: class id ({}) is unknown",
                                              i, static_cast<int>(m.semantic_class)));
    }
  }
  return Status::Ok();
}

Status Segmentation::ValidateFor(int image_width, int image_height) const {
  if (width != image_width || height != image_height) {
    return InvalidArgumentError(fmt::format("segmentation is {}x{} but the image is {}x{}", width,
                                            height, image_width, image_height));
  }
  return Validate();
}

Segmentation Segmentation::FromLabelImages(const InstanceImage& instance_ids,
                                           const ClassImage& class_ids, float confidence,
                                           const std::vector<SemanticClass>& keep_classes) {
  AVP_THROW_UNLESS(instance_ids.SameSizeAs(class_ids), instance_ids.width(), instance_ids.height(),
                   class_ids.width(), class_ids.height());
  const int w = instance_ids.width();
  const int h = instance_ids.height();
  // Majority class per instance id.
  std::map<uint16_t, std::array<int, kNumSemanticClasses>> votes;
  for (int v = 0; v < h; ++v) {
    for (int u = 0; u < w; ++u) {
      const uint16_t id = instance_ids.at(u, v);
      if (id == 0) continue;
      auto [it, inserted] = votes.try_emplace(id);
      if (inserted) it->second.fill(0);
      const int c = class_ids.at(u, v);
      if (c < kNumSemanticClasses) ++it->second[c];
    }
  }
  Segmentation out;
  out.width = w;
  out.height = h;
  std::map<uint16_t, size_t> index_of;
  for (const auto& [id, counts] : votes) {
    int best = 0;
    for (int c = 1; c < kNumSemanticClasses; ++c) {
      if (counts[c] > counts[best]) best = c;
    }
    const auto cls = static_cast<SemanticClass>(best);
    bool keep = false;
    for (SemanticClass k : keep_classes) keep = keep || (k == cls);
    if (!keep) continue;
    index_of[id] = out.instances.size();
    InstanceMask m;
    m.mask = MaskImage(w, h, 0);
    m.semantic_class = cls;
    m.confidence = confidence;
    m.label = std::string(ToString(cls));
    out.instances.push_back(std::move(m));
  }
  for (int v = 0; v < h; ++v) {
    for (int u = 0; u < w; ++u) {
      const uint16_t id = instance_ids.at(u, v);
      if (id == 0) continue;
      const auto it = index_of.find(id);
      if (it != index_of.end()) out.instances[it->second].mask.at(u, v) = 1;
    }
  }
  return out;
}

}  // namespace avp
