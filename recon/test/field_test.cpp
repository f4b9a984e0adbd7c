#include <gtest/gtest.h>
TEST(Placeholder_field_test, Builds) { SUCCEED(); }
