// V4l2FrameSource through a fake of the system-call seam (v4l2_device.hpp): the MMAP streaming
// path (umockdev cannot emulate mmap() or poll()), driver timestamps, sequence gaps, error
// buffers, EINTR / EAGAIN, unplug and replug; the spec parser; the pixel-format conversions.
#include "sonoshape/acquisition/v4l2_source.hpp"

#include <gtest/gtest.h>
#include <linux/videodev2.h>
#include <sys/mman.h>
#include <turbojpeg.h>

#include <cerrno>
#include <chrono>
#include <cstring>
#include <deque>
#include <map>
#include <mutex>
#include <thread>
#include <variant>

#include "sonoshape/testing/fake_v4l2_driver.hpp"

namespace sonoshape::acquisition::v4l2_source_test {
namespace {

using FakeDriver = testing::FakeV4l2Driver;

constexpr int kWidth = 64, kHeight = 48, kStride = 2 * kWidth + 8;

// A grey JPEG at quality 100, as a webcam's MJPG frame would carry it (libjpeg-turbo).
std::vector<std::uint8_t> encode_jpeg(const std::vector<std::uint8_t>& grey, int width_px,
                                      int height_px) {
  tjhandle encoder = tjInitCompress();
  unsigned char* bytes = nullptr;
  unsigned long size = 0;
  std::vector<std::uint8_t> jpeg;
  if (tjCompress2(encoder, grey.data(), width_px, width_px, height_px, TJPF_GRAY, &bytes, &size,
                  TJSAMP_GRAY, 100, TJFLAG_ACCURATEDCT) == 0)
    jpeg.assign(bytes, bytes + size);
  tjFree(bytes);
  tjDestroy(encoder);
  return jpeg;
}

// A YUYV frame of the fake's granted size whose Y at (i, j) is (i + 2 j + shade) mod 256 and
// whose chroma is 128 (so a wrong plane shows).
std::vector<std::uint8_t> yuyv_frame(int shade) {
  std::vector<std::uint8_t> bytes(std::size_t(kStride) * kHeight, 0xEE);
  for (int j = 0; j < kHeight; ++j)
    for (int i = 0; i < kWidth; ++i) {
      bytes[std::size_t(j) * kStride + 2 * i] = static_cast<std::uint8_t>(i + 2 * j + shade);
      bytes[std::size_t(j) * kStride + 2 * i + 1] = 128;
    }
  return bytes;
}

FakeDriver::Filled filled(std::uint32_t sequence, double timestamp_s, std::uint32_t extra = 0) {
  return {yuyv_frame(static_cast<int>(sequence)), sequence, timestamp_s,
          V4L2_BUF_FLAG_TIMESTAMP_MONOTONIC | extra};
}

V4l2Options fake_options() {
  V4l2Options options;
  options.device = "/dev/video7";
  options.reopen_first_s = 0.01;
  options.reopen_max_s = 0.05;
  return options;
}

std::vector<Frame> take(FrameSource& source, std::size_t count, double timeout_s = 5.0) {
  std::vector<Frame> frames;
  while (frames.size() < count) {
    auto got = source.next(timeout_s);
    if (!got) break;
    frames.push_back(std::move(got->item));
  }
  return frames;
}

template <typename Predicate>
bool eventually(Predicate predicate, double timeout_s = 5.0) {
  const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
  while (std::chrono::steady_clock::now() < end) {
    if (predicate()) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
  return predicate();
}

TEST(V4l2Spec, ParsesTheDeviceAndEveryKey) {
  const auto options = parse_v4l2_spec(
      "/dev/video2?size=1280x720&format=yuyv&fps=29.97&io=read&crop=10,20,300,400"
      "&buffers=6");
  ASSERT_TRUE(options) << options.message();
  EXPECT_EQ(options->device, "/dev/video2");
  EXPECT_EQ(options->width_px, 1280);
  EXPECT_EQ(options->height_px, 720);
  EXPECT_EQ(options->pixel_format, "yuyv");
  EXPECT_DOUBLE_EQ(options->frame_rate_hz, 29.97);
  EXPECT_EQ(options->io, V4l2Io::kRead);
  EXPECT_EQ(options->crop, (PixelRect{10, 20, 300, 400}));
  EXPECT_EQ(options->buffer_count, 6);
  const auto plain = parse_v4l2_spec("/dev/video0");
  ASSERT_TRUE(plain);
  EXPECT_EQ(plain->io, V4l2Io::kAuto);
  EXPECT_FALSE(plain->crop);
  EXPECT_EQ(plain->buffer_count, 4);
}

TEST(V4l2Spec, RejectsBadValuesNamingTheKey) {
  const std::pair<const char*, const char*> cases[] = {
      {"?size=640x480", "no device node"},
      {"/dev/video0?size=640", "size=640"},
      {"/dev/video0?format=RGB3", "format=RGB3"},
      {"/dev/video0?fps=0", "fps=0"},
      {"/dev/video0?io=dma", "io=dma"},
      {"/dev/video0?crop=1,2,3", "crop=1,2,3"},
      {"/dev/video0?crop=0,0,0,5", "crop=0,0,0,5"},
      {"/dev/video0?buffers=2", "buffers=2"},
      {"/dev/video0?colour=1", "unknown key 'colour'"},
      {"/dev/video0?size", "'size'"},
      // Issue 40: a bare std::bad_alloc before any device opened.
      {"/dev/video0?size=99999999x99999999", "size=99999999x99999999 is larger than any capture"},
      {"/dev/video0?crop=0,0,99999999,5", "crop=0,0,99999999,5 reaches beyond"},
  };
  for (const auto& [spec, expected] : cases) {
    const auto options = parse_v4l2_spec(spec);
    ASSERT_FALSE(options) << spec;
    EXPECT_NE(options.message().find(expected), std::string::npos) << options.message();
    EXPECT_NE(options.message().find("v4l2:/dev/videoN?size=WxH"), std::string::npos);
  }
}

TEST(V4l2ToGrey, GreyIsCopiedRowByRowSkippingThePadding) {
  const std::vector<std::uint8_t> bytes = {1, 2, 3, 99, 4, 5, 6, 99};  // 3x2, stride 4
  const auto image = v4l2_to_grey(V4L2_PIX_FMT_GREY, bytes.data(), bytes.size(), 3, 2, 4, {});
  ASSERT_TRUE(image) << image.message();
  EXPECT_EQ(image->pixels, (std::vector<std::uint8_t>{1, 2, 3, 4, 5, 6}));
}

TEST(V4l2ToGrey, YuyvGivesItsYPlane) {
  const auto bytes = yuyv_frame(3);
  const auto image =
      v4l2_to_grey(V4L2_PIX_FMT_YUYV, bytes.data(), bytes.size(), kWidth, kHeight, kStride, {});
  ASSERT_TRUE(image) << image.message();
  ASSERT_EQ(image->width, kWidth);
  ASSERT_EQ(image->height, kHeight);
  for (int j = 0; j < kHeight; ++j)
    for (int i = 0; i < kWidth; ++i)
      ASSERT_EQ(image->at(i, j), static_cast<std::uint8_t>(i + 2 * j + 3)) << i << "," << j;
}

TEST(V4l2ToGrey, CropKeepsTheRectangleOfTheBModeImage) {
  const auto bytes = yuyv_frame(0);
  const auto image = v4l2_to_grey(V4L2_PIX_FMT_YUYV, bytes.data(), bytes.size(), kWidth, kHeight,
                                  kStride, PixelRect{5, 7, 20, 10});
  ASSERT_TRUE(image) << image.message();
  ASSERT_EQ(image->width, 20);
  ASSERT_EQ(image->height, 10);
  EXPECT_EQ(image->at(0, 0), 5 + 2 * 7);
  EXPECT_EQ(image->at(19, 9), 24 + 2 * 16);
}

TEST(V4l2ToGrey, MjpegDecodesToGreyAndCrops) {
  std::vector<std::uint8_t> grey(std::size_t{kWidth} * kHeight);
  for (int j = 0; j < kHeight; ++j)
    for (int i = 0; i < kWidth; ++i) grey[std::size_t(j) * kWidth + i] = std::uint8_t(3 * i + j);
  const std::vector<std::uint8_t> jpeg = encode_jpeg(grey, kWidth, kHeight);
  ASSERT_FALSE(jpeg.empty());
  const auto image = v4l2_to_grey(V4L2_PIX_FMT_MJPEG, jpeg.data(), jpeg.size(), kWidth, kHeight, 0,
                                  PixelRect{8, 4, 16, 12});
  ASSERT_TRUE(image) << image.message();
  ASSERT_EQ(image->width, 16);
  ASSERT_EQ(image->height, 12);
  int worst = 0;
  for (int j = 0; j < 12; ++j)
    for (int i = 0; i < 16; ++i)
      worst = std::max(worst, std::abs(int(image->at(i, j)) - (3 * (i + 8) + (j + 4))));
  EXPECT_LE(worst, 3);  // JPEG at quality 100 is near-lossless on a smooth ramp
}

// Webcams send MJPG frames without their Huffman tables (the DHT segment): the decoder takes the
// standard tables, which the encoder used, so the frame decodes to the same pixels.
TEST(V4l2ToGrey, MjpegWithoutHuffmanTablesDecodesAsWithThem) {
  std::vector<std::uint8_t> grey(std::size_t{kWidth} * kHeight);
  for (int j = 0; j < kHeight; ++j)
    for (int i = 0; i < kWidth; ++i) grey[std::size_t(j) * kWidth + i] = std::uint8_t(i * j % 251);
  const std::vector<std::uint8_t> jpeg = encode_jpeg(grey, kWidth, kHeight);
  ASSERT_FALSE(jpeg.empty());
  // Drop every DHT marker segment (FF C4, then a big-endian length that counts itself).
  std::vector<std::uint8_t> stripped(jpeg.begin(), jpeg.begin() + 2);
  std::size_t at = 2, dropped = 0;
  while (at + 4 <= jpeg.size() && jpeg[at] == 0xFF && jpeg[at + 1] != 0xDA) {
    const std::size_t length = 2 + (std::size_t{jpeg[at + 2]} << 8 | jpeg[at + 3]);
    if (jpeg[at + 1] == 0xC4)
      ++dropped;
    else
      stripped.insert(stripped.end(), jpeg.begin() + at, jpeg.begin() + at + length);
    at += length;
  }
  stripped.insert(stripped.end(), jpeg.begin() + at, jpeg.end());
  ASSERT_GT(dropped, 0u);
  const auto with =
      v4l2_to_grey(V4L2_PIX_FMT_MJPEG, jpeg.data(), jpeg.size(), kWidth, kHeight, 0, {});
  const auto without =
      v4l2_to_grey(V4L2_PIX_FMT_MJPEG, stripped.data(), stripped.size(), kWidth, kHeight, 0, {});
  ASSERT_TRUE(with) << with.message();
  ASSERT_TRUE(without) << without.message();
  EXPECT_EQ(without->pixels, with->pixels);
}

TEST(V4l2ToGrey, RefusesOtherFormatsShortBuffersBadJpegAndCropsOutside) {
  const std::vector<std::uint8_t> bytes(100, 0);
  const auto rgb = v4l2_to_grey(V4L2_PIX_FMT_RGB24, bytes.data(), bytes.size(), 4, 4, 0, {});
  ASSERT_FALSE(rgb);
  EXPECT_NE(rgb.message().find("RGB3"), std::string::npos) << rgb.message();
  const auto short_buffer =
      v4l2_to_grey(V4L2_PIX_FMT_YUYV, bytes.data(), bytes.size(), 10, 10, 0, {});
  ASSERT_FALSE(short_buffer);
  EXPECT_NE(short_buffer.message().find("short"), std::string::npos) << short_buffer.message();
  const auto jpeg = v4l2_to_grey(V4L2_PIX_FMT_MJPEG, bytes.data(), bytes.size(), 10, 10, 0, {});
  ASSERT_FALSE(jpeg);
  EXPECT_NE(jpeg.message().find("MJPG frame of 100 bytes"), std::string::npos) << jpeg.message();
  const auto outside =
      v4l2_to_grey(V4L2_PIX_FMT_GREY, bytes.data(), bytes.size(), 10, 10, 0, PixelRect{5, 5, 6, 2});
  ASSERT_FALSE(outside);
  EXPECT_NE(outside.message().find("not inside the 10x10 frame"), std::string::npos);
}

TEST(V4l2Mmap, FramesCarryTheDriversTimestampsAndPixels) {
  auto driver = std::make_shared<FakeDriver>();
  V4l2Options options = fake_options();
  options.width_px = 1280;  // more than the fake grants: the granted size is read back
  options.height_px = 720;
  options.frame_rate_hz = 25.0;
  V4l2FrameSource source(options, driver);
  for (std::uint32_t k = 0; k < 8; ++k) driver->push(filled(k, 1000.25 + k / 30.0));
  ASSERT_TRUE(source.start());
  const auto frames = take(source, 8);
  ASSERT_EQ(frames.size(), 8u) << source.message();
  for (std::size_t k = 0; k < frames.size(); ++k) {
    EXPECT_EQ(frames[k].index, static_cast<std::int64_t>(k));
    EXPECT_NEAR(frames[k].timestamp_s, 1000.25 + k / 30.0, 1e-6);
    ASSERT_EQ(frames[k].image.width, kWidth);
    EXPECT_EQ(frames[k].image.at(10, 3), static_cast<std::uint8_t>(10 + 6 + k));
  }
  const auto format = source.backend().format();
  ASSERT_TRUE(format);
  EXPECT_EQ(format->card, "fake grabber");
  EXPECT_EQ(fourcc_text(format->fourcc), "YUYV");
  EXPECT_EQ(format->width_px, kWidth);
  EXPECT_EQ(format->height_px, kHeight);
  EXPECT_EQ(format->bytes_per_line, kStride);
  EXPECT_EQ(format->io, V4l2Io::kMmap);
  EXPECT_EQ(format->buffers, 5);  // asked for 4, granted 5
  EXPECT_DOUBLE_EQ(format->frame_rate_hz, 25.0);
  EXPECT_TRUE(format->driver_timestamps);
  EXPECT_EQ(driver->maps(), 5);
  EXPECT_TRUE(driver->streaming());
  EXPECT_EQ(source.dropped(), 0u);
  EXPECT_EQ(source.state(), SourceState::kRunning);
}

TEST(V4l2Mmap, StopReleasesTheBuffersAndTheDevice) {
  auto driver = std::make_shared<FakeDriver>();
  V4l2FrameSource source(fake_options(), driver);
  driver->push(filled(0, 5.0));
  ASSERT_TRUE(source.start());
  ASSERT_EQ(take(source, 1).size(), 1u);
  source.stop();
  EXPECT_EQ(source.state(), SourceState::kEnded);
  EXPECT_FALSE(driver->streaming());
  EXPECT_EQ(driver->maps(), 0);
  EXPECT_EQ(driver->released_buffers(), 1);
  EXPECT_EQ(driver->open_fds(), 0);
}

TEST(V4l2Mmap, SequenceGapsAreCountedAsDriverDrops) {
  auto driver = std::make_shared<FakeDriver>();
  V4l2FrameSource source(fake_options(), driver);
  for (const std::uint32_t k : {10u, 11u, 14u, 15u, 20u}) driver->push(filled(k, k / 30.0));
  ASSERT_TRUE(source.start());
  ASSERT_EQ(take(source, 5).size(), 5u);
  EXPECT_EQ(source.backend().counters().driver_dropped, 2u + 4u);
  EXPECT_EQ(source.losses(), (std::map<std::string, std::size_t>{
                                 {"driver_dropped", 6}, {"error_frames", 0}, {"undecodable", 0}}));
  EXPECT_EQ(source.backend().counters().delivered, 5u);
  EXPECT_EQ(source.dropped(), 6u);
}

TEST(V4l2Mmap, ErrorBuffersAndEioAreDroppedAndCountedEintrAndEagainRetried) {
  auto driver = std::make_shared<FakeDriver>();
  V4l2FrameSource source(fake_options(), driver);
  driver->push(filled(0, 1.0));
  driver->push(EINTR);
  driver->push(filled(1, 2.0, V4L2_BUF_FLAG_ERROR));
  driver->push(EAGAIN);
  driver->push(EIO);
  driver->push(filled(2, 3.0));
  ASSERT_TRUE(source.start());
  const auto frames = take(source, 2);
  ASSERT_EQ(frames.size(), 2u) << source.message();
  EXPECT_DOUBLE_EQ(frames[0].timestamp_s, 1.0);
  EXPECT_DOUBLE_EQ(frames[1].timestamp_s, 3.0);
  EXPECT_EQ(frames[1].index, 1);
  EXPECT_EQ(source.backend().counters().error_frames, 2u);
  EXPECT_EQ(source.backend().counters().driver_dropped,
            0u);                          // the error buffer kept its sequence number
  EXPECT_EQ(driver->stream_starts(), 2);  // EIO restarted the stream
  EXPECT_EQ(source.dropped(), 2u);
  EXPECT_EQ(source.state(), SourceState::kRunning);
}

TEST(V4l2Mmap, UnplugIsReportedAndCaptureResumesWhenTheDeviceReturns) {
  auto driver = std::make_shared<FakeDriver>();
  V4l2FrameSource source(fake_options(), driver);
  driver->push(filled(0, 1.0));
  driver->push(filled(1, 1.1));
  ASSERT_TRUE(source.start());
  ASSERT_EQ(take(source, 2).size(), 2u);

  driver->set_present(false);  // every call fails with ENODEV, open with ENOENT
  ASSERT_TRUE(eventually([&] { return !source.condition().empty(); }));
  EXPECT_NE(source.condition().find("vanished"), std::string::npos) << source.condition();
  EXPECT_EQ(source.state(), SourceState::kRunning);  // the scan goes on
  EXPECT_EQ(source.backend().counters().unplugs, 1u);
  ASSERT_TRUE(eventually([&] { return driver->open_fds() == 0; }));
  EXPECT_EQ(driver->maps(), 0);                                // the old mappings are gone
  std::this_thread::sleep_for(std::chrono::milliseconds(80));  // several failed reopens

  driver->set_present(true);
  driver->push(filled(0, 2.0));  // a fresh device numbers from 0 again: no gap
  driver->push(filled(1, 2.1));
  const auto after = take(source, 2);
  ASSERT_EQ(after.size(), 2u) << source.condition();
  EXPECT_EQ(after[0].index, 2);
  EXPECT_DOUBLE_EQ(after[1].timestamp_s, 2.1);
  EXPECT_EQ(source.condition(), "");
  EXPECT_EQ(source.backend().counters().reopens, 1u);
  EXPECT_EQ(source.backend().counters().driver_dropped, 0u);
  EXPECT_EQ(driver->maps(), 5);
}

TEST(V4l2Mmap, AFormatTheDeviceDoesNotOfferFailsListingWhatItOffers) {
  auto driver = std::make_shared<FakeDriver>();
  driver->offered = {V4L2_PIX_FMT_RGB24, V4L2_PIX_FMT_NV12};
  V4l2FrameSource source(fake_options(), driver);
  ASSERT_TRUE(source.start());
  EXPECT_TRUE(take(source, 1).empty());
  EXPECT_EQ(source.state(), SourceState::kFailed);
  EXPECT_NE(source.message().find("it offers RGB3, NV12"), std::string::npos) << source.message();
  EXPECT_EQ(driver->open_fds(), 0);

  auto grey_only = std::make_shared<FakeDriver>();
  grey_only->offered = {V4L2_PIX_FMT_GREY};
  V4l2Options options = fake_options();
  options.pixel_format = "MJPG";
  V4l2FrameSource asked(options, grey_only);
  ASSERT_TRUE(asked.start());
  EXPECT_TRUE(take(asked, 1).empty());
  EXPECT_NE(asked.message().find("offers no MJPG frames; it offers GREY"), std::string::npos)
      << asked.message();
}

TEST(V4l2Mmap, ACropOutsideTheGrantedFrameFailsAtOpen) {
  auto driver = std::make_shared<FakeDriver>();
  V4l2Options options = fake_options();
  options.crop = PixelRect{0, 0, 100, 10};  // the fake grants 64x48
  V4l2FrameSource source(options, driver);
  ASSERT_TRUE(source.start());
  EXPECT_TRUE(take(source, 1).empty());
  EXPECT_NE(source.message().find("not inside the 64x48 frame"), std::string::npos)
      << source.message();
}

}  // namespace
}  // namespace sonoshape::acquisition::v4l2_source_test
