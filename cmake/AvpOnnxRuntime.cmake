# ONNX Runtime for the zero-shot segmentation backends (docs/zero-shot-models.md §3). Included by
# the top-level CMakeLists.txt when AVP_WITH_ONNX is ON. Nothing is downloaded here: scripts/setup
# (through scripts/onnxruntime and cmake/FetchOnnxRuntime.cmake) extracts the pinned npm packages
# into ${XDG_CACHE_HOME:-~/.cache}/avp/npm/onnxruntime-<ver>/{include,lib}; this file finds it.
#
# Defines:
#   onnxruntime::onnxruntime   IMPORTED SHARED target at <root>/lib/libonnxruntime.so.1, with the
#                              ORT headers as SYSTEM includes (so -Werror does not apply to them)
#   AVP_ORT_ROOT               cache variable: the tree (override for another ORT build laid out the
#                              same way, e.g. Microsoft's 1.30 CPU core with the 1.29 headers)
#   AVP_ORT_LIB_DIR            <root>/lib (the core and the provider libraries)
# Build RPATH: executables linking the target find <root>/lib. Install RPATH: $ORIGIN/../lib, where
# the install step copies the core and the providers.

include(FetchOnnxRuntime)  # defines avp_ort_default_root and avp_ort_check_tree only

avp_ort_default_root(_avp_ort_default_root)
set(AVP_ORT_ROOT "${_avp_ort_default_root}"
    CACHE PATH "ONNX Runtime tree with include/ and lib/libonnxruntime.so.1 (from scripts/setup)")
# Re-configure when the lock changes (a new pin must not silently keep the old tree).
set_property(DIRECTORY APPEND PROPERTY CMAKE_CONFIGURE_DEPENDS "${AVP_ORT_LOCK_FILE}")

set(_avp_ort_hint
    "run scripts/setup (or scripts/onnxruntime), or configure with -DAVP_WITH_ONNX=OFF")
foreach(_f lib/libonnxruntime.so.1 include/onnxruntime_cxx_api.h include/onnxruntime_c_api.h)
  if(NOT EXISTS "${AVP_ORT_ROOT}/${_f}")
    message(FATAL_ERROR "AVP_WITH_ONNX: ONNX Runtime not found: ${AVP_ORT_ROOT}/${_f} is missing; "
                        "${_avp_ort_hint}")
  endif()
endforeach()
# A tree written by FetchOnnxRuntime.cmake carries a stamp: it must match the current lock.
if(EXISTS "${AVP_ORT_ROOT}/${AVP_ORT_STAMP_NAME}")
  # Package 0 of the lock is the required core; optional packages are checked only if stamped.
  avp_ort_check_tree("${AVP_ORT_ROOT}" "0" _avp_ort_ok _avp_ort_reason _avp_ort_installed)
  if(NOT _avp_ort_ok)
    message(FATAL_ERROR "AVP_WITH_ONNX: ONNX Runtime at ${AVP_ORT_ROOT} does not match "
                        "cmake/onnxruntime.lock (${_avp_ort_reason}); ${_avp_ort_hint}")
  endif()
endif()

set(AVP_ORT_LIB_DIR "${AVP_ORT_ROOT}/lib")
add_library(onnxruntime::onnxruntime SHARED IMPORTED GLOBAL)
set_target_properties(onnxruntime::onnxruntime PROPERTIES
  IMPORTED_LOCATION "${AVP_ORT_LIB_DIR}/libonnxruntime.so.1"
  IMPORTED_SONAME "libonnxruntime.so.1"
  INTERFACE_INCLUDE_DIRECTORIES "${AVP_ORT_ROOT}/include"
  INTERFACE_SYSTEM_INCLUDE_DIRECTORIES "${AVP_ORT_ROOT}/include")

# CMake puts the imported library's folder into the build RPATH of what links it; say so explicitly
# for the providers, which ORT dlopen()s from the core's folder.
list(APPEND CMAKE_BUILD_RPATH "${AVP_ORT_LIB_DIR}")
if(NOT "\$ORIGIN/../lib" IN_LIST CMAKE_INSTALL_RPATH)
  list(APPEND CMAKE_INSTALL_RPATH "\$ORIGIN/../lib")
endif()
install(DIRECTORY "${AVP_ORT_LIB_DIR}/" DESTINATION lib COMPONENT onnxruntime
        FILES_MATCHING PATTERN "libonnxruntime*")

set(_avp_ort_gpu "CPU only")
if(EXISTS "${AVP_ORT_LIB_DIR}/libonnxruntime_providers_cuda.so")
  set(_avp_ort_gpu "with the CUDA execution provider")
endif()
message(STATUS "ONNX Runtime: ${AVP_ORT_ROOT} (${_avp_ort_gpu})")
