#pragma once

namespace avp::zsl {

/// True when this build has ONNX Runtime (AVP_WITH_ONNX), i.e. the ywes and lsam backends.
bool BuiltWithOnnxRuntime();

}  // namespace avp::zsl
