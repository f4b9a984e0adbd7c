#include <gtest/gtest.h>
TEST(Placeholder_arrangement_test, Builds) { SUCCEED(); }
