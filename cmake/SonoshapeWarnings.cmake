# sonoshape_target_defaults(<target>): warnings (errors with SONOSHAPE_WERROR) for our own code.
function(sonoshape_target_defaults target)
  target_compile_options(${target} PRIVATE -Wall -Wextra -Wpedantic)
  if(SONOSHAPE_WERROR)
    target_compile_options(${target} PRIVATE -Werror)
  endif()
endfunction()

# sonoshape_test_optimization(<target>): test programs are compiled at -O1 in optimised builds, the
# libraries they test keep the build type's -O3. A test's own code is checks and fixtures, and -O1
# compiles it in about two thirds of the CPU time of -O3 (docs/benchmarks.md, "Build time");
# without -ffast-math every -O level computes the same results. The test header and every test
# source must agree on it (GCC takes a precompiled header only with the same -O). At -O1 GCC 12
# warns that a std::optional member "may be used uninitialized" in destructors it half-inlines
# (GCC bug 80635, a false positive); the libraries, at -O3, keep the warning.
function(sonoshape_test_optimization target)
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
    sonoshape_test_optimization(sonoshape_test_pch)
    target_precompile_headers(sonoshape_test_pch PRIVATE
      <gtest/gtest.h> <Eigen/Core> <Eigen/Geometry> <algorithm> <chrono> <cmath> <cstdint>
      <filesystem> <fstream> <functional> <map> <memory> <optional> <set> <sstream> <string>
      <thread> <utility> <vector>)
  endif()
  target_precompile_headers(${target} REUSE_FROM sonoshape_test_pch)
endfunction()

# sonoshape_add_test(<name> SOURCES ... LIBS ...): one GoogleTest executable registered with ctest.
function(sonoshape_add_test name)
  cmake_parse_arguments(ARG "" "" "SOURCES;LIBS;LABELS" ${ARGN})
  add_executable(${name} ${ARG_SOURCES})
  sonoshape_test_optimization(${name})
  sonoshape_use_test_pch(${name})
  target_link_libraries(${name} PRIVATE ${ARG_LIBS} GTest::gtest GTest::gtest_main)
  target_compile_definitions(${name} PRIVATE SONOSHAPE_DATA_DIR="${SONOSHAPE_DATA_DIR}")
  target_include_directories(${name} PRIVATE ${PROJECT_SOURCE_DIR}/tests/support)
  sonoshape_target_defaults(${name})
  gtest_discover_tests(${name} DISCOVERY_TIMEOUT 60 PROPERTIES LABELS "${ARG_LABELS}")
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
  sonoshape_test_optimization(${name})
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
  set_target_properties(${target} PROPERTIES UNITY_BUILD ON UNITY_BUILD_MODE GROUP)
  set_source_files_properties(${ARGN} TARGET_DIRECTORY ${target} PROPERTIES UNITY_GROUP ${group})
endfunction()
