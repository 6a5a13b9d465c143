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

# avp_set_test_code_options(<target>)
# Code whose speed does not matter is compiled at -O1 in a Release build: test programs' own code
# (half the build's compile time; the code under test is in the libraries, which keep the build
# type's flags) and the command line's glue (apps/: CLI11 is header-only, and its code compiled at
# -O3 in every command's file made those the slowest files of the build). -O3 took ~1.7-1.9x as
# long to compile them, for nothing. Results do not change: no fused multiply-add
# (-ffp-contract=off) and SSE arithmetic at every level.
function(avp_set_test_code_options target)
  target_compile_options(${target} PRIVATE $<$<CONFIG:Release>:-O1>)
endfunction()

# avp_add_library(<module> SOURCES ... PUBLIC_DEPS ... PRIVATE_DEPS ...)
# Creates avp_<module> with the alias avp::<module>; public headers live in
# <folder>/include/avp/<folder>/, where <module> is the folder with "_" for "/" (the ROS wing's
# ros/msg is avp_ros_msg, its headers avp/ros/msg/*.h).
function(avp_add_library module)
  cmake_parse_arguments(ARG "" "" "SOURCES;PUBLIC_DEPS;PRIVATE_DEPS" ${ARGN})
  set(target avp_${module})
  add_library(${target} ${ARG_SOURCES})
  add_library(avp::${module} ALIAS ${target})
  target_include_directories(${target} PUBLIC $<BUILD_INTERFACE:${CMAKE_CURRENT_SOURCE_DIR}/include>)
  target_link_libraries(${target} PUBLIC ${ARG_PUBLIC_DEPS} PRIVATE ${ARG_PRIVATE_DEPS})
  avp_set_compile_options(${target})
  set_property(DIRECTORY ${CMAKE_SOURCE_DIR} APPEND PROPERTY AVP_LIBRARY_TARGETS ${target})
endfunction()

# avp_add_test(<name> SOURCES ... DEPS ...)
# One GoogleTest executable registered with ctest (each TEST becomes its own ctest entry).
function(avp_add_test name)
  cmake_parse_arguments(ARG "" "" "SOURCES;DEPS" ${ARGN})
  add_executable(${name} ${ARG_SOURCES})
  target_link_libraries(${name} PRIVATE ${ARG_DEPS} avp_test_support GTest::gtest GTest::gmock
                                        GTest::gtest_main)
  avp_set_compile_options(${name})
  avp_set_test_code_options(${name})
  target_compile_definitions(${name} PRIVATE AVP_CONFIG_DIR="${AVP_CONFIG_DIR}"
                                             AVP_TEST_DATA_DIR="${CMAKE_SOURCE_DIR}/tests/data")
  gtest_discover_tests(${name} DISCOVERY_TIMEOUT 60
                       PROPERTIES ENVIRONMENT "AVP_CONFIG_DIR=${AVP_CONFIG_DIR}")
endfunction()

# avp_add_node_test(<name> <script.mjs> [ARGS ...] TIMEOUT <s>)
# A test run by Node.js (its npm packages from scripts/setup: tests/npm/npm_test.mjs); without
# node, a test that fails saying so (never a silent skip).
function(avp_add_node_test name script)
  cmake_parse_arguments(ARG "" "TIMEOUT" "ARGS" ${ARGN})
  find_program(AVP_NODE_EXECUTABLE NAMES node nodejs)
  if(AVP_NODE_EXECUTABLE)
    add_test(NAME ${name} COMMAND ${AVP_NODE_EXECUTABLE} ${script} ${ARG_ARGS})
  else()
    add_test(NAME ${name}
             COMMAND sh -c "echo '${name}: node not found; run scripts/setup' >&2; exit 1")
  endif()
  set_tests_properties(${name} PROPERTIES TIMEOUT ${ARG_TIMEOUT})
endfunction()

# avp_add_benchmark(<name> SOURCES ... DEPS ...)
function(avp_add_benchmark name)
  cmake_parse_arguments(ARG "" "" "SOURCES;DEPS" ${ARGN})
  add_executable(${name} ${ARG_SOURCES})
  target_link_libraries(${name} PRIVATE ${ARG_DEPS} benchmark::benchmark)
  avp_set_compile_options(${name})
  target_compile_definitions(${name} PRIVATE AVP_CONFIG_DIR="${AVP_CONFIG_DIR}")
endfunction()

# avp_write_link_graph(<file>)
# Writes, for every avp library target (avp_<module>), the transitive closure of what linking it
# pulls in: avp modules, imported targets (embree, assimp::assimp, ...) and plain libraries, one
# line per module: "avp_pipeline: avp_core avp_io ...". tests/architecture_test.cpp reads it to
# check the link graph (e.g. that the loop a real robot runs links no simulator). Call it once,
# after every target is defined.
function(_avp_link_items target out_var)
  set(items "")
  get_target_property(type ${target} TYPE)
  get_target_property(imported ${target} IMPORTED)
  if(NOT imported AND NOT type STREQUAL "INTERFACE_LIBRARY")
    get_target_property(direct ${target} LINK_LIBRARIES)
    if(direct)
      list(APPEND items ${direct})
    endif()
  endif()
  get_target_property(interface ${target} INTERFACE_LINK_LIBRARIES)
  if(interface)
    list(APPEND items ${interface})
  endif()
  set(clean "")
  foreach(item IN LISTS items)
    # A static library's private dependencies appear as $<LINK_ONLY:x>; other generator
    # expressions (build/install interfaces, configurations) are left out.
    string(REGEX REPLACE "^\\$<LINK_ONLY:(.*)>$" "\\1" item "${item}")
    if(item MATCHES "^\\$<" OR item STREQUAL "")
      continue()
    endif()
    if(TARGET ${item})
      get_target_property(aliased ${item} ALIASED_TARGET)
      if(aliased)
        set(item ${aliased})
      endif()
    endif()
    list(APPEND clean ${item})
  endforeach()
  set(${out_var} ${clean} PARENT_SCOPE)
endfunction()

function(avp_write_link_graph file)
  get_property(targets DIRECTORY ${CMAKE_SOURCE_DIR} PROPERTY AVP_LIBRARY_TARGETS)
  set(text "")
  foreach(target IN LISTS targets)
    set(closure "")
    set(work ${target})
    while(work)
      list(POP_FRONT work current)
      _avp_link_items(${current} direct)
      foreach(item IN LISTS direct)
        if(NOT item IN_LIST closure)
          list(APPEND closure ${item})
          if(TARGET ${item})
            list(APPEND work ${item})
          endif()
        endif()
      endforeach()
    endwhile()
    list(SORT closure)
    list(JOIN closure " " joined)
    string(APPEND text "${target}: ${joined}\n")
  endforeach()
  file(WRITE ${file} "${text}")
endfunction()
