#include <gtest/gtest.h>
TEST(Placeholder_mesh_test, Builds) { SUCCEED(); }
