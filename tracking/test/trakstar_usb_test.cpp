// The trakSTAR source end to end through libusb under umockdev: a USB device of vendor 0x21e2 in
// a fake sysfs, and an ioctl handler on its usbfs node that answers the bulk URBs libusb submits
// (USBDEVFS_SUBMITURB / REAPURB[NDELAY] / DISCARDURB) with the Bird emulator behind them.
// Faults: garbage bytes, a stalled IN endpoint (EPIPE), a detached sensor, and an unplug and
// replug mid-stream. Runs under umockdev-wrapper (ctest does so); skipped without it.
#include <gtest/gtest.h>
#include <linux/usbdevice_fs.h>
#include <sys/ioctl.h>
#include <umockdev.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cstddef>
#include <cstdlib>
#include <cstring>
#include <deque>
#include <mutex>
#include <thread>

#include "bird_emulator.hpp"
#include "pose_samples.hpp"
#include "sonoshape/testing/trakstar_usb_record.hpp"
#include "sonoshape/tracking/trakstar_source.hpp"

namespace sonoshape::tracking::trakstar_usb_test {
namespace {

using test::BirdEmulator;
using test::PointFault;

constexpr const char* kDevNode = "/dev/bus/usb/001/002";
constexpr const char* kSysPath = sonoshape::testing::kTrakstarSysPath;

// A usbfs device node served by the emulator. Runs in umockdev's worker thread.
class UsbDeviceHandler {
 public:
  BirdEmulator emulator;
  std::atomic<bool> gone{false};
  std::atomic<int> stall_next_in{0};  // IN URBs to complete with EPIPE (a halted endpoint)
  std::atomic<int> clear_halts{0};

  static gboolean on_ioctl(UMockdevIoctlBase*, UMockdevIoctlClient* client, gpointer self) {
    return static_cast<UsbDeviceHandler*>(self)->handle(client);
  }

  ~UsbDeviceHandler() {
    for (Urb& u : in_) g_object_unref(u.urb);
    for (Urb& u : done_) g_object_unref(u.urb);
  }

 private:
  struct Urb {
    UMockdevIoctlData* urb;     // the client's struct usbdevfs_urb (owned reference)
    UMockdevIoctlData* buffer;  // its buffer (a child of urb)
  };

  static usbdevfs_urb* fields(const Urb& u) { return reinterpret_cast<usbdevfs_urb*>(u.urb->data); }

  gboolean handle(UMockdevIoctlClient* client) {
    std::lock_guard lock(mutex_);
    const unsigned long request = umockdev_ioctl_client_get_request(client);
    UMockdevIoctlData* arg = umockdev_ioctl_client_get_arg(client);
    // A vanished device answers ENODEV, but for the reaps: as the kernel's usbfs, it still hands
    // back the URBs it had (those in flight killed), then ENODEV. Answering ENODEV to a reap too
    // left a transfer submitted before the unplug in flight for good (libusb waits for it and
    // cannot cancel it), which hung the unplug test under load.
    const bool reap_request = request == USBDEVFS_REAPURB || request == USBDEVFS_REAPURBNDELAY;
    if (gone && request != USBDEVFS_RELEASEINTERFACE && !reap_request) {
      umockdev_ioctl_client_complete(client, -1, ENODEV);
      return TRUE;
    }
    switch (request) {
      case USBDEVFS_GET_CAPABILITIES: {
        UMockdevIoctlData* data =
            umockdev_ioctl_data_resolve(arg, 0, sizeof(std::uint32_t), nullptr);
        const std::uint32_t caps = USBDEVFS_CAP_BULK_CONTINUATION | USBDEVFS_CAP_NO_PACKET_SIZE_LIM;
        std::memcpy(data->data, &caps, sizeof caps);
        umockdev_ioctl_client_complete(client, 0, 0);
        g_object_unref(data);
        return TRUE;
      }
      case USBDEVFS_CLEAR_HALT:
        ++clear_halts;
        [[fallthrough]];
      case USBDEVFS_CLAIMINTERFACE:
      case USBDEVFS_RELEASEINTERFACE:
      case USBDEVFS_DISCONNECT_CLAIM:
      case USBDEVFS_SETINTERFACE:
      case USBDEVFS_RESETEP:
        umockdev_ioctl_client_complete(client, 0, 0);
        return TRUE;
      case USBDEVFS_GETDRIVER:
      case USBDEVFS_IOCTL:
        umockdev_ioctl_client_complete(client, -1, ENODATA);  // no kernel driver bound
        return TRUE;
      case USBDEVFS_SUBMITURB:
        return submit(client, arg);
      case USBDEVFS_REAPURB:
      case USBDEVFS_REAPURBNDELAY:
        return reap(client, arg);
      case USBDEVFS_DISCARDURB:
        return discard(client, arg);
      default:
        umockdev_ioctl_client_complete(client, -1, ENOTTY);
        return TRUE;
    }
  }

  gboolean submit(UMockdevIoctlClient* client, UMockdevIoctlData* arg) {
    Urb u{umockdev_ioctl_data_resolve(arg, 0, sizeof(usbdevfs_urb), nullptr), nullptr};
    if (!u.urb) return FALSE;  // resolve() gave us a reference: the queue's
    usbdevfs_urb* f = fields(u);
    u.buffer = umockdev_ioctl_data_resolve(u.urb, offsetof(usbdevfs_urb, buffer),
                                           static_cast<gsize>(f->buffer_length), nullptr);
    if (u.buffer) g_object_unref(u.buffer);  // the urb's child list keeps it
    if ((f->endpoint & 0x80) == 0) {
      if (u.buffer) emulator.receive({u.buffer->data, u.buffer->data + f->buffer_length});
      f->actual_length = f->buffer_length;
      f->status = 0;
      done_.push_back(u);
    } else {
      in_.push_back(u);
    }
    umockdev_ioctl_client_complete(client, 0, 0);
    return TRUE;
  }

  // Completes the oldest IN URB with what the emulator has to say, if anything.
  void fill_in() {
    if (in_.empty()) return;
    Urb u = in_.front();
    usbdevfs_urb* f = fields(u);
    if (stall_next_in > 0) {
      --stall_next_in;
      f->status = -EPIPE;
      f->actual_length = 0;
    } else {
      const auto bytes = emulator.take(static_cast<std::size_t>(f->buffer_length));
      if (bytes.empty()) return;
      std::memcpy(u.buffer->data, bytes.data(), bytes.size());
      f->actual_length = static_cast<int>(bytes.size());
      f->status = 0;
    }
    in_.pop_front();
    done_.push_back(u);
  }

  gboolean reap(UMockdevIoctlClient* client, UMockdevIoctlData* arg) {
    if (gone) {
      // Unplugged: the URBs in flight end with ESHUTDOWN, as the kernel kills them.
      for (Urb& u : in_) {
        fields(u)->status = -ESHUTDOWN;
        fields(u)->actual_length = 0;
        done_.push_back(u);
      }
      in_.clear();
    } else {
      fill_in();
    }
    if (done_.empty()) {
      umockdev_ioctl_client_complete(client, -1, gone ? ENODEV : EAGAIN);
      return TRUE;
    }
    Urb u = done_.front();
    done_.pop_front();
    UMockdevIoctlData* slot = umockdev_ioctl_data_resolve(arg, 0, sizeof(void*), nullptr);
    umockdev_ioctl_data_set_ptr(slot ? slot : arg, 0, u.urb);
    umockdev_ioctl_client_complete(client, 0, 0);
    if (slot) g_object_unref(slot);
    g_object_unref(u.urb);
    return TRUE;
  }

  gboolean discard(UMockdevIoctlClient* client, UMockdevIoctlData* arg) {
    const gulong address = *reinterpret_cast<gulong*>(arg->data);
    for (auto it = in_.begin(); it != in_.end(); ++it) {
      if (it->urb->client_addr != address) continue;
      fields(*it)->status = -ENOENT;
      fields(*it)->actual_length = 0;
      done_.push_back(*it);
      in_.erase(it);
      umockdev_ioctl_client_complete(client, 0, 0);
      return TRUE;
    }
    umockdev_ioctl_client_complete(client, -1, EINVAL);
    return TRUE;
  }

  std::mutex mutex_;
  std::deque<Urb> in_;
  std::deque<Urb> done_;
};

// The sysfs record of a trakSTAR: vendor 0x21e2, one interface with bulk endpoints 0x02 / 0x86.
class TrakstarTestbed {
 public:
  TrakstarTestbed() : testbed_(umockdev_testbed_new()), base_(umockdev_ioctl_base_new()) {
    g_signal_connect(base_, "handle-ioctl", G_CALLBACK(UsbDeviceHandler::on_ioctl), &handler);
    plug();
    GError* error = nullptr;
    attached_ = umockdev_testbed_attach_ioctl(testbed_, kDevNode, base_, &error);
    if (error) {
      attach_error_ = error->message;
      g_error_free(error);
    }
  }
  ~TrakstarTestbed() {
    umockdev_testbed_detach_ioctl(testbed_, kDevNode, nullptr);
    g_object_unref(base_);
    g_object_unref(testbed_);
  }

  void plug() {
    GError* error = nullptr;
    if (!umockdev_testbed_add_from_string(testbed_, sonoshape::testing::kTrakstarUsbRecord,
                                          &error)) {
      ADD_FAILURE() << "umockdev record: " << error->message;
      g_error_free(error);
    }
  }
  // Unplugging answers every ioctl with ENODEV, as the kernel does for a vanished device, but
  // keeps the emulated node: removing it from the testbed while the source's reader waits in a
  // transfer leaves that ioctl unanswered for good (umockdev serves it through a socket of the
  // node), which hung the test under load.
  void unplug() {
    handler.gone = true;
    umockdev_testbed_uevent(testbed_, kSysPath, "remove");
  }
  void replug() {
    handler.gone = false;
    umockdev_testbed_uevent(testbed_, kSysPath, "add");
  }

  bool attached() const { return attached_; }
  const std::string& attach_error() const { return attach_error_; }

  UsbDeviceHandler handler;

 private:
  UMockdevTestbed* testbed_;
  UMockdevIoctlBase* base_;
  bool attached_ = false;
  std::string attach_error_;
};

TrakstarOptions fast_options() {
  TrakstarOptions options;
  options.rate_hz = 200.0;
  // Generous: umockdev answers through a socket, and these tests failed once under a parallel
  // ctest on a loaded machine with 0.2 s, where a late reply counts as a timeout the tests do
  // not expect. A planted stall costs one whole timeout.
  options.reply_timeout_s = 1.0;
  options.reopen_interval_s = 0.02;
  return options;
}

using test::count_valid;
using test::take;
using test::take_then_stop;
using test::within_one;

class TrakstarUsb : public ::testing::Test {
 protected:
  void SetUp() override {
    // Not umockdev_in_mock_environment(): it caches its answer, which is false until a testbed
    // exists, and the testbed then sends no uevents.
    const char* preload = std::getenv("LD_PRELOAD");
    if (!preload || !std::strstr(preload, "umockdev-preload"))
      GTEST_SKIP() << "run under umockdev-wrapper (ctest does)";
    if (!have_libusb()) GTEST_SKIP() << "built without libusb";
  }
};

TEST_F(TrakstarUsb, KnownPosesArriveThroughLibusbWithFaultsCountedByReason) {
  TrakstarTestbed bed;
  ASSERT_TRUE(bed.attached()) << bed.attach_error();
  bed.handler.emulator.faults = {{2, PointFault::kGarbage},
                                 {4, PointFault::kDetached},
                                 {5, PointFault::kOutOfRange},
                                 {7, PointFault::kStall}};
  TrakstarOptions options = fast_options();
  options.sensor = 2;
  TrakstarPoseSource source(options);
  ASSERT_TRUE(source.start());
  // POINTs 0..10, the stall unanswered: 10 samples.
  const auto poses = take_then_stop(source, 10);
  ASSERT_GE(poses.size(), 10u) << source.message();
  EXPECT_EQ(bed.handler.emulator.value(bird::kParamMeasurementRate), 200 * 256);
  EXPECT_EQ(bed.handler.emulator.last_address(), 2);
  const auto sent = bed.handler.emulator.sent();
  std::size_t valid = 0;
  for (std::size_t k = 0; k < poses.size(); ++k) {
    const bool invalid = k == 4 || k == 5;
    ASSERT_EQ(poses[k].status, invalid ? TrackingStatus::kInvalid : TrackingStatus::kValid) << k;
    if (invalid) continue;
    const Eigen::Isometry3d& expected = sent[valid++];
    EXPECT_LT((poses[k].T_reference_probe.translation() - expected.translation()).norm(), 0.2);
    EXPECT_LT((poses[k].T_reference_probe.linear() - expected.linear()).cwiseAbs().maxCoeff(),
              1e-3);
  }
  const TrakstarCounts c = source.backend().counts();
  within_one(c.valid, count_valid(poses));
  EXPECT_EQ(c.not_attached, 1u);
  EXPECT_EQ(c.out_of_range, 1u);
  EXPECT_EQ(c.timeouts, 1u);
  EXPECT_EQ(c.skipped_bytes, 3u);
}

TEST_F(TrakstarUsb, FindTrakstarsListsTheDeviceInTheFormTrackerTakes) {
  TrakstarTestbed bed;
  const auto found = find_trakstars();
  ASSERT_TRUE(found) << found.message();
  ASSERT_EQ(found->size(), 1u);
  EXPECT_EQ((*found)[0].spec, "usb:trakstar:product=0x0001");
  EXPECT_EQ((*found)[0].description, "USB bus 1 device 2, vendor 0x21e2 product 0x0001");
  const auto options = parse_trakstar_options(
      std::string_view((*found)[0].spec).substr(std::string_view("usb:trakstar:").size()));
  ASSERT_TRUE(options);
  EXPECT_EQ(options->product_id, 1);
}

TEST_F(TrakstarUsb, AStalledEndpointIsClearedAndPosesContinue) {
  TrakstarTestbed bed;
  ASSERT_TRUE(bed.attached()) << bed.attach_error();
  TrakstarPoseSource source(fast_options());
  ASSERT_TRUE(source.start());
  ASSERT_EQ(take(source, 3).size(), 3u) << source.message();
  bed.handler.stall_next_in = 1;
  const auto after = take_then_stop(source, 5);
  ASSERT_GE(after.size(), 5u) << source.message();
  for (const Pose& p : after) EXPECT_EQ(p.status, TrackingStatus::kValid);
  EXPECT_GE(bed.handler.clear_halts.load(), 1);
  EXPECT_EQ(source.backend().counts().stalls, 1u);
  EXPECT_EQ(source.backend().counts().timeouts, 0u);  // the record still came after the clear
  EXPECT_EQ(source.backend().counts().unplugged, 0u);
}

TEST_F(TrakstarUsb, UnplugAndReplugMidStreamAreReportedAndRecovered) {
  TrakstarTestbed bed;
  ASSERT_TRUE(bed.attached()) << bed.attach_error();
  TrakstarPoseSource source(fast_options());
  ASSERT_TRUE(source.start());
  ASSERT_EQ(take(source, 5).size(), 5u) << source.message();
  bed.unplug();
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(10);
  while (source.backend().connected() && std::chrono::steady_clock::now() < deadline)
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  ASSERT_FALSE(source.backend().connected());
  EXPECT_EQ(source.state(), acquisition::SourceState::kRunning);
  EXPECT_NE(source.backend().status_line().find("waiting for the tracker"), std::string::npos);
  std::this_thread::sleep_for(std::chrono::milliseconds(100));
  EXPECT_FALSE(source.backend().connected());  // nothing to reopen while unplugged
  while (source.next(0.0)) {
  }
  bed.replug();
  const auto after = take_then_stop(source, 5);
  ASSERT_GE(after.size(), 5u) << source.backend().status_line();
  for (const Pose& p : after) EXPECT_EQ(p.status, TrackingStatus::kValid);
  EXPECT_EQ(source.backend().counts().unplugged, 1u);
  EXPECT_EQ(source.backend().counts().reopened, 1u);
}

}  // namespace
}  // namespace sonoshape::tracking::trakstar_usb_test
