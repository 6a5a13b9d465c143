# OpenCV from Debian's per-module -dev packages (libopencv-{imgproc,imgcodecs,dnn,calib3d}-dev):
# only the umbrella libopencv-dev ships OpenCVConfig.cmake, and it pulls in every module (VTK
# included), so the modules avp uses are found directly. calib3d: the lens models of
# ros/msg/lens.h (undistortion maps). Defines the imported target avp::opencv.
find_path(AVP_OPENCV_INCLUDE_DIR opencv2/core.hpp PATH_SUFFIXES opencv4 REQUIRED)
set(_avp_opencv_libs)
foreach(_m core imgproc imgcodecs dnn calib3d)
  find_library(AVP_OPENCV_${_m}_LIBRARY NAMES opencv_${_m} REQUIRED)
  list(APPEND _avp_opencv_libs ${AVP_OPENCV_${_m}_LIBRARY})
endforeach()
add_library(avp_opencv INTERFACE)
add_library(avp::opencv ALIAS avp_opencv)
target_include_directories(avp_opencv SYSTEM INTERFACE ${AVP_OPENCV_INCLUDE_DIR})
target_link_libraries(avp_opencv INTERFACE ${_avp_opencv_libs})
message(STATUS "OpenCV modules: ${_avp_opencv_libs}")
