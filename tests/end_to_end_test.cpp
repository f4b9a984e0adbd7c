#include <gtest/gtest.h>
TEST(Placeholder_end_to_end_test, Builds) { SUCCEED(); }
