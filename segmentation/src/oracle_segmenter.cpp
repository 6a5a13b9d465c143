#include <algorithm>
#include <array>
#include <cmath>
#include <map>
#include <optional>
#include <set>
#include <utility>
#include <vector>

#include <fmt/format.h>
#include <fmt/ranges.h>

#include <avp/core/error.h>
#include <avp/core/rng.h>
#include <avp/segmentation/mask_ops.h>
#include <avp/segmentation/oracle_segmenter.h>

#include "phrase.h"

namespace avp::segmentation {

namespace {

bool InUnitInterval(double x) { return std::isfinite(x) && x >= 0.0 && x <= 1.0; }

/// Pixel count and class votes of one instance id in the label images.
struct InstanceStats {
  std::array<size_t, kNumSemanticClasses> votes{};
  size_t pixels = 0;
  /// Majority class; ties go to the lower class id (as Segmentation::FromLabelImages).
  SemanticClass Majority() const {
    int best = 0;
    for (int c = 1; c < kNumSemanticClasses; ++c) {
      if (votes[c] > votes[best]) best = c;
    }
    return static_cast<SemanticClass>(best);
  }
};

/// A fruit the model decided to report, before merging.
struct Detection {
  uint16_t instance_id = 0;
  MaskImage mask;
  float confidence = 0.0f;
  int boundary_px = 0;       ///< > 0 dilates, < 0 erodes
  bool merged_away = false;  ///< absorbed into another detection
  bool merged = false;       ///< took part in a merge this frame
};

// ---- Stages of OracleSegmenter::Segment ---------------------------------------------------------

/// The request's prompt phrases, once the request is known to be usable: a valid frame, a
/// threshold in [0, 1], and simulator labels of the frame's size.
Result<std::vector<std::string>> CheckedPromptPhrases(const SegmentationRequest& request) {
  if (request.frame == nullptr) {
    return InvalidArgumentError("oracle segmenter: request.frame is null");
  }
  const RgbdFrame& frame = *request.frame;
  AVP_RETURN_IF_ERROR(frame.Validate().WithContext("oracle segmenter"));
  AVP_ASSIGN_OR_RETURN(std::vector<std::string> phrases, SplitPrompt(request.prompt));
  if (!InUnitInterval(request.score_threshold)) {
    return InvalidArgumentError(fmt::format(
        "oracle segmenter: score_threshold ({}) must be in [0, 1]", request.score_threshold));
  }
  if (request.labels == nullptr) {
    return FailedPreconditionError(
        "the oracle segmenter reads the simulator's labels, and this frame has none (a real "
        "camera's or a recording's without /avp/sim labels): pick a segmenter that reads "
        "images (--segmenter color, ywes, lsam or remote://HOST:PORT)");
  }
  const SimulatorLabels& labels = *request.labels;
  const int w = frame.rgb.width();
  const int h = frame.rgb.height();
  if (!labels.instance_ids.SameSizeAs(w, h) || !labels.class_ids.SameSizeAs(w, h)) {
    return InvalidArgumentError(fmt::format(
        "oracle segmenter: simulator labels are {}x{} (instance ids) and {}x{} (class ids), but "
        "the frame is {}x{}",
        labels.instance_ids.width(), labels.instance_ids.height(), labels.class_ids.width(),
        labels.class_ids.height(), w, h));
  }
  return phrases;
}

/// Ground-truth fruit by instance id (the first entry of an id wins).
using TruthById = std::map<uint16_t, const GroundTruthFruit*>;

/// The labels' ground-truth fruits by instance id; InvalidArgument for a non-finite centre or a
/// radius that is not finite and > 0.
Result<TruthById> TruthByInstanceId(const SimulatorLabels& labels) {
  TruthById truth_of;
  for (const GroundTruthFruit& fruit : labels.fruits) {
    if (!std::isfinite(fruit.radius_m) || fruit.radius_m <= 0.0) {
      return InvalidArgumentError(fmt::format(
          "oracle segmenter: ground-truth fruit {}: radius_m ({}) must be finite and > 0",
          fruit.instance_id, fruit.radius_m));
    }
    if (!fruit.center_W.allFinite()) {
      return InvalidArgumentError(fmt::format(
          "oracle segmenter: ground-truth fruit {}: center_W ({}, {}, {}) must be finite",
          fruit.instance_id, fruit.center_W.x(), fruit.center_W.y(), fruit.center_W.z()));
    }
    truth_of.try_emplace(fruit.instance_id, &fruit);  // the first entry of an id wins
  }
  return truth_of;
}

/// Pixel count and class votes of every instance id in the label images (0 = none skipped).
std::map<uint16_t, InstanceStats> InstanceStatsOf(const SimulatorLabels& labels) {
  std::map<uint16_t, InstanceStats> stats;
  const int w = labels.instance_ids.width();
  const int h = labels.instance_ids.height();
  uint16_t last_id = 0;
  InstanceStats* last = nullptr;  // neighbouring pixels mostly share an id: skip the map lookup
  for (int v = 0; v < h; ++v) {
    for (int u = 0; u < w; ++u) {
      const uint16_t id = labels.instance_ids.at(u, v);
      if (id == 0) continue;
      if (last == nullptr || id != last_id) {
        last = &stats[id];
        last_id = id;
      }
      ++last->pixels;
      const int c = labels.class_ids.at(u, v);
      if (c < kNumSemanticClasses) ++last->votes[c];
    }
  }
  return stats;
}

/// The fruits the model reports, with empty masks of the frame's size.
struct Detections {
  std::vector<Detection> list;
  std::vector<int32_t> index_of = std::vector<int32_t>(size_t{1} << 16, -1);  ///< id -> list index
};

/// Detection and confidence of each fruit instance, drawn from fruit_rng forked by instance id.
Detections DetectedFruits(const std::map<uint16_t, InstanceStats>& stats, const TruthById& truth_of,
                          const RgbdFrame& frame, const OracleOptions& o, const Rng& fruit_rng) {
  Detections detections;
  for (const auto& [id, s] : stats) {
    if (s.Majority() != SemanticClass::kFruit) continue;
    double visible_fraction = 1.0;
    if (const auto it = truth_of.find(id); it != truth_of.end()) {
      if (const auto area = ExpectedFruitAreaPx(frame.K, frame.X_WC, *it->second)) {
        visible_fraction = std::clamp(static_cast<double>(s.pixels) / *area, 0.0, 1.0);
      }
    }
    // Always the same draws in the same order, so one part's parameters do not shift another's.
    Rng rng = fruit_rng.Fork(id);
    const double u_detect = rng.Uniform01();
    const double z_confidence = rng.Normal();
    const int boundary_px = o.boundary_offset_px +
                            static_cast<int>(rng.UniformInt(-o.max_boundary_px, o.max_boundary_px));
    const bool detected = s.pixels >= static_cast<size_t>(o.min_pixels) &&
                          u_detect < o.DetectionProbability(visible_fraction);
    if (!detected) continue;
    const double confidence =
        std::clamp(o.MeanConfidence(visible_fraction) + o.confidence_stddev * z_confidence,
                   o.confidence_min, o.confidence_max);
    detections.index_of[id] = static_cast<int32_t>(detections.list.size());
    Detection d;
    d.instance_id = id;
    d.mask = MaskImage(frame.rgb.width(), frame.rgb.height(), 0);
    d.confidence = static_cast<float>(confidence);
    d.boundary_px = boundary_px;
    detections.list.push_back(std::move(d));
  }
  return detections;
}

/// Paints each detection's exact visible mask and returns the pairs (lower id first) of detected
/// fruits that touch (4-neighbours).
std::set<std::pair<uint16_t, uint16_t>> PaintMasksAndFindTouchingPairs(
    const SimulatorLabels& labels, Detections& detections) {
  const int w = labels.instance_ids.width();
  const int h = labels.instance_ids.height();
  const std::vector<int32_t>& detection_of = detections.index_of;
  std::set<std::pair<uint16_t, uint16_t>> touching;
  const auto note_touch = [&](uint16_t a, uint16_t b) {
    if (a == b || detection_of[a] < 0 || detection_of[b] < 0) return;
    touching.insert({std::min(a, b), std::max(a, b)});
  };
  for (int v = 0; v < h; ++v) {
    for (int u = 0; u < w; ++u) {
      const uint16_t id = labels.instance_ids.at(u, v);
      if (id == 0) continue;
      if (const int32_t slot = detection_of[id]; slot >= 0) {
        detections.list[slot].mask.at(u, v) = 1;
      }
      if (u + 1 < w) note_touch(id, labels.instance_ids.at(u + 1, v));
      if (v + 1 < h) note_touch(id, labels.instance_ids.at(u, v + 1));
    }
  }
  return touching;
}

/// Merges touching pairs with probability p_merge each (one draw from merge_rng forked by the
/// pair), each fruit at most once per frame: the lower id absorbs the other's mask.
void MergeTouchingDetections(const std::set<std::pair<uint16_t, uint16_t>>& touching,
                             const Rng& merge_rng, double p_merge, Detections& detections) {
  for (const auto& [a, b] : touching) {
    Rng rng = merge_rng.Fork((static_cast<uint64_t>(a) << 16) | b);
    if (!rng.Bernoulli(p_merge)) continue;
    Detection& da = detections.list[static_cast<size_t>(detections.index_of[a])];
    Detection& db = detections.list[static_cast<size_t>(detections.index_of[b])];
    if (da.merged || db.merged) continue;  // each fruit merges at most once per frame
    for (size_t i = 0; i < da.mask.num_pixels(); ++i) {
      if (db.mask.data()[i] != 0) da.mask.data()[i] = 1;
    }
    da.confidence = std::max(da.confidence, db.confidence);
    da.merged = db.merged = true;
    db.merged_away = true;
  }
}

/// A false positive on a leaf (with probability p_false_positive), labelled as a fruit; the
/// caller sets its label. The draws from fp_rng: the coin, the confidence, then the leaf.
std::optional<InstanceMask> FalsePositiveOnLeaf(const std::map<uint16_t, InstanceStats>& stats,
                                                const SimulatorLabels& labels,
                                                const OracleOptions& o, Rng fp_rng) {
  const bool false_positive = fp_rng.Bernoulli(o.p_false_positive);
  const double fp_confidence =
      fp_rng.Uniform(o.false_positive_confidence_min, o.false_positive_confidence_max);
  if (!false_positive) return std::nullopt;
  std::vector<uint16_t> leaves;
  for (const auto& [id, s] : stats) {
    const size_t leaf_pixels = s.votes[static_cast<int>(SemanticClass::kLeaf)];
    if (s.Majority() == SemanticClass::kLeaf && leaf_pixels >= static_cast<size_t>(o.min_pixels))
      leaves.push_back(id);
  }
  if (leaves.empty()) return std::nullopt;
  const uint16_t leaf =
      leaves[static_cast<size_t>(fp_rng.UniformInt(0, static_cast<int64_t>(leaves.size()) - 1))];
  const int w = labels.instance_ids.width();
  const int h = labels.instance_ids.height();
  InstanceMask m;
  m.mask = MaskImage(w, h, 0);
  for (int v = 0; v < h; ++v) {
    for (int u = 0; u < w; ++u) {
      if (labels.instance_ids.at(u, v) == leaf &&
          labels.class_ids.at(u, v) == static_cast<uint8_t>(SemanticClass::kLeaf)) {
        m.mask.at(u, v) = 1;
      }
    }
  }
  m.semantic_class = SemanticClass::kFruit;
  m.confidence = static_cast<float>(fp_confidence);
  return m;
}

}  // namespace

OracleOptions OracleOptions::Perfect() {
  OracleOptions o;
  o.p_max = 1.0;
  o.v_min = 0.0;
  o.v_full = 0.0;
  o.min_pixels = 1;
  o.confidence_mean_at_0 = 0.95;
  o.confidence_gain = 0.0;
  o.confidence_stddev = 0.0;
  o.max_boundary_px = 0;
  o.boundary_offset_px = 0;
  o.p_false_positive = 0.0;
  o.p_merge = 0.0;
  return o;
}

const OptionTable<OracleOptions>& OracleOptionTable() {
  static const auto* table = [] {
    using O = OracleOptions;
    auto* t = new OptionTable<O>("oracle option");
    const ValueRange unit = ValueRange::Closed(0, 1);
    t->TextList("fruit_words", &O::fruit_words, "prompt words that name the fruit class");
    t->Real("p_max", &O::p_max, "", unit, "detection probability of a fully visible fruit");
    t->Real("v_min", &O::v_min, "", unit, "visible fraction below which a fruit is never found");
    t->Real("v_full", &O::v_full, "", unit, "visible fraction from which p_max applies");
    t->Integer("min_pixels", &O::min_pixels, "px", ValueRange::AtLeast(1),
               "visible pixels a fruit needs to be detected");
    t->Real("confidence_mean_at_0", &O::confidence_mean_at_0, "", ValueRange::Any(),
            "mean score of a fruit seen at visible fraction 0");
    t->Real("confidence_gain", &O::confidence_gain, "", ValueRange::Any(),
            "the mean score rises by this from visible fraction 0 to 1");
    t->Real("confidence_stddev", &O::confidence_stddev, "", ValueRange::AtLeast(0),
            "spread of the score (0: the mean exactly)");
    t->Real("confidence_min", &O::confidence_min, "", unit, "lower clamp of the score");
    t->Real("confidence_max", &O::confidence_max, "", unit, "upper clamp of the score");
    t->Integer("max_boundary_px", &O::max_boundary_px, "px", ValueRange::Closed(0, 16),
               "masks grow or shrink by up to this many pixels");
    t->Integer("boundary_offset_px", &O::boundary_offset_px, "px", ValueRange::Closed(-16, 16),
               "every mask grows (> 0) or shrinks (< 0) by this many pixels more");
    t->Real("p_false_positive", &O::p_false_positive, "", unit,
            "probability of a false fruit on a leaf per frame");
    t->Real("false_positive_confidence_min", &O::false_positive_confidence_min, "", unit,
            "lowest score of a false positive");
    t->Real("false_positive_confidence_max", &O::false_positive_confidence_max, "", unit,
            "highest score of a false positive");
    t->Real("p_merge", &O::p_merge, "", unit, "probability that two touching fruits merge");
    t->AddRule([unit](const O& o, std::vector<std::string>& errors) {
      for (size_t i = 0; i < o.fruit_words.size(); ++i) {
        if (!internal::IsVocabularyWord(o.fruit_words[i])) {
          errors.push_back(fmt::format(
              "fruit_words[{}] (\"{}\") must be a non-empty lower-case word", i, o.fruit_words[i]));
        }
      }
      const auto ordered = [&](double lo, double hi, const char* lo_name, const char* hi_name) {
        if (unit.Contains(lo) && unit.Contains(hi) && hi < lo) {
          errors.push_back(fmt::format("{} ({}) must be >= {} ({})", hi_name, hi, lo_name, lo));
        }
      };
      ordered(o.v_min, o.v_full, "v_min", "v_full");
      ordered(o.confidence_min, o.confidence_max, "confidence_min", "confidence_max");
      ordered(o.false_positive_confidence_min, o.false_positive_confidence_max,
              "false_positive_confidence_min", "false_positive_confidence_max");
    });
    return t;
  }();
  return *table;
}

Status OracleOptions::Validate() const { return OracleOptionTable().Validate(*this); }

namespace {

SegmenterEntry OracleEntry(std::string name, std::string description, OracleOptions defaults) {
  return MakeSegmenterEntry<OracleOptions>(
      std::move(name), std::move(description), OracleOptionTable(), std::move(defaults),
      [](std::string_view, const OracleOptions& o, const SegmenterContext& c) {
        return Result<std::unique_ptr<Segmenter>>(std::make_unique<OracleSegmenter>(o, c.seed));
      });
}

}  // namespace

SegmenterEntry OracleSegmenterEntry() {
  return OracleEntry("oracle",
                     "the simulator's labels through a seeded zero-shot-like error model "
                     "(docs/segmentation.md)",
                     OracleOptions{});
}

SegmenterEntry OraclePerfectSegmenterEntry() {
  return OracleEntry("oracle-perfect", "the simulator's labels, every visible fruit, no noise",
                     OracleOptions::Perfect());
}

double OracleOptions::DetectionProbability(double visible_fraction) const {
  const double v = std::clamp(std::isfinite(visible_fraction) ? visible_fraction : 0.0, 0.0, 1.0);
  if (v >= v_full) return p_max;
  if (v <= v_min) return 0.0;
  const double t = std::clamp((v - v_min) / (v_full - v_min), 0.0, 1.0);
  return p_max * t * t * (3.0 - 2.0 * t);
}

double OracleOptions::MeanConfidence(double visible_fraction) const {
  const double v = std::clamp(std::isfinite(visible_fraction) ? visible_fraction : 0.0, 0.0, 1.0);
  return confidence_mean_at_0 + confidence_gain * v;
}

std::optional<double> ExpectedFruitAreaPx(const CameraIntrinsics& K, const RigidTransform& X_WC,
                                          const GroundTruthFruit& fruit) {
  const Eigen::Vector3d p_C = X_WC.inverse() * fruit.center_W;
  const double z = p_C.z();
  if (!std::isfinite(z) || !(z > fruit.radius_m)) return std::nullopt;
  const double f = std::sqrt(K.fx * K.fy);
  const double r_px = f * fruit.radius_m / z;
  return M_PI * r_px * r_px;
}

OracleSegmenter::OracleSegmenter(OracleOptions options, uint64_t seed)
    : options_(std::move(options)), seed_(seed) {
  const Status status = options_.Validate();
  AVP_THROW_UNLESS(status.ok(), status.message());
}

std::optional<SemanticClass> OracleSegmenter::ClassForPhrase(std::string_view phrase) const {
  const std::vector<std::string> words = internal::PhraseWords(phrase);
  if (words.empty()) return std::nullopt;
  for (const std::string& candidate : internal::SingularCandidates(words.back())) {
    if (std::find(options_.fruit_words.begin(), options_.fruit_words.end(), candidate) !=
        options_.fruit_words.end()) {
      return SemanticClass::kFruit;
    }
  }
  return std::nullopt;
}

Result<Segmentation> OracleSegmenter::Segment(const SegmentationRequest& request) {
  AVP_ASSIGN_OR_RETURN(const std::vector<std::string> phrases, CheckedPromptPhrases(request));
  const RgbdFrame& frame = *request.frame;
  const SimulatorLabels& labels = *request.labels;
  AVP_ASSIGN_OR_RETURN(const TruthById truth_of, TruthByInstanceId(labels));
  const int w = frame.rgb.width();
  const int h = frame.rgb.height();

  Segmentation out;
  out.width = w;
  out.height = h;
  const std::string* target_phrase = nullptr;
  for (const std::string& phrase : phrases) {
    if (ClassForPhrase(phrase) == SemanticClass::kFruit) {
      target_phrase = &phrase;
      break;
    }
  }
  if (target_phrase == nullptr) return out;  // nothing in the prompt names a simulated class

  AVP_RETURN_IF_ERROR(CheckInterrupt(request));
  const std::map<uint16_t, InstanceStats> stats = InstanceStatsOf(labels);
  const Rng frame_rng = Rng(seed_).Fork("oracle").Fork(request.frame_index);
  const OracleOptions& o = options_;
  Detections detections = DetectedFruits(stats, truth_of, frame, o, frame_rng.Fork("fruit"));
  AVP_RETURN_IF_ERROR(CheckInterrupt(request));
  const std::set<std::pair<uint16_t, uint16_t>> touching =
      PaintMasksAndFindTouchingPairs(labels, detections);
  AVP_RETURN_IF_ERROR(CheckInterrupt(request));
  for (Detection& d : detections.list) {
    if (d.boundary_px != 0) d.mask = AdjustBoundary(d.mask, d.boundary_px);
  }
  AVP_RETURN_IF_ERROR(CheckInterrupt(request));
  MergeTouchingDetections(touching, frame_rng.Fork("merge"), o.p_merge, detections);
  for (Detection& d : detections.list) {
    if (d.merged_away || CountPixels(d.mask) == 0) continue;  // eroded away: a missed detection
    InstanceMask m;
    m.mask = std::move(d.mask);
    m.semantic_class = SemanticClass::kFruit;
    m.confidence = d.confidence;
    m.label = *target_phrase;
    out.instances.push_back(std::move(m));
  }
  if (std::optional<InstanceMask> fp =
          FalsePositiveOnLeaf(stats, labels, o, frame_rng.Fork("false_positive"))) {
    fp->label = *target_phrase;
    out.instances.push_back(std::move(*fp));
  }

  // ---- Score threshold --------------------------------------------------------------------------
  std::erase_if(out.instances,
                [&](const InstanceMask& m) { return m.confidence < request.score_threshold; });
  return out;
}

}  // namespace avp::segmentation
