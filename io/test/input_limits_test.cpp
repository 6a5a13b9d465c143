// Hostile inputs to the readers of avp::io (issue 15): sizes declared in headers are checked
// before anything is decoded or allocated, text from files reaches messages escaped, and deep
// YAML is refused before yaml-cpp recurses into it. Every input here is tiny: a test that
// allocated what the headers declare would take gigabytes.

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include <avp/core/limits.h>
#include <avp/core/options.h>
#include <avp/core/status.h>
#include <avp/io/image_codec.h>
#include <avp/io/image_limits.h>
#include <avp/io/mask_codec.h>
#include <avp/io/options_yaml.h>
#include <avp/io/png.h>
#include <avp/io/yaml.h>
#include <avp/test/temp_dir_test.h>

namespace avp::io {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;
using ::testing::Not;

uint32_t Crc32(const std::vector<uint8_t>& bytes) {
  uint32_t crc = 0xffffffffu;
  for (const uint8_t b : bytes) {
    crc ^= b;
    for (int k = 0; k < 8; ++k) crc = (crc >> 1) ^ (0xedb88320u & (0u - (crc & 1u)));
  }
  return ~crc;
}

void PutU32(std::vector<uint8_t>& out, uint32_t v) {
  for (int shift = 24; shift >= 0; shift -= 8) out.push_back(static_cast<uint8_t>(v >> shift));
}

void PutChunk(std::vector<uint8_t>& out, const char* type, const std::vector<uint8_t>& data) {
  PutU32(out, static_cast<uint32_t>(data.size()));
  std::vector<uint8_t> typed(type, type + 4);
  typed.insert(typed.end(), data.begin(), data.end());
  out.insert(out.end(), typed.begin(), typed.end());
  PutU32(out, Crc32(typed));
}

/// A PNG whose IHDR (with a correct CRC) declares width x height pixels, followed by a small IDAT
/// of zeros and IEND: some hundred bytes that would decode to gigabytes.
std::vector<uint8_t> PngDeclaring(uint32_t width, uint32_t height, uint8_t bit_depth = 8,
                                  uint8_t color_type = 2) {
  std::vector<uint8_t> png = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  std::vector<uint8_t> ihdr;
  PutU32(ihdr, width);
  PutU32(ihdr, height);
  ihdr.insert(ihdr.end(), {bit_depth, color_type, 0, 0, 0});
  PutChunk(png, "IHDR", ihdr);
  // A zlib stream of 64 zero bytes (stored block): a start, never enough.
  std::vector<uint8_t> z = {0x78, 0x01, 0x01, 64, 0, static_cast<uint8_t>(~64), 0xff};
  z.insert(z.end(), 64, 0);
  PutU32(z, 0x00400001u);  // Adler-32 of 64 zeros
  PutChunk(png, "IDAT", z);
  PutChunk(png, "IEND", {});
  return png;
}

/// A baseline JPEG header (SOI, APP0 JFIF, SOF0) declaring width x height, 3 components.
std::vector<uint8_t> JpegDeclaring(uint16_t width, uint16_t height) {
  std::vector<uint8_t> j = {0xFF, 0xD8,                                            // SOI
                            0xFF, 0xE0, 0x00, 0x10, 'J',  'F',  'I',  'F',  0x00,  // APP0
                            0x01, 0x01, 0x00, 0x00, 0x01, 0x00, 0x01, 0x00, 0x00,  //
                            0xFF, 0xC0, 0x00, 0x11, 0x08};                         // SOF0
  j.push_back(static_cast<uint8_t>(height >> 8));
  j.push_back(static_cast<uint8_t>(height & 0xff));
  j.push_back(static_cast<uint8_t>(width >> 8));
  j.push_back(static_cast<uint8_t>(width & 0xff));
  j.insert(j.end(), {0x03, 0x01, 0x22, 0x00, 0x02, 0x11, 0x01, 0x03, 0x11, 0x01});
  j.insert(j.end(), {0xFF, 0xD9});  // EOI
  return j;
}

class InputLimitsTest : public test::TempDirTest {
 protected:
  fs::path WriteBytes(const std::string& name, const std::vector<uint8_t>& bytes) {
    const fs::path path = dir_ / name;
    std::ofstream out(path, std::ios::binary);
    out.write(reinterpret_cast<const char*>(bytes.data()),
              static_cast<std::streamsize>(bytes.size()));
    return path;
  }
};

// ---- Images: the header's size before any pixel ------------------------------------------------

TEST_F(InputLimitsTest, PngFileDeclaring20000x20000IsRefusedBeforeDecoding) {
  const std::vector<uint8_t> bytes = PngDeclaring(20000, 20000);
  ASSERT_LT(bytes.size(), 200u);
  const fs::path path = WriteBytes("huge.png", bytes);
  const Status rgb = ReadPngRgb8(path).status();
  EXPECT_EQ(rgb.code(), StatusCode::kResourceExhausted) << rgb.ToString();
  EXPECT_THAT(rgb.message(), HasSubstr("20000 x 20000"));
  EXPECT_THAT(rgb.message(), HasSubstr("400000000"));
  EXPECT_THAT(rgb.message(), HasSubstr("max_image_pixels = 67108864"));
  EXPECT_THAT(rgb.message(), HasSubstr(path.string()));
  // Depth (16-bit grey) and label (8-bit grey) images alike.
  const fs::path depth = WriteBytes("depth.png", PngDeclaring(20000, 20000, 16, 0));
  EXPECT_EQ(ReadPngGray16(depth).status().code(), StatusCode::kResourceExhausted);
  const fs::path labels = WriteBytes("labels.png", PngDeclaring(20000, 20000, 8, 0));
  EXPECT_EQ(ReadPngGray8(labels).status().code(), StatusCode::kResourceExhausted);
}

TEST_F(InputLimitsTest, EncodedPngAndJpegDeclaring20000x20000AreRefusedBeforeDecoding) {
  const Status png = DecodeImage(PngDeclaring(20000, 20000)).status();
  EXPECT_EQ(png.code(), StatusCode::kResourceExhausted) << png.ToString();
  EXPECT_THAT(png.message(), HasSubstr("PNG image of 20000 x 20000 pixels (400000000)"));
  EXPECT_THAT(png.message(), HasSubstr("max_image_pixels"));

  const std::vector<uint8_t> jpeg = JpegDeclaring(20000, 20000);
  const Status jpg = DecodeImage(jpeg).status();
  EXPECT_EQ(jpg.code(), StatusCode::kResourceExhausted) << jpg.ToString();
  EXPECT_THAT(jpg.message(), HasSubstr("JPEG image of 20000 x 20000 pixels"));

  const fs::path file = WriteBytes("huge.jpg", jpeg);
  const Status from_file = ReadImageFile(file).status();
  EXPECT_EQ(from_file.code(), StatusCode::kResourceExhausted) << from_file.ToString();
  EXPECT_THAT(from_file.message(), HasSubstr(file.string()));
}

TEST_F(InputLimitsTest, ImageHeadersAreReadWithoutDecoding) {
  const Result<ImageHeader> png = ReadImageHeader(PngDeclaring(640, 480));
  ASSERT_TRUE(png.ok()) << png.status().ToString();
  EXPECT_EQ(png->format, "PNG");
  EXPECT_EQ(png->width, 640u);
  EXPECT_EQ(png->height, 480u);
  const Result<ImageHeader> jpg = ReadImageHeader(JpegDeclaring(1920, 1080));
  ASSERT_TRUE(jpg.ok()) << jpg.status().ToString();
  EXPECT_EQ(jpg->format, "JPEG");
  EXPECT_EQ(jpg->width, 1920u);
  EXPECT_EQ(jpg->height, 1080u);
  // A real encoder's output.
  const Result<std::vector<uint8_t>> real = EncodeJpeg(ImageRgb8(33, 17, 100));
  ASSERT_TRUE(real.ok());
  const Result<ImageHeader> real_header = ReadImageHeader(*real);
  ASSERT_TRUE(real_header.ok()) << real_header.status().ToString();
  EXPECT_EQ(real_header->width, 33u);
  EXPECT_EQ(real_header->height, 17u);
  // Every prefix of a header that ends before the frame's width is refused, never read past its
  // end (SOI 2 + APP0 18 + SOF marker, length, precision, height and width 9 = 29 bytes).
  const std::vector<uint8_t> full = JpegDeclaring(100, 100);
  EXPECT_TRUE(ReadImageHeader(std::vector<uint8_t>(full.begin(), full.begin() + 29)).ok());
  for (size_t n = 0; n < 29; ++n) {
    const std::vector<uint8_t> cut(full.begin(), full.begin() + static_cast<long>(n));
    EXPECT_FALSE(ReadImageHeader(cut).ok()) << n;
  }
}

TEST_F(InputLimitsTest, JpegWithThousandsOfScansIsRefused) {
  // A small progressive-style file: a frame header, then 1000 scan headers with one byte of data.
  std::vector<uint8_t> j = JpegDeclaring(64, 64);
  j.resize(j.size() - 2);  // drop EOI
  for (int i = 0; i < 1000; ++i) {
    j.insert(j.end(), {0xFF, 0xDA, 0x00, 0x08, 0x01, 0x01, 0x00, 0x00, 0x3F, 0x00, 0x12});
  }
  j.insert(j.end(), {0xFF, 0xD9});
  const Status s = DecodeImage(j).status();
  EXPECT_EQ(s.code(), StatusCode::kResourceExhausted) << s.ToString();
  EXPECT_THAT(s.message(), HasSubstr("more than 256 scans"));
  // A real encoder's JPEG passes.
  const Result<std::vector<uint8_t>> real = EncodeJpeg(ImageRgb8(40, 30, 90));
  ASSERT_TRUE(real.ok());
  EXPECT_TRUE(CheckJpegScans(*real, "image").ok());
  EXPECT_TRUE(DecodeImage(*real).ok());
}

TEST_F(InputLimitsTest, OtherFormatsAreRefusedByName) {
  const std::vector<uint8_t> tiff = {'I', 'I', '*', 0, 8, 0, 0, 0, 0, 0};
  const Status s = DecodeImage(tiff).status();
  EXPECT_EQ(s.code(), StatusCode::kParseError);
  EXPECT_EQ(
      s.message(),
      "undecodable image (10 bytes): TIFF images are not accepted (only PNG, JPEG, BMP and PNM "
      "are)");
  // A BMP declaring 100000 x 100000 pixels.
  std::vector<uint8_t> bmp = {'B', 'M', 0, 0, 0, 0, 0, 0, 0, 0, 54, 0, 0, 0, 40, 0, 0, 0};
  for (const uint32_t side : {100000u, 100000u}) {
    for (int i = 0; i < 4; ++i) bmp.push_back(static_cast<uint8_t>(side >> (8 * i)));
  }
  bmp.resize(60, 0);
  EXPECT_EQ(DecodeImage(bmp).status().code(), StatusCode::kResourceExhausted);
}

TEST_F(InputLimitsTest, PnmHeadersAreReadAndHugeOnesRefused) {
  // A 2 x 1 binary PPM decodes; a 20-byte one declaring 20000 x 20000 does not get decoded.
  const std::string small("P6\n# a comment\n2 1\n255\n\xff\x00\x00\x00\xff\x00", 29);
  const std::vector<uint8_t> small_bytes(small.begin(), small.end());
  const Result<ImageHeader> h = ReadImageHeader(small_bytes);
  ASSERT_TRUE(h.ok()) << h.status().ToString();
  EXPECT_EQ(h->format, "PNM");
  EXPECT_EQ(h->width, 2u);
  EXPECT_EQ(h->height, 1u);
  const Result<ImageRgb8> img = DecodeImage(small_bytes);
  ASSERT_TRUE(img.ok()) << img.status().ToString();
  EXPECT_EQ(img->width(), 2);
  EXPECT_EQ(img->at(0, 0, 0), 255);  // red
  EXPECT_EQ(img->at(1, 0, 1), 255);  // green
  const std::string huge = "P6 20000 20000 255\n";
  const Status s = DecodeImage(std::vector<uint8_t>(huge.begin(), huge.end())).status();
  EXPECT_EQ(s.code(), StatusCode::kResourceExhausted) << s.ToString();
  EXPECT_THAT(s.message(), HasSubstr("20000 x 20000"));
  // The byte that ends a number goes with it, as in OpenCV's reader: here the '#' after the
  // width starts no comment, the height is 10500, and 100000 x 10500 is refused before OpenCV
  // allocates 3.15 GB for it (found by the fuzzer; fuzz/regressions/image_codec).
  const std::string glued("P5\n100000#10500P100\n10\0A\0", 25);
  const std::vector<uint8_t> glued_bytes(glued.begin(), glued.end());
  const Result<ImageHeader> g = ReadImageHeader(glued_bytes);
  ASSERT_TRUE(g.ok()) << g.status().ToString();
  EXPECT_EQ(g->width, 100000u);
  EXPECT_EQ(g->height, 10500u);
  const Status gs = DecodeImage(glued_bytes).status();
  EXPECT_EQ(gs.code(), StatusCode::kResourceExhausted) << gs.ToString();
  EXPECT_THAT(gs.message(), HasSubstr("100000 x 10500"));
  for (const std::string& bad :
       std::vector<std::string>{"P6", "P6 12", "P6 99999999999 1 255\n", "P7\nWIDTH 1\n"}) {
    EXPECT_FALSE(ReadImageHeader(std::vector<uint8_t>(bad.begin(), bad.end())).ok()) << bad;
  }
}

TEST_F(InputLimitsTest, PixelLimitIsConfigurable) {
  const Result<std::vector<uint8_t>> png = EncodePng(ImageRgb8(8, 8, 7));
  ASSERT_TRUE(png.ok());
  {
    const ScopedLimit small(MaxImagePixels(), 63);
    const Status s = DecodeImage(*png).status();
    EXPECT_EQ(s.code(), StatusCode::kResourceExhausted);
    EXPECT_THAT(s.message(), HasSubstr("(64) exceeds the limit max_image_pixels = 63"));
    const fs::path path = dir_ / "small.png";
    ASSERT_TRUE(WritePngRgb8(path, ImageRgb8(8, 8, 7)).ok());
    EXPECT_EQ(ReadPngRgb8(path).status().code(), StatusCode::kResourceExhausted);
  }
  const ScopedLimit exact(MaxImagePixels(), 64);
  const Result<ImageRgb8> decoded = DecodeImage(*png);
  ASSERT_TRUE(decoded.ok()) << decoded.status().ToString();
  EXPECT_EQ(*decoded, ImageRgb8(8, 8, 7));
}

TEST_F(InputLimitsTest, RleMaskSizeIsBoundedBeforeAllocating) {
  // One run of 4e9 background pixels would be 4 GB of mask.
  const std::vector<uint32_t> counts = {4000000000u};
  const Status s = RleToMask(counts, 80000, 50000).status();
  EXPECT_EQ(s.code(), StatusCode::kResourceExhausted) << s.ToString();
  EXPECT_THAT(s.message(), HasSubstr("RLE mask of 80000 x 50000 pixels"));
}

TEST_F(InputLimitsTest, PngWritersAreAtomicAndCreateFolders) {
  const fs::path path = dir_ / "a" / "b" / "out.png";
  ASSERT_TRUE(WritePngFile(ImageRgb8(3, 2, 5), path).ok());
  ASSERT_TRUE(WritePngGray16(dir_ / "a" / "d.png", Image<uint16_t>(3, 2, 700)).ok());
  EXPECT_EQ(ReadPngGray16(dir_ / "a" / "d.png").value(), Image<uint16_t>(3, 2, 700));
  EXPECT_EQ(ReadImageFile(path).value(), ImageRgb8(3, 2, 5));
  // Nothing but the results in the folders: no temporary file left behind.
  size_t files = 0;
  for (const auto& e : fs::recursive_directory_iterator(dir_)) files += e.is_regular_file();
  EXPECT_EQ(files, 2u);
  // A write that cannot happen leaves the old file untouched and names the path.
  const fs::path blocker = dir_ / "blocker";
  std::ofstream(blocker) << "x";
  const Status s = WritePngRgb8(blocker / "x.png", ImageRgb8(2, 2));
  EXPECT_EQ(s.code(), StatusCode::kIoError);
  EXPECT_THAT(s.message(), HasSubstr("blocker"));
}

// ---- YAML ---------------------------------------------------------------------------------------

TEST_F(InputLimitsTest, DeepYamlIsRefusedBeforeParsing) {
  const std::string flow = std::string(100000, '[') + std::string(100000, ']');
  const Status s = LoadYamlFile(Write("deep.yaml", "a: " + flow + "\n")).status();
  EXPECT_EQ(s.code(), StatusCode::kResourceExhausted) << s.ToString();
  EXPECT_THAT(s.message(), HasSubstr("max_yaml_depth = 64"));
  EXPECT_THAT(s.message(), HasSubstr("line 1"));

  std::string block;
  for (int i = 0; i < 200; ++i) block += "- ";
  block += "x\n";
  EXPECT_EQ(LoadYamlFile(Write("block.yaml", block)).status().code(),
            StatusCode::kResourceExhausted);
  std::string indented;
  for (int i = 0; i < 100; ++i) indented += std::string(static_cast<size_t>(i), ' ') + "k:\n";
  EXPECT_EQ(LoadYamlFile(Write("indented.yaml", indented)).status().code(),
            StatusCode::kResourceExhausted);
}

TEST_F(InputLimitsTest, YamlDepthCountsOnlyCollections) {
  // Brackets in quotes, comments, plain scalars and block scalars are not collections.
  const std::string text = "a: '" + std::string(200, '[') + "'\n" +  //
                           "b: \"" + std::string(200, '{') + "\"  # " + std::string(200, '[') +
                           "\n" + "c: x" + std::string(200, '[') + "\n" +       //
                           "d: |\n  " + std::string(200, '[') + "\n  more\n" +  //
                           "e: [[1, 2], {f: [3]}]\n" +                          //
                           "g:\n  h:\n    - i: 1\n      j: [1, 2]\n";
  const Result<YAML::Node> node = ParseYaml(text, "'test'");
  ASSERT_TRUE(node.ok()) << node.status().ToString();
  EXPECT_EQ((*node)["d"].as<std::string>().size(), 206u);
  // An upper estimate: the document's line counts as one level.
  EXPECT_TRUE(CheckYamlDepth(std::string(63, '[') + std::string(63, ']'), "'x'").ok());
  EXPECT_EQ(CheckYamlDepth(std::string(65, '[') + std::string(65, ']'), "'x'").code(),
            StatusCode::kResourceExhausted);
}

TEST_F(InputLimitsTest, YamlFileSizeIsBounded) {
  const ScopedLimit small(MaxYamlBytes(), 100);
  const fs::path path = Write("big.yaml", "a: " + std::string(200, 'x') + "\n");
  const Status s = LoadYamlFile(path).status();
  EXPECT_EQ(s.code(), StatusCode::kResourceExhausted) << s.ToString();
  EXPECT_THAT(s.message(), HasSubstr("max_yaml_bytes = 100"));
  EXPECT_THAT(s.message(), HasSubstr(path.string()));
}

TEST_F(InputLimitsTest, TextFromYamlIsEscapedAndShortenedInMessages) {
  const YAML::Node node = YAML::Load("n: \"\\e[2J\\e]0;pwned\\a\"\nbig: " + std::string(300, '9') +
                                     "\n\"\\e[31mkey\": 1\n");
  const Status n = ReadInt(node, "n", "cfg.yaml").status();
  EXPECT_EQ(n.code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(n.message(), Not(HasSubstr("\x1b")));
  EXPECT_THAT(n.message(), Not(HasSubstr("\a")));
  EXPECT_THAT(n.message(), HasSubstr("'\\x1b[2J\\x1b]0;pwned\\x07'"));
  // A 300-digit number is not echoed whole, and does not wrap around.
  const Status big = ReadInt(node, "big", "cfg.yaml").status();
  EXPECT_EQ(big.code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(big.message(), HasSubstr("...(300 bytes)"));
  EXPECT_LT(big.message().size(), 200u);
  const Status keys = RejectUnknownKeys(node, {"n", "big"}, "cfg.yaml");
  EXPECT_THAT(keys.message(), HasSubstr("'\\x1b[31mkey'"));
  EXPECT_THAT(keys.message(), Not(HasSubstr("\x1b")));
  // Malformed YAML: yaml-cpp's message, file, line and column.
  const Status bad = ParseYaml("a: [1,\n\x1b[2J", "'x.yaml'").status();
  EXPECT_EQ(bad.code(), StatusCode::kParseError);
  EXPECT_THAT(bad.message(), Not(HasSubstr("\x1b")));
}

TEST_F(InputLimitsTest, OptionsYamlWithANonScalarKeyIsAnError) {
  const YAML::Node node = YAML::Load("{[a, b]: 1}");
  const Result<OptionValues> values = FlattenYaml(node, "run.yaml");
  ASSERT_FALSE(values.ok());
  EXPECT_EQ(values.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(values.status().message(), HasSubstr("run.yaml"));
}

}  // namespace
}  // namespace avp::io
