#include <gtest/gtest.h>
TEST(Placeholder_mesh_slicer_test, Builds) { SUCCEED(); }
