#include <gtest/gtest.h>
TEST(Placeholder_evaluation_test, Builds) { SUCCEED(); }
