#include <gtest/gtest.h>
TEST(Placeholder_reconstruct_test, Builds) { SUCCEED(); }
