#include <gtest/gtest.h>
TEST(Placeholder_mesh_writer_test, Builds) { SUCCEED(); }
