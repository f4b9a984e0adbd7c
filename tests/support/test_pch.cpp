// The target sonoshape_test_pch compiles this empty unit to build the precompiled header that every
// test program reuses (cmake/SonoshapeWarnings.cmake, sonoshape_use_test_pch).
