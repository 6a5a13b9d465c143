// avp::zsl: see zsl/CMakeLists.txt for the module's parts.
#include <avp/zsl/zsl.h>

namespace avp::zsl {

bool BuiltWithOnnxRuntime() {
#ifdef AVP_WITH_ONNX
  return true;
#else
  return false;
#endif
}

}  // namespace avp::zsl
