# sonoshape_target_defaults(<target>): warnings (errors with SONOSHAPE_WERROR) for our own code.
# With SONOSHAPE_UNITY_BUILD, the target's sources are compiled in batches of eight, each batch as
# one translation unit (CMake's unity build): the headers they share (CGAL, CLI11, Boost.Beast,
# OpenCV, GoogleTest) are parsed and their templates instantiated once per batch instead of once
# per source, which saves two fifths of a first build's time (docs/benchmarks.md, "Build time").
# Each test source keeps its code in a namespace named after the file, so batches never meet
# two definitions of one name.
function(sonoshape_target_defaults target)
  target_compile_options(${target} PRIVATE -Wall -Wextra -Wpedantic)
  if(SONOSHAPE_WERROR)
    target_compile_options(${target} PRIVATE -Werror)
  endif()
  if(SONOSHAPE_UNITY_BUILD)
    set_target_properties(${target} PROPERTIES UNITY_BUILD ON)
    # GCC warns when a class outside an anonymous namespace holds a type from one, in any file
    # but the one it compiles, since a header's class would then differ between translation
    # units. A unity build includes every source in exactly one batch, so the private classes of
    # a source (pimpl's Impl holding its file's helper types) are false positives there.
    if(CMAKE_CXX_COMPILER_ID STREQUAL "GNU")
      target_compile_options(${target} PRIVATE -Wno-subobject-linkage)
    endif()
  endif()
endfunction()

# sonoshape_light_optimization(<target>): test programs, fuzz replays, the `sonoshape` command and
# the libraries whose work is I/O and wiring (acquisition, tracking, publish, scan, apps) are
# compiled at -O1 in optimised builds; the libraries that compute (core, recon, kernels,
# segmentation, simulator) keep the build type's -O3. A test's own code is checks and fixtures,
# the command's option parsing, the I/O libraries' parsing of files and messages and the threads
# that move frames between stages, and -O1 compiles them in about two thirds of the CPU time of
# -O3 (docs/benchmarks.md, "Build time");
# without -ffast-math every -O level computes the same results. The test header and every test
# source must agree on it (GCC takes a precompiled header only with the same -O). At -O1 GCC 12
# warns that a std::optional member "may be used uninitialized" in destructors it half-inlines
# (GCC bug 80635, a false positive); the libraries at -O3 keep the warning.
function(sonoshape_light_optimization target)
  target_compile_options(${target} PRIVATE
    "$<$<CONFIG:Release,RelWithDebInfo,MinSizeRel>:-O1;-Wno-maybe-uninitialized>")
endfunction()

# sonoshape_use_test_pch(<target>): the test program reuses one precompiled header of GoogleTest,
# Eigen and the standard library, which every test source would otherwise parse again (2-6 s of
# CPU per source at -O3; docs/benchmarks.md, "Build time"). The header is built once, by the
# target sonoshape_test_pch, with the flags every test target has.
function(sonoshape_use_test_pch target)
  if(NOT TARGET sonoshape_test_pch)
    add_library(sonoshape_test_pch OBJECT ${PROJECT_SOURCE_DIR}/tests/support/test_pch.cpp)
    target_link_libraries(sonoshape_test_pch PRIVATE GTest::gtest Eigen3::Eigen)
    sonoshape_target_defaults(sonoshape_test_pch)
    sonoshape_light_optimization(sonoshape_test_pch)
    target_precompile_headers(sonoshape_test_pch PRIVATE
      <gtest/gtest.h> <Eigen/Core> <Eigen/Geometry> <algorithm> <chrono> <cmath> <cstdint>
      <filesystem> <fstream> <functional> <map> <memory> <optional> <set> <sstream> <string>
      <thread> <utility> <vector>)
  endif()
  target_precompile_headers(${target} REUSE_FROM sonoshape_test_pch)
endfunction()

# sonoshape_add_test(<name> SOURCES ... LIBS ... [COST SECONDS]): one GoogleTest executable
# registered with ctest. COST: about how long its longest tests take; ctest starts costlier tests
# first, and without a record of earlier runs (a fresh build) it knows no other way to avoid
# ending a parallel run on one long test while the other cores idle.
function(sonoshape_add_test name)
  cmake_parse_arguments(ARG "" "COST" "SOURCES;LIBS;LABELS" ${ARGN})
  add_executable(${name} ${ARG_SOURCES})
  sonoshape_light_optimization(${name})
  sonoshape_use_test_pch(${name})
  target_link_libraries(${name} PRIVATE ${ARG_LIBS} GTest::gtest GTest::gtest_main)
  target_compile_definitions(${name} PRIVATE SONOSHAPE_DATA_DIR="${SONOSHAPE_DATA_DIR}")
  target_include_directories(${name} PRIVATE ${PROJECT_SOURCE_DIR}/tests/support)
  sonoshape_target_defaults(${name})
  # A test program's sources as one unit: at -O1 none is large, and GoogleTest's and the module's
  # headers are then compiled once per program.
  set_target_properties(${name} PROPERTIES UNITY_BUILD_BATCH_SIZE 0)
  # An empty value would shift the property list (LABELS "" COST 5 labels every test "COST").
  set(properties)
  if(ARG_LABELS)
    list(APPEND properties LABELS "${ARG_LABELS}")
  endif()
  if(ARG_COST)
    list(APPEND properties COST ${ARG_COST})
  endif()
  gtest_discover_tests(${name} DISCOVERY_TIMEOUT 60 PROPERTIES ${properties})
endfunction()

# sonoshape_add_umockdev_test(<name> SOURCES ... LIBS ...): a GoogleTest program that emulates
# devices with umockdev, so it runs under umockdev-wrapper (LD_PRELOAD): one ctest entry for the
# whole program. Skipped when umockdev (libumockdev-dev, umockdev) is not installed.
function(sonoshape_add_umockdev_test name)
  cmake_parse_arguments(ARG "" "" "SOURCES;LIBS" ${ARGN})
  if(NOT UMOCKDEV_FOUND OR NOT SONOSHAPE_UMOCKDEV_WRAPPER)
    message(STATUS "${name}: umockdev not found, test not built")
    return()
  endif()
  add_executable(${name} ${ARG_SOURCES})
  sonoshape_light_optimization(${name})
  sonoshape_use_test_pch(${name})
  target_link_libraries(${name} PRIVATE ${ARG_LIBS} PkgConfig::UMOCKDEV GTest::gtest
                                        GTest::gtest_main)
  target_include_directories(${name} PRIVATE ${PROJECT_SOURCE_DIR}/tests/support)
  sonoshape_target_defaults(${name})
  add_test(NAME ${name} COMMAND ${SONOSHAPE_UMOCKDEV_WRAPPER} $<TARGET_FILE:${name}>)
endfunction()

# sonoshape_unity_group(<target> <group> <source>...): compiles the sources as one translation
# unit (CMake's unity build in GROUP mode; the target's other sources stay one unit each). For
# sources that instantiate the same heavy templates (CGAL's exact kernel and Boolean operations),
# each instantiation is then parsed, compiled and optimised once instead of once per file
# (docs/benchmarks.md, "Build time"). The sources must not define the same name in an anonymous
# namespace.
function(sonoshape_unity_group target group)
  if(NOT SONOSHAPE_UNITY_BUILD)
    return()
  endif()
  set_target_properties(${target} PROPERTIES UNITY_BUILD ON UNITY_BUILD_MODE GROUP)
  set_source_files_properties(${ARGN} TARGET_DIRECTORY ${target} PROPERTIES UNITY_GROUP ${group})
endfunction()
