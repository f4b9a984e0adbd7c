// `sonoshape devices` as a user runs it, against a grabber umockdev emulates (the command runs
// as a child of this test and inherits the emulation). Runs under umockdev-wrapper.
#include <gtest/gtest.h>

#include <string>

#include "sonoshape/testing/command.hpp"
#include "sonoshape/testing/fake_v4l2_grabber.hpp"
#include "sonoshape/testing/temp_dir.hpp"
#include "sonoshape/testing/trakstar_usb_record.hpp"

namespace sonoshape::devices_command_test {
namespace {

TEST(DevicesCommand, ListsTheCaptureNodeWithAPastableSourceAndSkipsTheMetadataNode) {
  ASSERT_TRUE(testing::umockdev_preloaded()) << "run under umockdev-wrapper (ctest does)";
  testing::FakeV4l2Grabber grabber(/*with_metadata_node=*/true);
  testing::TempDir dir;
  const auto result = testing::run_command(SONOSHAPE_BINARY, "devices", dir.path() / "log.txt");
  ASSERT_EQ(result.exit_code, 0) << result.output;
  EXPECT_NE(result.output.find("Frame grabbers (V4L2):\n"
                               "  /dev/video0  Fake USB grabber  (usb-0000:00:14.0-1; io: read)\n"
                               "    GREY  8-bit Greyscale\n"
                               "      32x24 at 30, 15 fps:  --source "
                               "v4l2:/dev/video0?size=32x24&format=GREY&fps=30&io=read\n"),
            std::string::npos)
      << result.output;
  EXPECT_EQ(result.output.find("/dev/video1"), std::string::npos) << result.output;
}

TEST(DevicesCommand, SaysSoWhenNoGrabberIsAttached) {
  ASSERT_TRUE(testing::umockdev_preloaded()) << "run under umockdev-wrapper (ctest does)";
  UMockdevTestbed* empty = umockdev_testbed_new();  // an empty /sys: no video4linux class
  testing::TempDir dir;
  const auto result = testing::run_command(SONOSHAPE_BINARY, "devices", dir.path() / "log.txt");
  g_object_unref(empty);
  ASSERT_EQ(result.exit_code, 0) << result.output;
  EXPECT_NE(result.output.find("no video capture device found"), std::string::npos)
      << result.output;
  EXPECT_NE(result.output.find("Trackers (USB):\n  no trakSTAR / driveBAY found"),
            std::string::npos)
      << result.output;
}

TEST(DevicesCommand, ListsATrakstarOnUsbWithAPastableTracker) {
  ASSERT_TRUE(testing::umockdev_preloaded()) << "run under umockdev-wrapper (ctest does)";
  UMockdevTestbed* bed = umockdev_testbed_new();
  GError* error = nullptr;
  ASSERT_TRUE(umockdev_testbed_add_from_string(bed, testing::kTrakstarUsbRecord, &error))
      << (error ? error->message : "");
  testing::TempDir dir;
  const auto result = testing::run_command(SONOSHAPE_BINARY, "devices", dir.path() / "log.txt");
  g_object_unref(bed);
  ASSERT_EQ(result.exit_code, 0) << result.output;
  EXPECT_NE(result.output.find("Trackers (USB):\n  USB bus 1 device 2, vendor 0x21e2 product "
                               "0x0001:  --tracker usb:trakstar:product=0x0001\n"),
            std::string::npos)
      << result.output;
}

}  // namespace
}  // namespace sonoshape::devices_command_test
