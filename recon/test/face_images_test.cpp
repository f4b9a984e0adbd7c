#include <gtest/gtest.h>
TEST(Placeholder_face_images_test, Builds) { SUCCEED(); }
