#include <gtest/gtest.h>
TEST(Placeholder_mesh_reader_test, Builds) { SUCCEED(); }
