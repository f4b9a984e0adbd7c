#include <gtest/gtest.h>
TEST(Placeholder_csl_io_test, Builds) { SUCCEED(); }
