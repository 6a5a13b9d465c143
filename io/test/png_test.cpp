#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <limits>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/core/image.h>
#include <avp/core/rng.h>
#include <avp/core/status.h>
#include <avp/io/depth.h>
#include <avp/io/png.h>
#include <avp/test/read_file.h>
#include <avp/test/temp_dir_test.h>

namespace avp::io {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;

// ---- A tiny PNG encoder, independent of libpng: stored (uncompressed) deflate blocks. ----------

uint32_t Crc32(const std::vector<uint8_t>& bytes) {
  uint32_t crc = 0xffffffffu;
  for (const uint8_t b : bytes) {
    crc ^= b;
    for (int k = 0; k < 8; ++k) crc = (crc >> 1) ^ (0xedb88320u & (0u - (crc & 1u)));
  }
  return ~crc;
}

uint32_t Adler32(const std::vector<uint8_t>& bytes) {
  uint32_t a = 1;
  uint32_t b = 0;
  for (const uint8_t x : bytes) {
    a = (a + x) % 65521;
    b = (b + a) % 65521;
  }
  return (b << 16) | a;
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

// `rows` holds the raw scanlines, each starting with its filter byte (0 = none).
std::vector<uint8_t> MakePng(uint32_t width, uint32_t height, uint8_t bit_depth, uint8_t color_type,
                             const std::vector<uint8_t>& rows,
                             const std::vector<uint8_t>& palette = {}) {
  std::vector<uint8_t> png = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  std::vector<uint8_t> ihdr;
  PutU32(ihdr, width);
  PutU32(ihdr, height);
  ihdr.insert(ihdr.end(), {bit_depth, color_type, 0, 0, 0});
  PutChunk(png, "IHDR", ihdr);
  if (!palette.empty()) PutChunk(png, "PLTE", palette);
  // zlib stream: header, one final stored block, Adler-32 of the raw data.
  std::vector<uint8_t> z = {0x78, 0x01, 0x01};
  const auto n = static_cast<uint16_t>(rows.size());
  z.insert(z.end(), {static_cast<uint8_t>(n & 0xff), static_cast<uint8_t>(n >> 8),
                     static_cast<uint8_t>(~n & 0xff), static_cast<uint8_t>((~n >> 8) & 0xff)});
  z.insert(z.end(), rows.begin(), rows.end());
  PutU32(z, Adler32(rows));
  PutChunk(png, "IDAT", z);
  PutChunk(png, "IEND", {});
  return png;
}

class PngTest : public test::TempDirTest {
 protected:
  void WriteBytes(const fs::path& path, const std::vector<uint8_t>& bytes) {
    std::ofstream out(path, std::ios::binary);
    out.write(reinterpret_cast<const char*>(bytes.data()),
              static_cast<std::streamsize>(bytes.size()));
    ASSERT_TRUE(out.good());
  }
  std::vector<uint8_t> ReadBytes(const fs::path& path) {
    const std::string bytes = test::ReadWholeFile(path);
    return {bytes.begin(), bytes.end()};
  }
};

ImageRgb8 TestPattern(int width, int height) {
  ImageRgb8 image(width, height);
  for (int v = 0; v < height; ++v) {
    for (int u = 0; u < width; ++u) {
      for (int c = 0; c < 3; ++c) image(u, v, c) = static_cast<uint8_t>(u * 7 + v * 13 + c * 101);
    }
  }
  return image;
}

// ---- Round trips
// ---------------------------------------------------------------------------------

TEST_F(PngTest, Rgb8RoundTripIsBitExact) {
  // Odd width: rows of 3 * 37 = 111 bytes, not a multiple of 4 or 8.
  const ImageRgb8 image = TestPattern(37, 23);
  const fs::path path = dir_ / "rgb.png";
  ASSERT_TRUE(WritePngRgb8(path, image).ok());
  const Result<ImageRgb8> back = ReadPngRgb8(path);
  ASSERT_TRUE(back.ok()) << back.status().ToString();
  EXPECT_EQ(back->width(), 37);
  EXPECT_EQ(back->height(), 23);
  EXPECT_EQ(*back, image);
  // Channel order on disk is R, G, B: pixel (0, 0) is (0, 101, 202).
  EXPECT_EQ(back->at(0, 0, 0), 0);
  EXPECT_EQ(back->at(0, 0, 1), 101);
  EXPECT_EQ(back->at(0, 0, 2), 202);
}

TEST_F(PngTest, Gray8RoundTripIsBitExact) {
  Image<uint8_t> image(256, 3);
  for (int v = 0; v < 3; ++v) {
    for (int u = 0; u < 256; ++u) image(u, v) = static_cast<uint8_t>(v == 1 ? 255 - u : u);
  }
  const fs::path path = dir_ / "gray8.png";
  ASSERT_TRUE(WritePngGray8(path, image).ok());
  const Result<Image<uint8_t>> back = ReadPngGray8(path);
  ASSERT_TRUE(back.ok()) << back.status().ToString();
  EXPECT_EQ(*back, image);
}

TEST_F(PngTest, Gray16RoundTripIsBitExactAboveEightBits) {
  Image<uint16_t> image(7, 3);
  const uint16_t values[] = {0, 1, 255, 256, 0x1234, 0xff00, 65535};
  for (int u = 0; u < 7; ++u) {
    image(u, 0) = values[u];
    image(u, 1) = static_cast<uint16_t>(1000 + 4321 * u);
    image(u, 2) = static_cast<uint16_t>(65535 - u);
  }
  const fs::path path = dir_ / "gray16.png";
  ASSERT_TRUE(WritePngGray16(path, image).ok());
  const Result<Image<uint16_t>> back = ReadPngGray16(path);
  ASSERT_TRUE(back.ok()) << back.status().ToString();
  EXPECT_EQ(*back, image);
  EXPECT_EQ(back->at(4, 0), 0x1234);
}

TEST_F(PngTest, Gray16RandomRoundTrip) {
  Rng rng(16);
  Image<uint16_t> image(61, 17);
  for (uint16_t& x : image.data()) x = static_cast<uint16_t>(rng.UniformInt(0, 65535));
  const fs::path path = dir_ / "random16.png";
  ASSERT_TRUE(WritePngGray16(path, image).ok());
  EXPECT_EQ(ReadPngGray16(path).value(), image);
}

TEST_F(PngTest, Gray16IsBigEndianOnDisk) {
  // Written by us, read back by libpng as 8-bit RGB: reducing 16 to 8 bits keeps the most
  // significant byte, which is 0x12 only if 0x1234 was stored big-endian.
  Image<uint16_t> image(2, 1);
  image(0, 0) = 0x1234;
  image(1, 0) = 0xab01;
  const fs::path path = dir_ / "endian.png";
  ASSERT_TRUE(WritePngGray16(path, image).ok());
  const ImageRgb8 rgb = ReadPngRgb8(path).value();
  EXPECT_EQ(rgb(0, 0, 0), 0x12);
  EXPECT_EQ(rgb(0, 0, 2), 0x12);
  EXPECT_EQ(rgb(1, 0, 1), 0xab);
}

TEST_F(PngTest, ReadsHandBuiltGray16WithKnownBytes) {
  // Big-endian samples 0x012c = 300 and 0xfffe = 65534, encoded without libpng.
  const fs::path path = dir_ / "hand16.png";
  WriteBytes(path, MakePng(2, 1, 16, 0, {0, 0x01, 0x2c, 0xff, 0xfe}));
  const Result<Image<uint16_t>> image = ReadPngGray16(path);
  ASSERT_TRUE(image.ok()) << image.status().ToString();
  ASSERT_EQ(image->width(), 2);
  ASSERT_EQ(image->height(), 1);
  EXPECT_EQ(image->at(0, 0), 300);
  EXPECT_EQ(image->at(1, 0), 65534);
}

TEST_F(PngTest, ReadRgb8ConvertsOtherFormats) {
  // Gray 8-bit: R = G = B.
  WriteBytes(dir_ / "gray.png", MakePng(2, 1, 8, 0, {0, 17, 200}));
  const ImageRgb8 gray = ReadPngRgb8(dir_ / "gray.png").value();
  EXPECT_EQ(gray.pixel(0, 0)[0], 17);
  EXPECT_EQ(gray.pixel(0, 0)[1], 17);
  EXPECT_EQ(gray.pixel(1, 0)[2], 200);

  // Gray 1-bit: 0 -> 0, 1 -> 255 (scaled, not just unpacked). Bits 1,0,1 then padding.
  WriteBytes(dir_ / "gray1.png", MakePng(3, 1, 1, 0, {0, 0b10100000}));
  const ImageRgb8 bits = ReadPngRgb8(dir_ / "gray1.png").value();
  EXPECT_EQ(bits(0, 0, 0), 255);
  EXPECT_EQ(bits(1, 0, 0), 0);
  EXPECT_EQ(bits(2, 0, 1), 255);

  // RGBA 8-bit: alpha is dropped.
  WriteBytes(dir_ / "rgba.png", MakePng(1, 2, 8, 6, {0, 10, 20, 30, 40, 0, 50, 60, 70, 0}));
  const ImageRgb8 rgba = ReadPngRgb8(dir_ / "rgba.png").value();
  EXPECT_EQ(rgba(0, 0, 0), 10);
  EXPECT_EQ(rgba(0, 0, 2), 30);
  EXPECT_EQ(rgba(0, 1, 0), 50);
  EXPECT_EQ(rgba(0, 1, 2), 70);

  // Palette: indices 1, 0 into {(1, 2, 3), (250, 251, 252)}.
  WriteBytes(dir_ / "palette.png", MakePng(2, 1, 8, 3, {0, 1, 0}, {1, 2, 3, 250, 251, 252}));
  const ImageRgb8 palette = ReadPngRgb8(dir_ / "palette.png").value();
  EXPECT_EQ(palette(0, 0, 0), 250);
  EXPECT_EQ(palette(0, 0, 2), 252);
  EXPECT_EQ(palette(1, 0, 1), 2);
}

TEST_F(PngTest, WritersCreateParentFolders) {
  const fs::path path = dir_ / "a" / "b" / "c" / "image.png";
  ASSERT_TRUE(WritePngGray8(path, Image<uint8_t>(3, 2, 9)).ok());
  EXPECT_TRUE(fs::exists(path));
  EXPECT_EQ(ReadPngGray8(path).value(), Image<uint8_t>(3, 2, 9));
}

// ---- Failures are statuses that name the file ---------------------------------------------------

TEST_F(PngTest, MissingFileIsNotFound) {
  const fs::path path = dir_ / "does_not_exist.png";
  for (const Status& status :
       {ReadPngRgb8(path).status(), ReadPngGray8(path).status(), ReadPngGray16(path).status()}) {
    EXPECT_EQ(status.code(), StatusCode::kNotFound);
    EXPECT_THAT(status.message(), HasSubstr(path.string()));
  }
}

TEST_F(PngTest, TruncatedFileIsAParseErrorAtEveryLength) {
  // Noise does not compress, so the image data spans most of the file.
  Rng rng(1);
  ImageRgb8 image(64, 64);
  for (uint8_t& x : image.data()) x = static_cast<uint8_t>(rng.UniformInt(0, 255));
  const fs::path full = dir_ / "full.png";
  ASSERT_TRUE(WritePngRgb8(full, image).ok());
  const std::vector<uint8_t> bytes = ReadBytes(full);
  ASSERT_GT(bytes.size(), 12000u);

  const fs::path cut = dir_ / "cut.png";
  for (const size_t length : {size_t{0}, size_t{4}, size_t{8}, size_t{20}, size_t{33}, size_t{60},
                              bytes.size() / 2, bytes.size() - 13, bytes.size() - 1}) {
    WriteBytes(cut, std::vector<uint8_t>(bytes.begin(), bytes.begin() + length));
    const Result<ImageRgb8> result = ReadPngRgb8(cut);
    ASSERT_FALSE(result.ok()) << "truncated to " << length << " of " << bytes.size() << " bytes";
    EXPECT_EQ(result.status().code(), StatusCode::kParseError) << result.status().ToString();
    EXPECT_THAT(result.status().message(), HasSubstr(cut.string()));
  }
}

TEST_F(PngTest, CorruptImageDataIsAParseError) {
  const fs::path path = dir_ / "corrupt.png";
  ASSERT_TRUE(WritePngRgb8(path, TestPattern(32, 32)).ok());
  std::vector<uint8_t> bytes = ReadBytes(path);
  bytes[bytes.size() / 2] ^= 0xff;  // inside IDAT: the chunk CRC no longer matches
  WriteBytes(path, bytes);
  const Status status = ReadPngRgb8(path).status();
  EXPECT_EQ(status.code(), StatusCode::kParseError);
  EXPECT_THAT(status.message(), HasSubstr(path.string()));
}

TEST_F(PngTest, NonPngFileIsAParseError) {
  const fs::path path = dir_ / "notes.png";
  {
    std::ofstream out(path);
    out << "this is a text file, not an image\n";
  }
  for (const Status& status :
       {ReadPngRgb8(path).status(), ReadPngGray8(path).status(), ReadPngGray16(path).status()}) {
    EXPECT_EQ(status.code(), StatusCode::kParseError);
    EXPECT_THAT(status.message(), HasSubstr(path.string()));
  }
}

TEST_F(PngTest, WrongChannelTypeIsInvalidArgument) {
  const fs::path rgb = dir_ / "rgb.png";
  const fs::path gray8 = dir_ / "gray8.png";
  const fs::path gray16 = dir_ / "gray16.png";
  ASSERT_TRUE(WritePngRgb8(rgb, TestPattern(4, 4)).ok());
  ASSERT_TRUE(WritePngGray8(gray8, Image<uint8_t>(4, 4, 1)).ok());
  ASSERT_TRUE(WritePngGray16(gray16, Image<uint16_t>(4, 4, 1000)).ok());

  const Status rgb_as_gray = ReadPngGray8(rgb).status();
  EXPECT_EQ(rgb_as_gray.code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(rgb_as_gray.message(), HasSubstr(rgb.string()));
  EXPECT_THAT(rgb_as_gray.message(), HasSubstr("expected single-channel 8-bit"));
  EXPECT_EQ(ReadPngGray16(rgb).status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(ReadPngGray16(gray8).status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(ReadPngGray8(gray16).status().code(), StatusCode::kInvalidArgument);
  // Gray with alpha is not single-channel either.
  WriteBytes(dir_ / "ga.png", MakePng(1, 1, 8, 4, {0, 9, 255}));
  EXPECT_EQ(ReadPngGray8(dir_ / "ga.png").status().code(), StatusCode::kInvalidArgument);
  // Reading as RGB accepts all of them.
  EXPECT_EQ(ReadPngRgb8(gray8).value(), ImageRgb8(4, 4, 1));
}

TEST_F(PngTest, WritingAnEmptyImageIsInvalidArgument) {
  const fs::path path = dir_ / "empty.png";
  const Status status = WritePngGray8(path, Image<uint8_t>());
  EXPECT_EQ(status.code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(status.message(), HasSubstr(path.string()));
  EXPECT_FALSE(WritePngRgb8(path, ImageRgb8(0, 5)).ok());
}

TEST_F(PngTest, UnwritablePathIsAnError) {
  // The parent "folder" is a regular file.
  const fs::path blocker = dir_ / "blocker";
  { std::ofstream(blocker) << "x"; }
  const fs::path path = blocker / "image.png";
  const Status status = WritePngGray8(path, Image<uint8_t>(2, 2));
  EXPECT_FALSE(status.ok());
  EXPECT_EQ(status.code(), StatusCode::kIoError);
  EXPECT_THAT(status.message(), HasSubstr("blocker"));
}

// ---- Depth in millimetres -----------------------------------------------------------------------

TEST(DepthTest, MetresToMillimetresRoundsToNearest) {
  DepthImage depth(6, 1);
  depth(0, 0) = 1.0f;
  depth(1, 0) = 1.2344f;   // 1234.4 mm -> 1234
  depth(2, 0) = 1.2346f;   // 1234.6 mm -> 1235
  depth(3, 0) = 0.0004f;   // 0.4 mm -> 0
  depth(4, 0) = 0.0016f;   // 1.6 mm -> 2
  depth(5, 0) = 65.5344f;  // 65534.4 mm -> 65534
  const Image<uint16_t> mm = DepthToMillimetres(depth);
  ASSERT_TRUE(mm.SameSizeAs(depth));
  EXPECT_EQ(mm(0, 0), 1000);
  EXPECT_EQ(mm(1, 0), 1234);
  EXPECT_EQ(mm(2, 0), 1235);
  EXPECT_EQ(mm(3, 0), 0);
  EXPECT_EQ(mm(4, 0), 2);
  EXPECT_EQ(mm(5, 0), 65534);
}

TEST(DepthTest, InvalidDepthBecomesZero) {
  DepthImage depth(5, 1);
  depth(0, 0) = 0.0f;
  depth(1, 0) = std::numeric_limits<float>::quiet_NaN();
  depth(2, 0) = -1.5f;
  depth(3, 0) = std::numeric_limits<float>::infinity();
  depth(4, 0) = -0.0f;
  const Image<uint16_t> mm = DepthToMillimetres(depth);
  for (const uint16_t x : mm.data()) EXPECT_EQ(x, 0);
}

TEST(DepthTest, FarDepthSaturates) {
  DepthImage depth(4, 1);
  depth(0, 0) = 65.535f;
  depth(1, 0) = 65.6f;
  depth(2, 0) = 100.0f;
  depth(3, 0) = 1e6f;
  const Image<uint16_t> mm = DepthToMillimetres(depth);
  for (const uint16_t x : mm.data()) EXPECT_EQ(x, 65535);
}

TEST(DepthTest, MillimetresToMetresAndBackIsExactForEveryValue) {
  Image<uint16_t> mm(256, 256);
  for (int i = 0; i < 65536; ++i) mm.data()[static_cast<size_t>(i)] = static_cast<uint16_t>(i);
  const DepthImage m = DepthFromMillimetres(mm);
  ASSERT_TRUE(m.SameSizeAs(mm));
  EXPECT_EQ(m(0, 0), 0.0f);  // 0 stays invalid
  EXPECT_FALSE(IsValidDepth(m(0, 0)));
  EXPECT_NEAR(m(1, 0), 0.001f, 1e-9f);
  EXPECT_NEAR(m.data()[1234], 1.234f, 1e-6f);
  EXPECT_NEAR(m.data()[65535], 65.535f, 1e-5f);
  EXPECT_EQ(DepthToMillimetres(m), mm);
}

TEST_F(PngTest, DepthSurvivesA16BitPng) {
  DepthImage depth(3, 2, 0.0f);
  depth(0, 0) = 0.5f;
  depth(1, 0) = 2.25f;
  depth(2, 1) = 3.0f;
  const fs::path path = dir_ / "depth.png";
  ASSERT_TRUE(WritePngGray16(path, DepthToMillimetres(depth)).ok());
  const DepthImage back = DepthFromMillimetres(ReadPngGray16(path).value());
  EXPECT_NEAR(back(0, 0), 0.5f, 1e-6f);
  EXPECT_NEAR(back(1, 0), 2.25f, 1e-6f);
  EXPECT_NEAR(back(2, 1), 3.0f, 1e-6f);
  EXPECT_EQ(back(1, 1), 0.0f);
}

}  // namespace
}  // namespace avp::io
