// Writes the generated part of the fuzz seed corpora (fuzz/corpus/<target>/gen-*): small valid
// inputs made with avp's own writers, and near-valid variants of them (truncated, one field
// changed). The hand-made edge cases (hand-*) are committed beside them. Run it after a format
// changes and commit the result:
//
//   ninja -C <build> avp_fuzz_make_corpus && <build>/fuzz/avp_fuzz_make_corpus fuzz/corpus
//
// Deterministic: the same build writes the same bytes.

#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include <avp/core/rgbd_frame.h>
#include <avp/core/segmentation.h>
#include <avp/core/simulator_labels.h>
#include <avp/io/image_codec.h>
#include <avp/mapping/map_file.h>
#include <avp/mapping/octomap_io.h>
#include <avp/mapping/semantic_map.h>
#include <avp/segmentation_service/segmentation_codec.h>

#include "grpc_predict_v2.pb.h"
#include "proto_convert.h"

namespace fs = std::filesystem;
using namespace avp;

namespace {

int g_failures = 0;

void Write(const fs::path& path, std::string_view bytes) {
  fs::create_directories(path.parent_path());
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  if (!out) {
    std::fprintf(stderr, "make_corpus: cannot write %s\n", path.c_str());
    ++g_failures;
  }
}
void Write(const fs::path& path, std::span<const uint8_t> bytes) {
  Write(path, std::string_view(reinterpret_cast<const char*>(bytes.data()), bytes.size()));
}
std::string ReadAll(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}
void Check(const Status& s, std::string_view what) {
  if (!s.ok()) {
    std::fprintf(stderr, "make_corpus: %.*s: %s\n", static_cast<int>(what.size()), what.data(),
                 s.ToString().c_str());
    ++g_failures;
  }
}

mapping::SemanticMap SmallMap(bool labelled) {
  mapping::SemanticMap map;
  mapping::OccupancyGrid& grid = map.grid();
  const float hi = grid.clamp_max_log_odds();
  const float lo = grid.clamp_min_log_odds();
  for (int i = 0; i < 12; ++i) {
    grid.SetLogOdds({i - 4, i % 3, -(i % 5)}, i % 3 == 0 ? lo : hi);
  }
  grid.SetLogOdds({300, -200, 17}, 0.25f * hi);  // a second block
  if (labelled) {
    for (int x = 0; x < 3; ++x) {
      const VoxelKey k{x, 0, 0};
      grid.SetLogOdds(k, hi);
      mapping::SemanticCell* c = grid.MutableSemantic(k);
      c->semantic_class = static_cast<uint8_t>(SemanticClass::kFruit);
      c->instance_id = static_cast<uint16_t>(1 + x / 2);
      c->observations = 3;
      c->confidence = 0.8f;
      c->class_log_odds[1] = 120;
    }
  }
  return map;
}

void MapFileCorpus(const fs::path& dir) {
  for (bool labelled : {false, true}) {
    const std::string name = labelled ? "labelled" : "occupancy";
    mapping::MapSaveOptions save;
    save.note = "fuzz seed " + name;
    auto bytes = mapping::SerializeMap(SmallMap(labelled), save);
    Check(bytes.status(), "SerializeMap");
    if (!bytes.ok()) continue;
    Write(dir / ("gen-" + name + ".avpmap"), *bytes);
    // Near-valid: cut in the middle (the checksum and declared size then disagree), and one
    // payload byte changed (a checksum mismatch).
    std::vector<uint8_t> cut(bytes->begin(), bytes->begin() + static_cast<long>(bytes->size() / 2));
    Write(dir / ("gen-" + name + "-truncated.avpmap"), cut);
    std::vector<uint8_t> flipped = *bytes;
    flipped[flipped.size() / 2] ^= 0x40;
    Write(dir / ("gen-" + name + "-flipped.avpmap"), flipped);
  }
  auto empty = mapping::SerializeMap(mapping::SemanticMap{});
  Check(empty.status(), "SerializeMap(empty)");
  if (empty.ok()) Write(dir / "gen-empty.avpmap", *empty);
}

void OctomapCorpus(const fs::path& dir, const fs::path& scratch) {
  const mapping::SemanticMap map = SmallMap(true);
  const fs::path bt = scratch / "seed.bt";
  const fs::path ot = scratch / "seed.ot";
  Check(mapping::ExportOctomapBinary(map.grid(), bt).status(), "ExportOctomapBinary");
  Check(mapping::ExportOctomapColor(map, ot).status(), "ExportOctomapColor");
  for (const auto& [file, name] :
       {std::pair{bt, std::string("binary.bt")}, std::pair{ot, std::string("color.ot")}}) {
    const std::string bytes = ReadAll(file);
    Write(dir / ("gen-" + name), bytes);
    Write(dir / ("gen-truncated-" + name), bytes.substr(0, bytes.size() * 2 / 3));
  }
}

ImageRgb8 TestImage(int w, int h) {
  ImageRgb8 image(w, h);
  for (int v = 0; v < h; ++v) {
    for (int u = 0; u < w; ++u) {
      const bool fruit = (u - w / 2) * (u - w / 2) + (v - h / 2) * (v - h / 2) <= (h * h) / 9;
      auto p = image.pixel(u, v);
      p[0] = fruit ? 200 : static_cast<uint8_t>(30 + 10 * (u % 4));
      p[1] = fruit ? 20 : static_cast<uint8_t>(120 + 5 * (v % 6));
      p[2] = fruit ? 25 : 40;
    }
  }
  return image;
}

void ImageCorpus(const fs::path& dir) {
  for (const auto& [w, h] : {std::pair{1, 1}, std::pair{8, 6}, std::pair{31, 17}}) {
    const std::string size = std::to_string(w) + "x" + std::to_string(h);
    const ImageRgb8 image = TestImage(w, h);
    auto png = io::EncodePng(image);
    auto jpeg = io::EncodeJpeg(image, 80);
    Check(png.status(), "EncodePng");
    Check(jpeg.status(), "EncodeJpeg");
    if (png.ok()) Write(dir / ("gen-" + size + ".png"), *png);
    if (jpeg.ok()) Write(dir / ("gen-" + size + ".jpg"), *jpeg);
    if (png.ok() && w > 1) {
      Write(dir / ("gen-" + size + "-truncated.png"),
            std::span<const uint8_t>(png->data(), png->size() * 3 / 4));
    }
  }
  // A PNG whose (valid, checksummed) header declares 20000 x 20000 pixels: must be refused
  // from the header (max_image_pixels), before any pixel is decoded.
  std::vector<uint8_t> big = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n', 0, 0, 0, 13};
  const std::vector<uint8_t> ihdr = {'I', 'H',  'D',  'R', 0, 0, 0x4e, 0x20, 0,
                                     0,   0x4e, 0x20, 8,   2, 0, 0,    0};
  big.insert(big.end(), ihdr.begin(), ihdr.end());
  const uint32_t crc = mapping::Crc32(ihdr);
  for (int s = 24; s >= 0; s -= 8) big.push_back(static_cast<uint8_t>(crc >> s));
  const std::vector<uint8_t> iend = {0, 0, 0, 0, 'I', 'E', 'N', 'D', 0xae, 0x42, 0x60, 0x82};
  big.insert(big.end(), iend.begin(), iend.end());
  Write(dir / "gen-20000x20000-header.png", big);
}

RgbdFrame TestFrame(int w, int h) {
  RgbdFrame frame;
  frame.rgb = TestImage(w, h);
  frame.K = CameraIntrinsics::FromHorizontalFov(w, h, 60.0);
  frame.depth_m = DepthImage(w, h, 0.8f);
  frame.stamp_ns = 123456789;
  return frame;
}

SimulatorLabels TestLabels(const RgbdFrame& frame) {
  SimulatorLabels labels;
  const int w = frame.rgb.width();
  const int h = frame.rgb.height();
  labels.instance_ids = InstanceImage(w, h);
  labels.class_ids = ClassImage(w, h);
  for (int v = 0; v < h; ++v) {
    for (int u = 0; u < w; ++u) {
      if (frame.rgb.pixel(u, v)[0] == 200) {
        labels.instance_ids(u, v) = 7;
        labels.class_ids(u, v) = static_cast<uint8_t>(SemanticClass::kFruit);
      } else if (v > h / 2) {
        labels.instance_ids(u, v) = 3;
        labels.class_ids(u, v) = static_cast<uint8_t>(SemanticClass::kLeaf);
      }
    }
  }
  GroundTruthFruit fruit;
  fruit.instance_id = 7;
  fruit.center_W = Eigen::Vector3d(0.0, 0.0, 0.8);
  fruit.radius_m = 0.03;
  labels.fruits.push_back(fruit);
  return labels;
}

void RequestCorpus(const fs::path& dir) {
  const RgbdFrame frame = TestFrame(8, 6);
  const SimulatorLabels labels = TestLabels(frame);
  struct Variant {
    std::string name;
    std::string model;
    segmentation_service::ImageEncoding image;
    bool depth;
    bool with_labels;
    std::string prompt;
  };
  const std::vector<Variant> variants = {
      {"color-raw", "color", segmentation_service::ImageEncoding::kRaw, true, false, "tomato"},
      {"color-png", "color", segmentation_service::ImageEncoding::kPng, false, false,
       "red tomato, leaf"},
      {"color-jpeg", "color", segmentation_service::ImageEncoding::kJpeg, false, false, "tomato"},
      {"oracle-raw", "oracle", segmentation_service::ImageEncoding::kRaw, true, true, "tomato"},
      {"oracle-perfect-png", "oracle-perfect", segmentation_service::ImageEncoding::kPng, true,
       true, "tomato, leaf"},
  };
  for (const Variant& v : variants) {
    segmentation::SegmentationRequest request;
    request.frame = &frame;
    request.prompt = v.prompt;
    request.score_threshold = 0.1f;
    request.labels = v.with_labels ? &labels : nullptr;
    request.frame_index = 3;
    segmentation_service::RequestEncodeOptions options;
    options.model_name = v.model;
    options.seed = 11;
    options.image = v.image;
    options.send_depth = v.depth;
    auto encoded = segmentation_service::EncodeSegmentationRequest(request, options);
    Check(encoded.status(), "EncodeSegmentationRequest " + v.name);
    if (!encoded.ok()) continue;
    inference::ModelInferRequest proto;
    segmentation_service::internal::ToProto(*encoded, &proto);
    Write(dir / ("gen-" + v.name + ".pb"), proto.SerializeAsString());
    if (v.name == "color-raw") {
      // Near-valid: the rgb tensor one row short; an unknown requested output.
      inference::ModelInferRequest shorter = proto;
      std::string* raw = shorter.mutable_raw_input_contents(0);
      raw->resize(raw->size() - 8 * 3);
      Write(dir / "gen-color-raw-short-rgb.pb", shorter.SerializeAsString());
      inference::ModelInferRequest outputs = proto;
      outputs.add_outputs()->set_name("masks");
      outputs.add_outputs()->set_name("nope");
      Write(dir / "gen-color-raw-unknown-output.pb", outputs.SerializeAsString());
    }
  }
}

Segmentation TestSegmentation() {
  Segmentation seg;
  seg.width = 8;
  seg.height = 6;
  for (int i = 0; i < 2; ++i) {
    InstanceMask m;
    m.mask = MaskImage(8, 6);
    for (int u = i * 3; u < i * 3 + 3; ++u) m.mask(u, 2) = 1;
    m.semantic_class = i == 0 ? SemanticClass::kFruit : SemanticClass::kLeaf;
    m.confidence = 0.9f - 0.2f * static_cast<float>(i);
    m.label = i == 0 ? "tomato" : "leaf";
    if (i == 0) m.box = PixelBox{0, 2, 3, 3};
    m.mask_score = i == 0 ? 0.7f : -1.0f;
    seg.instances.push_back(std::move(m));
  }
  seg.timings.push_back({"color", 1.5});
  return seg;
}

void ResponseCorpus(const fs::path& dir) {
  auto response = segmentation_service::EncodeSegmentation(TestSegmentation());
  Check(response.status(), "EncodeSegmentation");
  if (!response.ok()) return;
  response->model_name = "color";
  response->id = "camera@1";
  inference::ModelInferResponse proto;
  segmentation_service::internal::ToProto(*response, &proto);
  Write(dir / "gen-two-instances.pb", proto.SerializeAsString());
  // The compact mask formats (mask_format rle and instance_ids).
  for (const auto& [format, name] :
       {std::pair{segmentation_service::MaskFormat::kRle, "gen-two-instances-rle.pb"},
        std::pair{segmentation_service::MaskFormat::kInstanceIds, "gen-two-instances-ids.pb"}}) {
    auto compact = segmentation_service::EncodeSegmentation(TestSegmentation(), format);
    Check(compact.status(), "EncodeSegmentation " + std::string(name));
    if (!compact.ok()) continue;
    inference::ModelInferResponse p;
    segmentation_service::internal::ToProto(*compact, &p);
    Write(dir / name, p.SerializeAsString());
  }
  Segmentation none;
  none.width = 8;
  none.height = 6;
  auto empty = segmentation_service::EncodeSegmentation(none);
  if (empty.ok()) {
    inference::ModelInferResponse p;
    segmentation_service::internal::ToProto(*empty, &p);
    Write(dir / "gen-no-instances.pb", p.SerializeAsString());
  }
  // Typed contents instead of raw ones (scores as fp32_contents, labels as bytes_contents).
  inference::ModelInferResponse typed;
  typed.set_model_name("color");
  auto* scores = typed.add_outputs();
  scores->set_name("scores");
  scores->set_datatype("FP32");
  scores->add_shape(2);
  scores->mutable_contents()->add_fp32_contents(0.9f);
  scores->mutable_contents()->add_fp32_contents(0.7f);
  auto* masks = typed.add_outputs();
  masks->set_name("masks");
  masks->set_datatype("BOOL");
  masks->add_shape(2);
  masks->add_shape(2);
  masks->add_shape(3);
  for (int i = 0; i < 12; ++i) masks->mutable_contents()->add_bool_contents(i % 5 == 0);
  auto* lbl = typed.add_outputs();
  lbl->set_name("labels");
  lbl->set_datatype("BYTES");
  lbl->add_shape(2);
  lbl->mutable_contents()->add_bytes_contents("tomato");
  lbl->mutable_contents()->add_bytes_contents("leaf");
  Write(dir / "gen-typed-contents.pb", typed.SerializeAsString());
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: avp_fuzz_make_corpus <fuzz/corpus folder>\n");
    return 2;
  }
  const fs::path root = argv[1];
  const fs::path scratch = fs::temp_directory_path() / "avp-fuzz-make-corpus";
  fs::create_directories(scratch);
  MapFileCorpus(root / "map_file");
  OctomapCorpus(root / "octomap_import", scratch);
  ImageCorpus(root / "image_codec");
  RequestCorpus(root / "infer_request");
  ResponseCorpus(root / "tensor_codec");
  fs::remove_all(scratch);
  if (g_failures > 0) {
    std::fprintf(stderr, "make_corpus: %d failures\n", g_failures);
    return 1;
  }
  std::printf("make_corpus: wrote the generated seeds under %s\n", root.c_str());
  return 0;
}
