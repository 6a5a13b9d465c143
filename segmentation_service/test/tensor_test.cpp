// Tensors, BYTES elements, parameters and the protobuf conversion (raw and typed contents).
#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/segmentation_service/tensor.h>

#include "proto_convert.h"

namespace avp::segmentation_service {
namespace {

using ::testing::HasSubstr;

TEST(DataTypeTest, NamesRoundTripAndSizes) {
  for (const char* name : {"BOOL", "UINT8", "UINT16", "UINT32", "UINT64", "INT8", "INT16", "INT32",
                           "INT64", "FP16", "FP32", "FP64", "BF16", "BYTES"}) {
    const auto t = DataTypeFromString(name);
    ASSERT_TRUE(t.has_value()) << name;
    EXPECT_EQ(ToString(*t), name);
  }
  EXPECT_FALSE(DataTypeFromString("fp32").has_value());
  EXPECT_EQ(ElementSize(DataType::kUint16), 2u);
  EXPECT_EQ(ElementSize(DataType::kFp64), 8u);
  EXPECT_EQ(ElementSize(DataType::kBytes), 0u);
}

TEST(TensorTest, BytesElementsRoundTripWithLittleEndianLengths) {
  const std::vector<std::string> elements = {"tomato", "", "green apple, ripe",
                                             std::string(300, 'x')};
  const Tensor t = MakeBytesTensor("labels", elements);
  EXPECT_EQ(t.shape, (std::vector<int64_t>{4}));
  EXPECT_EQ(t.data.substr(0, 4), std::string("\x06\x00\x00\x00", 4));
  EXPECT_EQ(t.data.substr(4 + 6 + 4 + 0 + 4 + 17, 4), std::string("\x2c\x01\x00\x00", 4));
  const auto back = ReadBytesElements(t);
  ASSERT_TRUE(back.ok()) << back.status().ToString();
  EXPECT_EQ(*back, elements);
  EXPECT_TRUE(CheckTensor(t, "output").ok());
}

TEST(TensorTest, MalformedBytesAreErrorsNamingTheTensor) {
  Tensor t = MakeBytesTensor("prompt", {"tomato"});
  t.data.pop_back();
  auto r = ReadBytesElements(t);
  ASSERT_FALSE(r.ok());
  EXPECT_THAT(r.status().message(), HasSubstr("'prompt'"));
  EXPECT_THAT(r.status().message(), HasSubstr("claims 6 bytes but only 5 are left"));

  t = MakeBytesTensor("prompt", {"a", "b"});
  t.shape = {3};
  r = ReadBytesElements(t);
  ASSERT_FALSE(r.ok());
  EXPECT_THAT(r.status().message(), HasSubstr("needs 3 BYTES elements, the contents hold 2"));

  t.data = "ab";
  t.shape = {1};
  r = ReadBytesElements(t);
  ASSERT_FALSE(r.ok());
  EXPECT_THAT(r.status().message(), HasSubstr("truncated 4-byte length prefix"));
}

TEST(TensorTest, CheckTensorComparesShapeAndBytes) {
  const std::vector<float> values(15, 1.0f);
  Tensor t = MakeTensor<float>("depth", DataType::kFp32, {4, 4}, std::span<const float>(values));
  const Status s = CheckTensor(t, "input");
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(s.message(), "input 'depth': shape [4, 4] of FP32 needs 64 bytes, got 60");
  t.shape = {3, 5};
  EXPECT_TRUE(CheckTensor(t, "input").ok());
  t.shape = {-1, 5};
  EXPECT_THAT(CheckTensor(t, "input").message(), HasSubstr("negative or huge dimension"));
  EXPECT_EQ(t.Describe(), "'depth' FP32 [-1, 5]");
}

TEST(TensorTest, ValuesRoundTripLittleEndian) {
  const std::vector<uint16_t> ids = {0, 1, 258, 65535};
  const Tensor t = MakeTensor<uint16_t>("instance_ids", DataType::kUint16, {2, 2},
                                        std::span<const uint16_t>(ids));
  EXPECT_EQ(t.data, std::string("\x00\x00\x01\x00\x02\x01\xff\xff", 8));
  auto back = ReadValues<uint16_t>(t);
  ASSERT_TRUE(back.ok());
  EXPECT_EQ(*back, ids);
  auto wrong = ReadValues<float>(t);
  ASSERT_FALSE(wrong.ok());
  EXPECT_THAT(wrong.status().message(), HasSubstr("'instance_ids' UINT16 [2, 2]"));
}

TEST(ParameterTest, TypesAndConversions) {
  Parameters p;
  p["seed_bits"] = int64_t{-1};
  p["seed_u"] = uint64_t{18446744073709551615ull};
  p["seed_s"] = std::string("18446744073709551615");
  p["t"] = 0.25;
  p["t_int"] = int64_t{1};
  p["t_str"] = std::string("0.5");
  p["flag"] = true;
  p["name"] = std::string("cam");
  for (const char* key : {"seed_bits", "seed_u", "seed_s"}) {
    auto v = GetUint64Parameter(p, key);
    ASSERT_TRUE(v.ok()) << key;
    EXPECT_EQ(**v, std::numeric_limits<uint64_t>::max()) << key;
  }
  EXPECT_EQ(**GetDoubleParameter(p, "t"), 0.25);
  EXPECT_EQ(**GetDoubleParameter(p, "t_int"), 1.0);
  EXPECT_EQ(**GetDoubleParameter(p, "t_str"), 0.5);
  EXPECT_FALSE(GetDoubleParameter(p, "absent")->has_value());
  EXPECT_EQ(**GetStringParameter(p, "name"), "cam");
  auto bad = GetUint64Parameter(p, "flag");
  ASSERT_FALSE(bad.ok());
  EXPECT_THAT(bad.status().message(), HasSubstr("parameter 'flag' (bool true)"));
  bad = GetUint64Parameter(p, "name");
  ASSERT_FALSE(bad.ok());
  EXPECT_THAT(bad.status().message(), HasSubstr("unsigned 64-bit integer"));
  auto bad_d = GetDoubleParameter(p, "name");
  ASSERT_FALSE(bad_d.ok());
  EXPECT_THAT(bad_d.status().message(),
              HasSubstr("parameter 'name' (string \"cam\") must be a number"));
}

// ---- protobuf ----------------------------------------------------------------------------------

TEST(ProtoConvertTest, RequestRoundTripsThroughRawContents) {
  InferRequest r;
  r.model_name = "oracle";
  r.model_version = "1";
  r.id = "cam@5";
  r.parameters["score_threshold"] = 0.5;
  r.parameters["seed"] = int64_t{-7};
  r.parameters["u"] = uint64_t{9};
  r.parameters["flag"] = false;
  r.parameters["s"] = std::string("x");
  const std::vector<uint8_t> rgb = {1, 2, 3, 4, 5, 6};
  r.inputs.push_back(
      MakeTensor<uint8_t>("rgb", DataType::kUint8, {1, 2, 3}, std::span<const uint8_t>(rgb)));
  r.inputs.push_back(MakeBytesTensor("prompt", {"tomato"}));
  r.requested_outputs = {"masks", "scores"};
  inference::ModelInferRequest proto;
  internal::ToProto(r, &proto);
  EXPECT_EQ(proto.raw_input_contents_size(), 2);
  EXPECT_EQ(proto.inputs(0).datatype(), "UINT8");
  EXPECT_EQ(proto.parameters().at("seed").int64_param(), -7);
  // Through the wire format too.
  inference::ModelInferRequest parsed;
  ASSERT_TRUE(parsed.ParseFromString(proto.SerializeAsString()));
  auto back = internal::FromProto(parsed);
  ASSERT_TRUE(back.ok()) << back.status().ToString();
  EXPECT_EQ(*back, r);
}

TEST(ProtoConvertTest, TypedContentsGiveTheSameTensorsAsRaw) {
  inference::ModelInferRequest proto;
  auto* rgb = proto.add_inputs();
  rgb->set_name("rgb");
  rgb->set_datatype("UINT8");
  for (const int64_t d : {1, 2, 3}) rgb->add_shape(d);
  for (const uint32_t v : {1u, 2u, 3u, 250u, 255u, 0u})
    rgb->mutable_contents()->add_uint_contents(v);
  auto* depth = proto.add_inputs();
  depth->set_name("depth");
  depth->set_datatype("FP32");
  for (const int64_t d : {1, 2}) depth->add_shape(d);
  depth->mutable_contents()->add_fp32_contents(0.5f);
  depth->mutable_contents()->add_fp32_contents(-1.25f);
  auto* ids = proto.add_inputs();
  ids->set_name("instance_ids");
  ids->set_datatype("UINT16");
  ids->add_shape(2);
  ids->mutable_contents()->add_uint_contents(65535);
  ids->mutable_contents()->add_uint_contents(3);
  auto* prompt = proto.add_inputs();
  prompt->set_name("prompt");
  prompt->set_datatype("BYTES");
  prompt->add_shape(2);
  prompt->mutable_contents()->add_bytes_contents("tomato");
  prompt->mutable_contents()->add_bytes_contents("apple");
  auto typed = internal::FromProto(proto);
  ASSERT_TRUE(typed.ok()) << typed.status().ToString();
  const std::vector<uint8_t> rgb_values = {1, 2, 3, 250, 255, 0};
  const std::vector<float> depth_values = {0.5f, -1.25f};
  const std::vector<uint16_t> id_values = {65535, 3};
  EXPECT_EQ(typed->inputs[0], MakeTensor<uint8_t>("rgb", DataType::kUint8, {1, 2, 3},
                                                  std::span<const uint8_t>(rgb_values)));
  EXPECT_EQ(typed->inputs[1], MakeTensor<float>("depth", DataType::kFp32, {1, 2},
                                                std::span<const float>(depth_values)));
  EXPECT_EQ(typed->inputs[2], MakeTensor<uint16_t>("instance_ids", DataType::kUint16, {2},
                                                   std::span<const uint16_t>(id_values)));
  EXPECT_EQ(typed->inputs[3], MakeBytesTensor("prompt", {"tomato", "apple"}));
}

TEST(ProtoConvertTest, BadContentsAreErrorsNamingTheTensor) {
  inference::ModelInferRequest proto;
  auto* rgb = proto.add_inputs();
  rgb->set_name("rgb");
  rgb->set_datatype("UINT8");
  rgb->add_shape(2);
  rgb->mutable_contents()->add_uint_contents(1);
  rgb->mutable_contents()->add_uint_contents(300);
  auto r = internal::FromProto(proto);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().message(), "input 'rgb': uint_contents[1] (300) is out of range for UINT8");

  rgb->mutable_contents()->set_uint_contents(1, 3);
  rgb->mutable_contents()->add_uint_contents(4);
  r = internal::FromProto(proto);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().message(), "input 'rgb': shape [2] of UINT8 needs 2 uint_contents, got 3");

  rgb->mutable_contents()->Clear();
  rgb->mutable_contents()->add_fp32_contents(1.0f);
  rgb->mutable_contents()->add_fp32_contents(2.0f);
  r = internal::FromProto(proto);
  ASSERT_FALSE(r.ok());
  EXPECT_THAT(r.status().message(), HasSubstr("needs 2 uint_contents, got 0"));

  rgb->set_datatype("FLOAT32");
  r = internal::FromProto(proto);
  ASSERT_FALSE(r.ok());
  EXPECT_THAT(r.status().message(), HasSubstr("input 'rgb': unknown datatype 'FLOAT32'"));

  rgb->set_datatype("UINT8");
  proto.add_raw_input_contents("ab");
  r = internal::FromProto(proto);
  ASSERT_FALSE(r.ok());
  EXPECT_THAT(r.status().message(), HasSubstr("has typed contents although raw_input_contents"));

  rgb->mutable_contents()->Clear();
  proto.add_raw_input_contents("cd");
  r = internal::FromProto(proto);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().message(),
            "raw_input_contents has 2 entries for 1 inputs: expected one per input");
}

TEST(ProtoConvertTest, StatusCodesMapToGrpc) {
  EXPECT_EQ(internal::ToGrpcStatus(InvalidArgumentError("x")).error_code(),
            grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(internal::ToGrpcStatus(NotFoundError("x")).error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_EQ(internal::ToGrpcStatus(FailedPreconditionError("x")).error_code(),
            grpc::StatusCode::FAILED_PRECONDITION);
  EXPECT_EQ(internal::ToGrpcStatus(InternalError("boom")).error_message(), "boom");
  EXPECT_TRUE(internal::ToGrpcStatus(Status::Ok()).ok());
}

}  // namespace
}  // namespace avp::segmentation_service
