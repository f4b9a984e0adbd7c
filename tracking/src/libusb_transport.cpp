// The libusb-1.0 transport of the trakSTAR backend (built with SONOSHAPE_WITH_LIBUSB).
#include <libusb.h>

#include <atomic>
#include <cmath>
#include <cstdio>
#include <memory>
#include <mutex>
#include <string>

#include "sonoshape/tracking/trakstar_source.hpp"

namespace sonoshape::tracking {
namespace {

// Without a hotplug event, an unplugged tracker is still looked for every this many tries
// (an event can be missed while the device initialises).
constexpr int kEnumerateEvery = 10;

int timeout_ms(double timeout_s) {
  // libusb reads 0 as "no timeout"; the shortest wait is 1 ms.
  return std::max(1, static_cast<int>(std::lround(timeout_s * 1e3)));
}

// One libusb context for the process, with a hotplug callback for vendor 0x21E2 where the
// platform has hotplug (LIBUSB_CAP_HAS_HOTPLUG); else openers enumerate each time.
class UsbContext {
 public:
  static std::shared_ptr<UsbContext> get(std::string& error) {
    static std::mutex mutex;
    static std::weak_ptr<UsbContext> shared;
    std::lock_guard lock(mutex);
    if (auto existing = shared.lock()) return existing;
    auto made = std::shared_ptr<UsbContext>(new UsbContext());
    if (const int rc = libusb_init(&made->context_); rc != 0) {
      made->context_ = nullptr;
      error = std::string("libusb_init failed: ") + libusb_strerror(rc);
      return nullptr;
    }
    made->register_hotplug();
    shared = made;
    return made;
  }
  ~UsbContext() {
    if (!context_) return;
    if (hotplug_) libusb_hotplug_deregister_callback(context_, hotplug_handle_);
    libusb_exit(context_);
  }
  libusb_context* context() const { return context_; }
  bool has_hotplug() const { return hotplug_; }
  /// Handles pending events without waiting; true when a tracker arrived since the last call.
  bool take_arrival() {
    timeval zero{};
    libusb_handle_events_timeout_completed(context_, &zero, nullptr);
    return arrived_.exchange(false);
  }

 private:
  UsbContext() = default;
  void register_hotplug() {
    if (!libusb_has_capability(LIBUSB_CAP_HAS_HOTPLUG)) return;
    const int rc = libusb_hotplug_register_callback(
        context_, LIBUSB_HOTPLUG_EVENT_DEVICE_ARRIVED, LIBUSB_HOTPLUG_NO_FLAGS, kTrakstarVendorId,
        LIBUSB_HOTPLUG_MATCH_ANY, LIBUSB_HOTPLUG_MATCH_ANY, &UsbContext::on_arrival, this,
        &hotplug_handle_);
    hotplug_ = rc == LIBUSB_SUCCESS;
  }
  static int LIBUSB_CALL on_arrival(libusb_context*, libusb_device*, libusb_hotplug_event,
                                    void* self) {
    static_cast<UsbContext*>(self)->arrived_.store(true);
    return 0;  // stay registered
  }

  libusb_context* context_ = nullptr;
  bool hotplug_ = false;
  libusb_hotplug_callback_handle hotplug_handle_{};
  std::atomic<bool> arrived_{false};
};

UsbIo to_io(int rc) {
  switch (rc) {
    case LIBUSB_SUCCESS:
      return UsbIo::kOk;
    case LIBUSB_ERROR_TIMEOUT:
      return UsbIo::kTimeout;
    case LIBUSB_ERROR_NO_DEVICE:
      return UsbIo::kGone;
    default:
      return UsbIo::kError;
  }
}

class LibusbTransport final : public BirdTransport {
 public:
  LibusbTransport(std::shared_ptr<UsbContext> context, libusb_device_handle* handle)
      : context_(std::move(context)), handle_(handle) {}
  ~LibusbTransport() override {
    libusb_release_interface(handle_, 0);
    libusb_close(handle_);
  }

  UsbIo write(std::span<const std::uint8_t> bytes, double timeout_s) override {
    std::vector<std::uint8_t> data(bytes.begin(), bytes.end());  // libusb takes non-const
    int sent = 0;
    const int rc =
        libusb_bulk_transfer(handle_, kTrakstarEndpointOut, data.data(),
                             static_cast<int>(data.size()), &sent, timeout_ms(timeout_s));
    if (rc == LIBUSB_ERROR_PIPE) return stalled(kTrakstarEndpointOut);
    if (rc == LIBUSB_SUCCESS && sent != static_cast<int>(data.size())) return UsbIo::kTimeout;
    return to_io(rc);
  }

  UsbIo read(std::span<std::uint8_t> buffer, std::size_t& received, double timeout_s) override {
    int got = 0;
    const int rc =
        libusb_bulk_transfer(handle_, kTrakstarEndpointIn, buffer.data(),
                             static_cast<int>(buffer.size()), &got, timeout_ms(timeout_s));
    received = static_cast<std::size_t>(std::max(got, 0));
    if (rc == LIBUSB_ERROR_PIPE) return stalled(kTrakstarEndpointIn);
    // A timeout may still have delivered part of a record.
    if (rc == LIBUSB_ERROR_TIMEOUT && received > 0) return UsbIo::kOk;
    return to_io(rc);
  }

 private:
  // A halted endpoint (STALL) is cleared; the caller retries.
  UsbIo stalled(std::uint8_t endpoint) {
    const int rc = libusb_clear_halt(handle_, endpoint);
    return rc == LIBUSB_ERROR_NO_DEVICE ? UsbIo::kGone : UsbIo::kStalled;
  }

  std::shared_ptr<UsbContext> context_;  // outlives the handle
  libusb_device_handle* handle_;
};

// The first device of vendor 0x21E2 (and `product_id` unless 0), opened; none with `error`.
libusb_device_handle* open_first(libusb_context* context, std::uint16_t product_id,
                                 std::string& error) {
  libusb_device** list = nullptr;
  const ssize_t count = libusb_get_device_list(context, &list);
  if (count < 0) {
    error = std::string("cannot list USB devices: ") + libusb_strerror(static_cast<int>(count));
    return nullptr;
  }
  libusb_device_handle* handle = nullptr;
  error = "no trakSTAR/driveBAY (USB vendor 0x21e2) found: check the cable and the power";
  for (ssize_t i = 0; i < count && !handle; ++i) {
    libusb_device_descriptor descriptor{};
    if (libusb_get_device_descriptor(list[i], &descriptor) != 0) continue;
    if (descriptor.idVendor != kTrakstarVendorId) continue;
    if (product_id != 0 && descriptor.idProduct != product_id) continue;
    if (const int rc = libusb_open(list[i], &handle); rc != 0) {
      handle = nullptr;
      error = std::string("cannot open the tracker: ") + libusb_strerror(rc) +
              (rc == LIBUSB_ERROR_ACCESS
                   ? " (add a udev rule giving your user access to vendor 21e2, or run as root)"
                   : "");
    }
  }
  libusb_free_device_list(list, 1);
  return handle;
}

}  // namespace

bool have_libusb() { return true; }

BirdTransportOpener libusb_trakstar_opener(const TrakstarOptions& options) {
  // The opener keeps the libusb context (and its hotplug callback) between tries: the source
  // owns the opener, so the context lives as long as the source.
  struct State {
    std::shared_ptr<UsbContext> context;
    int tries = 0;
  };
  auto state = std::make_shared<State>();
  const std::uint16_t product_id = options.product_id;
  return [product_id, state](std::string& error) -> std::unique_ptr<BirdTransport> {
    if (!state->context) state->context = UsbContext::get(error);
    if (!state->context) return nullptr;
    UsbContext& context = *state->context;
    // With hotplug, look only when a tracker arrived (or now and then): enumerating the bus
    // twice a second is what polling platforms pay.
    const bool arrived = context.has_hotplug() && context.take_arrival();
    const bool look = state->tries == 0 || !context.has_hotplug() || arrived ||
                      state->tries % kEnumerateEvery == 0;
    ++state->tries;
    if (!look) {
      error = "no trakSTAR/driveBAY: waiting for it to be plugged in";
      return nullptr;
    }
    libusb_device_handle* handle = open_first(context.context(), product_id, error);
    if (!handle) return nullptr;
    libusb_set_auto_detach_kernel_driver(handle, 1);
    if (const int rc = libusb_claim_interface(handle, 0); rc != 0) {
      error = std::string("cannot claim the tracker's USB interface: ") + libusb_strerror(rc) +
              " (is another program using it?)";
      libusb_close(handle);
      return nullptr;
    }
    state->tries = 0;
    return std::make_unique<LibusbTransport>(state->context, handle);
  };
}

Result<std::vector<FoundTracker>> find_trakstars() {
  std::string error;
  auto context = UsbContext::get(error);
  if (!context) return Status::error(error);
  libusb_device** list = nullptr;
  const ssize_t count = libusb_get_device_list(context->context(), &list);
  if (count < 0)
    return Status::error(std::string("cannot list USB devices: ") +
                         libusb_strerror(static_cast<int>(count)));
  std::vector<FoundTracker> found;
  for (ssize_t i = 0; i < count; ++i) {
    libusb_device_descriptor descriptor{};
    if (libusb_get_device_descriptor(list[i], &descriptor) != 0) continue;
    if (descriptor.idVendor != kTrakstarVendorId) continue;
    char product[8];
    std::snprintf(product, sizeof product, "0x%04x", descriptor.idProduct);
    found.push_back({std::string("usb:trakstar:product=") + product,
                     "USB bus " + std::to_string(libusb_get_bus_number(list[i])) + " device " +
                         std::to_string(libusb_get_device_address(list[i])) +
                         ", vendor 0x21e2 product " + product});
  }
  libusb_free_device_list(list, 1);
  return found;
}

}  // namespace sonoshape::tracking
