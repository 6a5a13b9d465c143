// segmentation_service::TensorServer and TensorClient on loopback with a hand-written model (y = 2x
// + b, and the count of x's elements as INT64): metadata, inference, and every refusal naming what
// is wrong (no such model, a missing, unknown or misshapen input, a server that is not there, a bad
// address).
#include <memory>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/segmentation_service/tensor_service.h>

namespace avp::segmentation_service {
namespace {

using ::testing::HasSubstr;

class Affine final : public TensorModelHandler {
 public:
  const std::string& name() const override { return name_; }
  std::string platform() const override { return "test"; }
  const std::vector<TensorSpec>& inputs() const override { return inputs_; }
  const std::vector<TensorSpec>& outputs() const override { return outputs_; }
  Result<InferResponse> Infer(const InferRequest& request) const override {
    AVP_ASSIGN_OR_RETURN(std::vector<float> x, ReadValues<float>(*request.FindInput("x")));
    AVP_ASSIGN_OR_RETURN(const std::vector<float> b, ReadValues<float>(*request.FindInput("b")));
    for (float& v : x) v = 2.f * v + b[0];
    const std::vector<int64_t> n = {static_cast<int64_t>(x.size())};
    InferResponse r;
    r.outputs.push_back(MakeTensor<float>("y", DataType::kFp32, request.FindInput("x")->shape,
                                          std::span<const float>(x)));
    r.outputs.push_back(
        MakeTensor<int64_t>("n", DataType::kInt64, {1}, std::span<const int64_t>(n)));
    return r;
  }

 private:
  std::string name_ = "affine";
  std::vector<TensorSpec> inputs_ = {{"x", DataType::kFp32, {-1, 3}, false},
                                     {"b", DataType::kFp32, {1}, false}};
  std::vector<TensorSpec> outputs_ = {{"y", DataType::kFp32, {-1, 3}, false},
                                      {"n", DataType::kInt64, {1}, false}};
};

std::unique_ptr<TensorServer> StartServer() {
  TensorServerOptions o;
  o.port = 0;
  Result<std::unique_ptr<TensorServer>> s = TensorServer::Start(o, {std::make_shared<Affine>()});
  EXPECT_TRUE(s.ok()) << s.status().ToString();
  return s.ok() ? std::move(s).value() : nullptr;
}

std::unique_ptr<TensorClient> Client(const std::string& address, const std::string& model) {
  TensorClientOptions o;
  o.address = address;
  o.model = model;
  o.deadline_s = 10.0;
  Result<std::unique_ptr<TensorClient>> c = TensorClient::Create(o);
  EXPECT_TRUE(c.ok()) << c.status().ToString();
  return c.ok() ? std::move(c).value() : nullptr;
}

InferRequest Request(std::vector<float> x, std::vector<int64_t> shape, float b = 1.f) {
  InferRequest r;
  r.inputs.push_back(MakeTensor<float>("x", DataType::kFp32, shape, std::span<const float>(x)));
  const std::vector<float> bias = {b};
  r.inputs.push_back(MakeTensor<float>("b", DataType::kFp32, {1}, std::span<const float>(bias)));
  return r;
}

TEST(TensorServiceTest, MetadataAndInferenceOverLoopback) {
  auto server = StartServer();
  ASSERT_NE(server, nullptr);
  auto client = Client(server->address(), "affine");
  ASSERT_TRUE(client->Ready().ok());
  EXPECT_TRUE(*client->Ready());
  const Result<TensorModelMetadata> meta = client->Metadata();
  ASSERT_TRUE(meta.ok()) << meta.status().ToString();
  EXPECT_EQ(meta->platform, "test");
  ASSERT_EQ(meta->inputs.size(), 2u);
  EXPECT_EQ(meta->inputs[0].shape, (std::vector<int64_t>{-1, 3}));
  EXPECT_EQ(meta->outputs[1].datatype, DataType::kInt64);
  const Result<InferResponse> r = client->Infer(Request({1, 2, 3, 4, 5, 6}, {2, 3}, 0.5f));
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(r->model_name, "affine");
  const Result<std::vector<float>> y = ReadValues<float>(*r->FindOutput("y"));
  ASSERT_TRUE(y.ok());
  EXPECT_EQ(*y, (std::vector<float>{2.5f, 4.5f, 6.5f, 8.5f, 10.5f, 12.5f}));
  EXPECT_EQ(r->FindOutput("y")->shape, (std::vector<int64_t>{2, 3}));
  EXPECT_EQ(*ReadValues<int64_t>(*r->FindOutput("n")), (std::vector<int64_t>{6}));
  EXPECT_EQ(server->stats().infer_ok, 1u);
}

TEST(TensorServiceTest, RefusalsNameTheModelAndTheTensor) {
  auto server = StartServer();
  ASSERT_NE(server, nullptr);
  auto other = Client(server->address(), "detector");
  Result<InferResponse> r = other->Infer(Request({1, 2, 3}, {1, 3}));
  EXPECT_EQ(r.status().code(), StatusCode::kNotFound);
  EXPECT_THAT(r.status().message(), AllOf(HasSubstr("no model 'detector'"), HasSubstr("affine")));
  EXPECT_EQ(other->Metadata().status().code(), StatusCode::kNotFound);
  EXPECT_FALSE(*other->Ready());

  auto client = Client(server->address(), "affine");
  r = client->Infer(Request({1, 2, 3, 4}, {1, 4}));  // a static dimension that differs
  EXPECT_EQ(r.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(r.status().message(), AllOf(HasSubstr("'x'"), HasSubstr("[-1, 3]")));
  // A dynamic dimension past max_dynamic_dim (1024) is refused before the model runs.
  r = client->Infer(Request(std::vector<float>(3 * 1025, 0.f), {1025, 3}));
  EXPECT_EQ(r.status().code(), StatusCode::kResourceExhausted);
  EXPECT_THAT(r.status().message(),
              HasSubstr("dimension 0 (1025) exceeds the limit max_dynamic_dim"));
  InferRequest missing = Request({1, 2, 3}, {1, 3});
  missing.inputs.pop_back();
  r = client->Infer(missing);
  EXPECT_THAT(r.status().message(), HasSubstr("input 'b' (FP32 [1]) is missing"));
  InferRequest unknown = Request({1, 2, 3}, {1, 3});
  const std::vector<float> z = {0.f};
  unknown.inputs.push_back(MakeTensor<float>("z", DataType::kFp32, {1}, std::span<const float>(z)));
  r = client->Infer(unknown);
  EXPECT_THAT(r.status().message(), HasSubstr("has no input 'z'"));
  InferRequest short_data = Request({1, 2, 3}, {1, 3});
  short_data.inputs[0].data.resize(8);
  r = client->Infer(short_data);
  EXPECT_EQ(r.status().code(), StatusCode::kInvalidArgument);
  EXPECT_GE(server->stats().infer_failed, 4u);

  // Two models of one name, a bad option, a server that is not there, a bad address.
  TensorServerOptions o;
  o.port = 0;
  EXPECT_THAT(TensorServer::Start(o, {std::make_shared<Affine>(), std::make_shared<Affine>()})
                  .status()
                  .message(),
              HasSubstr("two models are named 'affine'"));
  o.threads = 0;
  EXPECT_THAT(TensorServer::Start(o, {}).status().message(), HasSubstr("threads (0)"));
  auto nobody = Client("127.0.0.1:1", "affine");
  const Result<TensorModelMetadata> m = nobody->Metadata();
  EXPECT_EQ(m.status().code(), StatusCode::kUnavailable);
  EXPECT_THAT(m.status().message(), HasSubstr("127.0.0.1:1"));
  EXPECT_EQ(*ParseGrpcAddress("grpc://127.0.0.1:8001"), "127.0.0.1:8001");
  EXPECT_EQ(*ParseGrpcAddress("grpc://[::1]:8001/"), "[::1]:8001");
  for (const char* bad : {"127.0.0.1:8001", "grpc://host", "grpc://host:0", "grpc://host:99999",
                          "grpc://::1:8001", "grpc://:8001"}) {
    EXPECT_FALSE(ParseGrpcAddress(bad).ok()) << bad;
  }
}

}  // namespace
}  // namespace avp::segmentation_service
