# Helpers shared by every module: one library target per module, warnings as errors, sanitizers,
# explicit source lists (no GLOB).

function(avp_set_compile_options target)
  target_compile_options(${target} PRIVATE -Wall -Wextra -Wpedantic -Wshadow -Wnon-virtual-dtor
                                           -Wcast-align -Woverloaded-virtual)
  if(AVP_WARNINGS_AS_ERRORS)
    target_compile_options(${target} PRIVATE -Werror)
  endif()
  # Same seed, same numbers on any x86-64 or ARM machine: no fused multiply-add contraction.
  target_compile_options(${target} PRIVATE -ffp-contract=off)
  if(AVP_SANITIZE)
    target_compile_options(${target} PRIVATE -fsanitize=${AVP_SANITIZE} -fno-omit-frame-pointer)
    target_link_options(${target} PRIVATE -fsanitize=${AVP_SANITIZE})
    if(AVP_SANITIZE MATCHES "address")
      # ASan replaces malloc, so Eigen's aligned allocator in our code and in the (unsanitized)
      # liborocos-kdl would disagree about who owns a block: tell Eigen malloc is already aligned.
      target_compile_definitions(${target} PRIVATE EIGEN_MALLOC_ALREADY_ALIGNED=1)
    endif()
  endif()
endfunction()

# avp_add_library(<module> SOURCES ... PUBLIC_DEPS ... PRIVATE_DEPS ...)
# Creates avp_<module> with the alias avp::<module>; public headers live in <module>/include/avp/<module>/.
function(avp_add_library module)
  cmake_parse_arguments(ARG "" "" "SOURCES;PUBLIC_DEPS;PRIVATE_DEPS" ${ARGN})
  set(target avp_${module})
  add_library(${target} ${ARG_SOURCES})
  add_library(avp::${module} ALIAS ${target})
  target_include_directories(${target} PUBLIC $<BUILD_INTERFACE:${CMAKE_CURRENT_SOURCE_DIR}/include>)
  target_link_libraries(${target} PUBLIC ${ARG_PUBLIC_DEPS} PRIVATE ${ARG_PRIVATE_DEPS})
  avp_set_compile_options(${target})
endfunction()

# avp_add_test(<name> SOURCES ... DEPS ...)
# One GoogleTest executable registered with ctest (each TEST becomes its own ctest entry).
function(avp_add_test name)
  cmake_parse_arguments(ARG "" "" "SOURCES;DEPS" ${ARGN})
  add_executable(${name} ${ARG_SOURCES})
  target_link_libraries(${name} PRIVATE ${ARG_DEPS} avp_test_support GTest::gtest GTest::gmock
                                        GTest::gtest_main)
  avp_set_compile_options(${name})
  target_compile_definitions(${name} PRIVATE AVP_CONFIG_DIR="${AVP_CONFIG_DIR}"
                                             AVP_TEST_DATA_DIR="${CMAKE_SOURCE_DIR}/tests/data")
  gtest_discover_tests(${name} DISCOVERY_TIMEOUT 60
                       PROPERTIES ENVIRONMENT "AVP_CONFIG_DIR=${AVP_CONFIG_DIR}")
endfunction()

# avp_add_benchmark(<name> SOURCES ... DEPS ...)
function(avp_add_benchmark name)
  cmake_parse_arguments(ARG "" "" "SOURCES;DEPS" ${ARGN})
  add_executable(${name} ${ARG_SOURCES})
  target_link_libraries(${name} PRIVATE ${ARG_DEPS} benchmark::benchmark)
  avp_set_compile_options(${name})
  target_compile_definitions(${name} PRIVATE AVP_CONFIG_DIR="${AVP_CONFIG_DIR}")
endfunction()
