#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <numbers>
#include <string>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <avp/core/camera.h>
#include <avp/core/rng.h>
#include <avp/core/status.h>
#include <avp/core/transform.h>
#include <avp/io/json.h>
#include <avp/test/read_file.h>
#include <avp/test/temp_dir_test.h>

namespace avp::io {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;
using ::testing::Not;

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kPi = std::numbers::pi;

class JsonFileTest : public test::TempDirTest {};

CameraIntrinsics OddIntrinsics() {
  CameraIntrinsics K;
  K.width = 1281;
  K.height = 719;
  K.fx = 912.3456789012345;
  K.fy = 911.0000000000001;
  K.cx = 640.123;
  K.cy = 358.9;
  K.min_depth_m = 0.07;
  K.max_depth_m = 6.5;
  return K;
}

Status IntrinsicsError(const nlohmann::json& j) { return IntrinsicsFromJson(j).status(); }
Status TransformError(const nlohmann::json& j) { return TransformFromJson(j).status(); }

// ---- Camera intrinsics
// ---------------------------------------------------------------------------

TEST(JsonTest, IntrinsicsToJsonFields) {
  const nlohmann::json j = ToJson(CameraIntrinsics::RealSenseD435());
  EXPECT_EQ(j.at("width").get<int>(), 640);
  EXPECT_EQ(j.at("height").get<int>(), 480);
  EXPECT_EQ(j.at("fx").get<double>(), 615.0);
  EXPECT_EQ(j.at("cy").get<double>(), 239.5);
  EXPECT_EQ(j.at("max_depth_m").get<double>(), 3.0);
  // K is row-major: [[fx, 0, cx], [0, fy, cy], [0, 0, 1]].
  EXPECT_EQ(j.at("K").at(0).at(2).get<double>(), 319.5);
  EXPECT_EQ(j.at("K").at(1).at(1).get<double>(), 615.0);
  EXPECT_EQ(j.at("K").at(2).at(2).get<double>(), 1.0);
  EXPECT_EQ(j.at("K").at(1).at(0).get<double>(), 0.0);
}

TEST(JsonTest, IntrinsicsRoundTripIsExact) {
  for (const CameraIntrinsics& K : {CameraIntrinsics::RealSenseD435(), OddIntrinsics(),
                                    CameraIntrinsics::FromHorizontalFov(100, 50, 73.3)}) {
    const Result<CameraIntrinsics> back = IntrinsicsFromJson(ToJson(K));
    ASSERT_TRUE(back.ok()) << back.status().ToString();
    EXPECT_EQ(*back, K) << ToString(*back) << " vs " << ToString(K);
    // Also through text.
    EXPECT_EQ(IntrinsicsFromJson(nlohmann::json::parse(ToJson(K).dump())).value(), K);
  }
}

TEST(JsonTest, IntrinsicsDepthRangeIsOptional) {
  nlohmann::json j = ToJson(OddIntrinsics());
  j.erase("min_depth_m");
  j.erase("max_depth_m");
  const CameraIntrinsics K = IntrinsicsFromJson(j).value();
  EXPECT_EQ(K.min_depth_m, CameraIntrinsics().min_depth_m);
  EXPECT_EQ(K.max_depth_m, CameraIntrinsics().max_depth_m);
  EXPECT_EQ(K.fx, OddIntrinsics().fx);
}

TEST(JsonTest, IntrinsicsMissingFieldIsNamed) {
  for (const char* field : {"width", "height", "fx", "fy", "cx", "cy"}) {
    nlohmann::json j = ToJson(OddIntrinsics());
    j.erase(field);
    const Status status = IntrinsicsError(j);
    EXPECT_EQ(status.code(), StatusCode::kInvalidArgument) << field;
    EXPECT_THAT(status.message(), HasSubstr(std::string("missing field '") + field + "'"));
  }
}

TEST(JsonTest, IntrinsicsNonFiniteFieldIsNamed) {
  nlohmann::json j = ToJson(OddIntrinsics());
  j["cx"] = kNaN;
  EXPECT_THAT(IntrinsicsError(j).message(), HasSubstr("field 'cx' must be a finite number"));
  j = ToJson(OddIntrinsics());
  j["max_depth_m"] = std::numeric_limits<double>::infinity();
  EXPECT_THAT(IntrinsicsError(j).message(), HasSubstr("'max_depth_m'"));
}

TEST(JsonTest, IntrinsicsWrongTypeIsNamedWithTheValue) {
  nlohmann::json j = ToJson(OddIntrinsics());
  j["fx"] = "615";
  const Status status = IntrinsicsError(j);
  EXPECT_EQ(status.code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(status.message(), HasSubstr("field 'fx' must be a finite number, got \"615\""));
  j = ToJson(OddIntrinsics());
  j["height"] = nlohmann::json::array({480});
  EXPECT_THAT(IntrinsicsError(j).message(), HasSubstr("field 'height'"));
  EXPECT_THAT(IntrinsicsError(nlohmann::json::array({1, 2})).message(), HasSubstr("'width'"));
}

TEST(JsonTest, IntrinsicsNonIntegerOrOutOfRangeSize) {
  nlohmann::json j = ToJson(OddIntrinsics());
  j["width"] = 640.5;
  EXPECT_THAT(IntrinsicsError(j).message(), HasSubstr("width (640.5)"));
  j = ToJson(OddIntrinsics());
  j["height"] = 1e10;  // an integer, but not an int
  const Status huge = IntrinsicsError(j);
  EXPECT_EQ(huge.code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(huge.message(), HasSubstr("height"));
  EXPECT_THAT(huge.message(), HasSubstr("10000000000"));
}

TEST(JsonTest, IntrinsicsAreValidated) {
  nlohmann::json j = ToJson(OddIntrinsics());
  j["width"] = -13;
  j["fy"] = -2.0;
  const Status status = IntrinsicsError(j);
  EXPECT_EQ(status.code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(status.message(), HasSubstr("width (-13) must be > 0"));
  EXPECT_THAT(status.message(), HasSubstr("fy (-2)"));
}

// ---- Transforms ---------------------------------------------------------------------------------

TEST(JsonTest, TransformToJsonFields) {
  const RigidTransform X = RigidTransform::FromRpy(0, 0, kPi / 2, {1, 2, 3});
  const nlohmann::json j = ToJson(X);
  EXPECT_EQ(j.at("translation_m"), nlohmann::json::array({1.0, 2.0, 3.0}));
  // 90 deg about z: q = (cos 45, 0, 0, sin 45), w first.
  EXPECT_NEAR(j.at("quaternion_wxyz").at(0).get<double>(), std::sqrt(0.5), 1e-15);
  EXPECT_NEAR(j.at("quaternion_wxyz").at(3).get<double>(), std::sqrt(0.5), 1e-15);
  EXPECT_NEAR(j.at("rpy_rad").at(2).get<double>(), kPi / 2, 1e-15);
  EXPECT_NEAR(j.at("matrix").at(0).at(1).get<double>(), -1.0, 1e-15);
  EXPECT_EQ(j.at("matrix").at(1).at(3).get<double>(), 2.0);
  EXPECT_EQ(j.at("matrix").at(3), nlohmann::json::array({0.0, 0.0, 0.0, 1.0}));
}

TEST(JsonTest, TransformRoundTripThroughQuaternionAndMatrix) {
  Rng rng(8);
  for (int i = 0; i < 100; ++i) {
    const RigidTransform X = RigidTransform::FromRpy(
        rng.Uniform(-kPi, kPi), rng.Uniform(-kPi / 2, kPi / 2), rng.Uniform(-kPi, kPi),
        Eigen::Vector3d(rng.Uniform(-9, 9), rng.Uniform(-9, 9), rng.Uniform(-9, 9)));
    const nlohmann::json j = nlohmann::json::parse(ToJson(X).dump());
    const Result<RigidTransform> back = TransformFromJson(j);
    ASSERT_TRUE(back.ok()) << back.status().ToString();
    EXPECT_LT((back->ToMatrix4() - X.ToMatrix4()).cwiseAbs().maxCoeff(), 1e-14);

    nlohmann::json matrix_only = j;
    matrix_only.erase("translation_m");
    matrix_only.erase("quaternion_wxyz");
    const Result<RigidTransform> from_matrix = TransformFromJson(matrix_only);
    ASSERT_TRUE(from_matrix.ok()) << from_matrix.status().ToString();
    EXPECT_LT((from_matrix->ToMatrix4() - X.ToMatrix4()).cwiseAbs().maxCoeff(), 1e-15);
  }
}

TEST(JsonTest, TransformQuaternionIsNormalisedWithinTolerance) {
  // Six printed digits (norm off by ~1e-7) are accepted and normalised.
  const nlohmann::json j = {{"translation_m", {0, 0, 0}},
                            {"quaternion_wxyz", {0.707107, 0, 0, 0.707107}}};
  const RigidTransform X = TransformFromJson(j).value();
  EXPECT_NEAR(X.AngleTo(RigidTransform::FromRpy(0, 0, kPi / 2, {0, 0, 0})), 0.0, 1e-12);
}

TEST(JsonTest, TransformErrorsNameTheField) {
  const nlohmann::json good = ToJson(RigidTransform::FromRpy(0.1, 0.2, 0.3, {1, 2, 3}));

  nlohmann::json j = good;
  j.erase("quaternion_wxyz");
  j.erase("matrix");
  Status status = TransformError(j);
  EXPECT_EQ(status.code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(status.message(), HasSubstr("'quaternion_wxyz'"));

  j = good;
  j["translation_m"] = {1, 2};
  EXPECT_THAT(TransformError(j).message(),
              HasSubstr("field 'translation_m' must be an array of 3 numbers, got [1,2]"));

  j = good;
  j["translation_m"] = {1, "two", 3};
  EXPECT_THAT(TransformError(j).message(), HasSubstr("field 'translation_m' must hold finite"));

  j = good;
  j["quaternion_wxyz"] = {1, 0, 0, kNaN};
  EXPECT_THAT(TransformError(j).message(), HasSubstr("'quaternion_wxyz'"));

  j = good;
  j["quaternion_wxyz"] = {2, 0, 0, 0};
  status = TransformError(j);
  EXPECT_THAT(status.message(), HasSubstr("quaternion_wxyz [2, 0, 0, 0] must have unit norm"));

  EXPECT_THAT(TransformError(nlohmann::json::object()).message(),
              HasSubstr("expected 'translation_m' + 'quaternion_wxyz' or a 4x4 'matrix'"));
  EXPECT_FALSE(TransformFromJson(nlohmann::json(3.5)).ok());
}

TEST(JsonTest, TransformMatrixErrorsNameTheMatrix) {
  nlohmann::json j = {{"matrix", {{1, 0, 0, 0}, {0, 1, 0, 0}, {0, 0, 2, 0}, {0, 0, 0, 1}}}};
  Status status = TransformError(j);
  EXPECT_EQ(status.code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(status.message(), HasSubstr("'matrix' is not a rigid transform"));

  j = {{"matrix", {{1, 0, 0, 0}, {0, 1, 0, 0}, {0, 0, 1, 0}, {0, 0, 0.5, 1}}}};
  EXPECT_THAT(TransformError(j).message(), HasSubstr("'matrix'"));

  j = {{"matrix", {{1, 0, 0, 0}, {0, 1, "x", 0}, {0, 0, 1, 0}, {0, 0, 0, 1}}}};
  status = TransformError(j);
  EXPECT_EQ(status.code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(status.message(), HasSubstr("'matrix[1]'"));
  EXPECT_THAT(status.message(), HasSubstr("\"x\""));

  j = {{"matrix", {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}, {0, 0, 0}}}};
  EXPECT_THAT(TransformError(j).message(),
              HasSubstr("'matrix[0]' must be an array of 4 numbers, got [1,0,0]"));
}

// ---- Files --------------------------------------------------------------------------------------

TEST_F(JsonFileTest, WriteAndReadBack) {
  const fs::path path = dir_ / "nested" / "dir" / "camera.json";
  const nlohmann::json j = ToJson(OddIntrinsics());
  ASSERT_TRUE(WriteJsonFile(path, j).ok());
  const std::string text = test::ReadWholeFile(path);
  EXPECT_EQ(text, j.dump(2) + "\n");  // pretty-printed with 2 spaces, trailing newline
  EXPECT_THAT(text, HasSubstr("\n  \"cx\": 640.123"));
  const Result<nlohmann::json> back = ReadJsonFile(path);
  ASSERT_TRUE(back.ok()) << back.status().ToString();
  EXPECT_EQ(*back, j);
  EXPECT_EQ(IntrinsicsFromJson(*back).value(), OddIntrinsics());
}

TEST_F(JsonFileTest, MissingFileIsNotFound) {
  const fs::path path = dir_ / "missing.json";
  const Status status = ReadJsonFile(path).status();
  EXPECT_EQ(status.code(), StatusCode::kNotFound);
  EXPECT_THAT(status.message(), HasSubstr(path.string()));
}

TEST_F(JsonFileTest, MalformedFileIsAParseErrorNamingTheFile) {
  const fs::path path = dir_ / "broken.json";
  {
    std::ofstream out(path);
    out << "{\n  \"fx\": 615,\n  \"fy\": \n}\n";
  }
  const Status status = ReadJsonFile(path).status();
  EXPECT_EQ(status.code(), StatusCode::kParseError);
  EXPECT_THAT(status.message(), HasSubstr(path.string()));
  EXPECT_THAT(status.message(), HasSubstr("line 4"));  // nlohmann's position of the error

  {
    std::ofstream out(path);  // empty file
  }
  EXPECT_EQ(ReadJsonFile(path).status().code(), StatusCode::kParseError);
}

TEST_F(JsonFileTest, UnwritablePathIsAnIoError) {
  const fs::path blocker = dir_ / "blocker";
  { std::ofstream(blocker) << "x"; }
  const fs::path path = blocker / "out.json";
  const Status status = WriteJsonFile(path, nlohmann::json::object());
  EXPECT_EQ(status.code(), StatusCode::kIoError);
  EXPECT_THAT(status.message(), HasSubstr(path.string()));
}

TEST_F(JsonFileTest, AFolderIsNotMissingAndFileBytesAreEscaped) {
  const Status folder = ReadJsonFile(dir_).status();
  EXPECT_EQ(folder.code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(folder.message(), HasSubstr("is a folder, not a JSON file"));
  EXPECT_THAT(folder.message(), Not(HasSubstr("does not exist")));
  // A crafted file cannot send escape sequences to the terminal through the parse error.
  const fs::path path = dir_ / "evil.json";
  // (nlohmann writes C0 controls as <U+001B> itself, but passes other bytes through: 0x9b is
  // the one-byte CSI of many terminals.)
  std::ofstream(path) << "{\"a\": \x9b[2Jnope}";
  const Status s = ReadJsonFile(path).status();
  EXPECT_EQ(s.code(), StatusCode::kParseError);
  EXPECT_THAT(s.message(), Not(HasSubstr("\x9b")));
  EXPECT_THAT(s.message(), HasSubstr("\\x9b"));
}

TEST_F(JsonFileTest, InvalidUtf8IsWrittenReplacedNotThrown) {
  const fs::path path = dir_ / "record.json";
  const nlohmann::json j = {{"scene", std::string("plant\xff\xfe")}};
  ASSERT_TRUE(WriteJsonFile(path, j).ok());
  const Result<nlohmann::json> back = ReadJsonFile(path);
  ASSERT_TRUE(back.ok()) << back.status().ToString();
  EXPECT_EQ((*back)["scene"], "plant\xef\xbf\xbd\xef\xbf\xbd");  // U+FFFD twice
}

}  // namespace
}  // namespace avp::io
