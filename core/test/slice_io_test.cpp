#include <gtest/gtest.h>
TEST(Placeholder_slice_io_test, Builds) { SUCCEED(); }
