#include <gtest/gtest.h>
TEST(Placeholder_mean_value_test, Builds) { SUCCEED(); }
