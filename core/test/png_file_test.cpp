// write_png: the pictures read back through libpng pixel for pixel, and a path that cannot be
// written is named in the error.
#include "sonoshape/core/png_file.hpp"

#include <gtest/gtest.h>
#include <png.h>

#include <vector>

#include "sonoshape/core/image.hpp"
#include "sonoshape/testing/temp_dir.hpp"

namespace sonoshape::png_file_test {
namespace {

using testing::contains;
using testing::TempDir;

// The file's pixels in the given layout, through libpng's simplified reader.
std::vector<std::uint8_t> read_png(const std::filesystem::path& path, png_uint_32 format,
                                   int& width_px, int& height_px) {
  png_image image{};
  image.version = PNG_IMAGE_VERSION;
  if (png_image_begin_read_from_file(&image, path.c_str()) == 0) return {};
  image.format = format;
  std::vector<std::uint8_t> pixels(PNG_IMAGE_SIZE(image));
  if (png_image_finish_read(&image, nullptr, pixels.data(), 0, nullptr) == 0) return {};
  width_px = static_cast<int>(image.width);
  height_px = static_cast<int>(image.height);
  return pixels;
}

TEST(PngFile, GreyAndBgrPicturesReadBackExactly) {
  const TempDir dir;
  ImageU8 grey(7, 5);
  for (int j = 0; j < 5; ++j)
    for (int i = 0; i < 7; ++i) grey.at(i, j) = static_cast<std::uint8_t>(37 * i + 11 * j);
  ASSERT_TRUE(write_png(dir.path() / "grey.png", PngPixels::kGrey, 7, 5, grey.pixels.data(), 7));
  int width = 0, height = 0;
  EXPECT_EQ(read_png(dir.path() / "grey.png", PNG_FORMAT_GRAY, width, height), grey.pixels);
  EXPECT_EQ(width, 7);
  EXPECT_EQ(height, 5);

  // Three columns of blue, green, red in rows padded to 12 bytes: the padding is not written.
  std::vector<std::uint8_t> bgr(12 * 2, 99);
  for (int j = 0; j < 2; ++j)
    for (int i = 0; i < 3; ++i)
      for (int c = 0; c < 3; ++c)
        bgr[12 * j + 3 * i + c] = static_cast<std::uint8_t>(c == i ? 200 : j);
  ASSERT_TRUE(write_png(dir.path() / "bgr.png", PngPixels::kBgr, 3, 2, bgr.data(), 12));
  const auto rgb = read_png(dir.path() / "bgr.png", PNG_FORMAT_RGB, width, height);
  ASSERT_EQ(rgb.size(), 18u);
  EXPECT_EQ(width, 3);
  for (int j = 0; j < 2; ++j)
    for (int i = 0; i < 3; ++i)
      for (int c = 0; c < 3; ++c)  // RGB in the file's reading: red is BGR's channel 2
        EXPECT_EQ(rgb[9 * j + 3 * i + c], bgr[12 * j + 3 * i + (2 - c)]) << i << "," << j;
}

TEST(PngFile, AnUnwritablePathAndAnEmptyPictureAreNamed) {
  const TempDir dir;
  const ImageU8 picture(4, 4);
  const Status missing = write_png(dir.path() / "no_such_dir" / "a.png", PngPixels::kGrey, 4, 4,
                                   picture.pixels.data(), 4);
  ASSERT_FALSE(missing);
  EXPECT_TRUE(contains(missing.message(), "no_such_dir/a.png")) << missing.message();
  const Status empty =
      write_png(dir.path() / "b.png", PngPixels::kGrey, 0, 4, picture.pixels.data(), 4);
  ASSERT_FALSE(empty);
  EXPECT_TRUE(contains(empty.message(), "empty")) << empty.message();
}

}  // namespace
}  // namespace sonoshape::png_file_test
