#include <cstdint>
#include <fstream>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include <avp/io/image_codec.h>
#include <avp/test/temp_dir_test.h>

namespace avp::io {
namespace {

using ::testing::HasSubstr;

ImageRgb8 TestImage() {
  ImageRgb8 rgb(5, 3);
  for (int v = 0; v < 3; ++v) {
    for (int u = 0; u < 5; ++u) {
      rgb.at(u, v, 0) = static_cast<uint8_t>(40 * u);
      rgb.at(u, v, 1) = static_cast<uint8_t>(60 * v);
      rgb.at(u, v, 2) = static_cast<uint8_t>(7 + u + v);
    }
  }
  rgb.at(0, 0, 0) = 255;  // pixel (0, 0) is pure red
  rgb.at(0, 0, 1) = 0;
  rgb.at(0, 0, 2) = 0;
  return rgb;
}

class ImageIoTest : public avp::test::TempDirTest {};

TEST_F(ImageIoTest, PngBytesRoundTripAndAreStoredAsRgb) {
  const ImageRgb8 rgb = TestImage();
  const auto png = EncodePng(rgb);
  ASSERT_TRUE(png.ok()) << png.status().ToString();
  ASSERT_GT(png->size(), 8u);
  EXPECT_EQ((*png)[1], 'P');  // \x89PNG
  const auto back = DecodeImage(*png);
  ASSERT_TRUE(back.ok()) << back.status().ToString();
  EXPECT_EQ(*back, rgb);
  // An independent decoder (OpenCV gives BGR) sees red at (0, 0): the channels are not swapped.
  const cv::Mat bgr = cv::imdecode(*png, cv::IMREAD_COLOR);
  ASSERT_EQ(bgr.cols, 5);
  ASSERT_EQ(bgr.rows, 3);
  const cv::Vec3b p = bgr.at<cv::Vec3b>(0, 0);
  EXPECT_EQ(p[0], 0);
  EXPECT_EQ(p[1], 0);
  EXPECT_EQ(p[2], 255);
  const cv::Vec3b q = bgr.at<cv::Vec3b>(2, 4);  // row 2, column 4
  EXPECT_EQ(q[2], 160);                         // R = 40·4
  EXPECT_EQ(q[1], 120);                         // G = 60·2
  EXPECT_EQ(q[0], 13);                          // B = 7 + 4 + 2
}

TEST_F(ImageIoTest, ReadsPngAndJpegFilesAsRgb) {
  const ImageRgb8 rgb = TestImage();
  const auto png_path = dir_ / "test.png";
  ASSERT_TRUE(WritePngFile(rgb, png_path).ok());
  const auto png = ReadImageFile(png_path);
  ASSERT_TRUE(png.ok()) << png.status().ToString();
  EXPECT_EQ(*png, rgb);

  // A JPEG written by OpenCV from a BGR image of one colour: R 200, G 50, B 10 (lossy: ±3).
  const auto jpg_path = dir_ / "test.jpg";
  ASSERT_TRUE(cv::imwrite(jpg_path.string(), cv::Mat(16, 24, CV_8UC3, cv::Scalar(10, 50, 200))));
  const auto jpg = ReadImageFile(jpg_path);
  ASSERT_TRUE(jpg.ok()) << jpg.status().ToString();
  ASSERT_EQ(jpg->width(), 24);
  ASSERT_EQ(jpg->height(), 16);
  EXPECT_NEAR(jpg->at(8, 8, 0), 200, 3);
  EXPECT_NEAR(jpg->at(8, 8, 1), 50, 3);
  EXPECT_NEAR(jpg->at(8, 8, 2), 10, 3);

  // Grey PNGs are expanded to three equal channels.
  const auto grey_path = dir_ / "grey.png";
  ASSERT_TRUE(cv::imwrite(grey_path.string(), cv::Mat(2, 3, CV_8UC1, cv::Scalar(77))));
  const auto grey = ReadImageFile(grey_path);
  ASSERT_TRUE(grey.ok());
  EXPECT_EQ(*grey, ImageRgb8(3, 2, 77));
}

TEST_F(ImageIoTest, ErrorsNameTheFile) {
  const auto missing = ReadImageFile(dir_ / "nope.png");
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.status().code(), StatusCode::kNotFound);
  EXPECT_THAT(missing.status().message(), HasSubstr((dir_ / "nope.png").string()));

  const auto text = Write("not_an_image.png", "hello, this is not a PNG");
  const auto undecodable = ReadImageFile(text);
  ASSERT_FALSE(undecodable.ok());
  EXPECT_EQ(undecodable.status().code(), StatusCode::kParseError);
  EXPECT_THAT(undecodable.status().message(), HasSubstr(text.string()));
  EXPECT_THAT(undecodable.status().message(), HasSubstr("undecodable image file"));
  EXPECT_THAT(undecodable.status().message(),
              HasSubstr("(24 bytes): not a PNG, JPEG, BMP or PNM image"));

  const auto empty = Write("empty.jpg", "");
  const auto empty_result = ReadImageFile(empty);
  ASSERT_FALSE(empty_result.ok());
  EXPECT_EQ(empty_result.status().code(), StatusCode::kParseError);
  EXPECT_EQ(empty_result.status().message(), "image file " + empty.string() + " is empty");

  const auto folder = ReadImageFile(dir_);
  ASSERT_FALSE(folder.ok());
  EXPECT_EQ(folder.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(folder.status().message(), HasSubstr("is a folder, not an image file"));
}

TEST_F(ImageIoTest, UndecodableBytesSayHowMany) {
  const std::vector<uint8_t> junk = {1, 2, 3, 4, 5};
  const auto r = DecodeImage(junk);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kParseError);
  EXPECT_EQ(r.status().message(), "undecodable image (5 bytes): not a PNG, JPEG, BMP or PNM image");
  const auto none = DecodeImage({});
  ASSERT_FALSE(none.ok());
  EXPECT_EQ(none.status().message(), "undecodable image (0 bytes)");
  // A truncated PNG.
  std::vector<uint8_t> png = *EncodePng(TestImage());
  png.resize(png.size() / 2);
  const auto truncated = DecodeImage(png);
  ASSERT_FALSE(truncated.ok());
  EXPECT_EQ(truncated.status().message(),
            "undecodable image (" + std::to_string(png.size()) + " bytes)");
}

TEST_F(ImageIoTest, ATruncatedJpegIsRefusedAsATruncatedPngIs) {
  ImageRgb8 big(160, 120);  // entropy-coded data of several kB: the cuts land in it
  for (int v = 0; v < big.height(); ++v) {
    for (int u = 0; u < big.width(); ++u) {
      big.at(u, v, 0) = static_cast<uint8_t>(u * 7 + v * 13);
      big.at(u, v, 1) = static_cast<uint8_t>(u * v);
      big.at(u, v, 2) = 90;
    }
  }
  const Result<std::vector<uint8_t>> jpeg = EncodeJpeg(big, 90);
  ASSERT_TRUE(jpeg.ok());
  EXPECT_TRUE(DecodeImage(*jpeg).ok());
  // Cut in the entropy-coded data, and just before the end-of-image marker.
  for (const size_t keep : {jpeg->size() * 3 / 4, jpeg->size() - 2}) {
    const std::vector<uint8_t> cut(jpeg->begin(), jpeg->begin() + static_cast<long>(keep));
    const Result<ImageRgb8> r = DecodeImage(cut);
    ASSERT_FALSE(r.ok()) << keep;
    EXPECT_THAT(r.status().message(), HasSubstr("is truncated")) << keep;
    EXPECT_THAT(r.status().message(), HasSubstr(std::to_string(keep) + " bytes")) << keep;
  }
  // Bytes after the end-of-image marker (some cameras append metadata) are fine.
  std::vector<uint8_t> padded = *jpeg;
  padded.insert(padded.end(), {0, 0, 0, 0});
  EXPECT_TRUE(DecodeImage(padded).ok());
}

TEST_F(ImageIoTest, EncodeAndWriteErrors) {
  const auto empty = EncodePng(ImageRgb8());
  ASSERT_FALSE(empty.ok());
  EXPECT_EQ(empty.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(empty.status().message(), HasSubstr("0 x 0"));

  // The parent "folder" is a file: it cannot be created.
  Write("blocker", "x");
  const auto bad_path = dir_ / "blocker" / "out.png";
  const Status s = WritePngFile(TestImage(), bad_path);
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.code(), StatusCode::kIoError);
  EXPECT_THAT(s.message(), HasSubstr(bad_path.string()));
}

}  // namespace
}  // namespace avp::io
