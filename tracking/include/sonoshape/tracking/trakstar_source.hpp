#pragma once
// The NDI / Ascension trakSTAR and driveBAY (3D Guidance) electromagnetic trackers over USB
// (libusb-1.0; vendor 0x21E2, bulk OUT 0x02 / IN 0x86, the Bird command set: see
// tracking/src/bird_codec.hpp for the protocol, its sources and its assumptions).
//
// The source polls one sensor (POINT on its address) and delivers T_reference_probe =
// T_tracker_sensor in millimetres, stamped with CLOCK_MONOTONIC at reception minus the
// configured latency. Records with a sensor not attached, out of range, or not a rotation are
// delivered as kInvalid poses and counted by reason. An unplugged tracker is reported in
// status_line() and reopened when it comes back (libusb hotplug where the platform has it,
// else polling); the source keeps running meanwhile.
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "sonoshape/core/status.hpp"
#include "sonoshape/tracking/pose_source.hpp"

namespace sonoshape::tracking {

/// The trakSTAR's USB identity and endpoints.
inline constexpr std::uint16_t kTrakstarVendorId = 0x21E2;
inline constexpr std::uint8_t kTrakstarEndpointOut = 0x02;
inline constexpr std::uint8_t kTrakstarEndpointIn = 0x86;

/// What `--tracker usb:trakstar[:KEY=VALUE,...]` sets.
struct TrakstarOptions {
  int sensor = 1;                  ///< the sensor's bird address (port), 1..14
  double rate_hz = 80.0;           ///< measurement rate (Hz), 20..255 (sent as Hz x 256)
  bool long_range = false;         ///< position full scale 72 in (POSITION SCALING 1), else 36 in
  double latency_s = 0.0;          ///< subtracted from the reception time of every sample (s)
  double reply_timeout_s = 0.1;    ///< how long one POINT waits for its record (s)
  double reopen_interval_s = 0.5;  ///< how often an unplugged tracker is looked for (s)
  std::uint16_t product_id = 0;    ///< USB product id to open; 0: the first of vendor 0x21E2
};

/// Parses "sensor=2,rate=80,range=72,latency_ms=4,product=0x0007" (every key optional; empty:
/// the defaults). Fails naming the key and the values it takes.
Result<TrakstarOptions> parse_trakstar_options(std::string_view text);

/// The outcome of one bulk transfer.
enum class UsbIo {
  kOk,
  kTimeout,
  kStalled,  ///< the endpoint halted (STALL); the transport cleared it, nothing was moved
  kGone,     ///< the device was unplugged
  kError,
};

/// Bulk I/O with one opened tracker: the seam between the Bird protocol and libusb (tests
/// drive the source through an emulator). Used from the source's thread only.
class BirdTransport {
 public:
  virtual ~BirdTransport() = default;
  /// Writes all of `bytes` (bulk OUT). kGone: the device was unplugged.
  virtual UsbIo write(std::span<const std::uint8_t> bytes, double timeout_s) = 0;
  /// Reads up to `buffer.size()` bytes (bulk IN) into `buffer`; `received` = bytes read.
  /// kTimeout with received 0: nothing came in time.
  virtual UsbIo read(std::span<std::uint8_t> buffer, std::size_t& received, double timeout_s) = 0;
};

/// Opens a transport to the tracker. None (with `error` set) when no tracker is there.
using BirdTransportOpener = std::function<std::unique_ptr<BirdTransport>(std::string& error)>;
/// The libusb opener of `options` (vendor 0x21E2, options.product_id); none when sonoshape was
/// built without libusb (SONOSHAPE_WITH_LIBUSB off): then every open fails saying so.
BirdTransportOpener libusb_trakstar_opener(const TrakstarOptions& options);
/// Whether this build has the libusb backend.
bool have_libusb();

/// A tracker found on USB, in the form `--tracker` takes.
struct FoundTracker {
  std::string spec;         ///< e.g. "usb:trakstar:product=0x0001"
  std::string description;  ///< e.g. "USB bus 1 device 2, vendor 0x21e2 product 0x0001"
};
/// The trakSTAR / driveBAY units on USB (vendor 0x21E2), without opening them (for `sonoshape
/// devices`). Fails when libusb cannot list devices or the build has no libusb.
Result<std::vector<FoundTracker>> find_trakstars();

/// Counts of what the source received, by reason.
struct TrakstarCounts {
  std::size_t valid = 0;
  std::size_t not_attached = 0;   ///< kInvalid: no sensor on the port
  std::size_t out_of_range = 0;   ///< kInvalid: beyond the position full scale
  std::size_t bad_rotation = 0;   ///< kInvalid: corrupt orientation
  std::size_t timeouts = 0;       ///< POINTs without a record in time
  std::size_t stalls = 0;         ///< halted endpoints cleared (USB STALL)
  std::size_t skipped_bytes = 0;  ///< garbage and cut records
  std::size_t unplugged = 0;      ///< times the tracker vanished
  std::size_t reopened = 0;       ///< times it came back
};

/// A live trakSTAR pose source. Open failures at start fail the source (no tracker, no
/// permission, the device does not answer the protocol); later unplugs do not.
class TrakstarPoses final : public PoseBackend {
 public:
  /// `opener` empty: libusb_trakstar_opener(options).
  explicit TrakstarPoses(TrakstarOptions options, BirdTransportOpener opener = {});

  std::string describe() const override;
  /// The counts so far (any thread).
  TrakstarCounts counts() const;
  /// "connected", or "unplugged since ..., waiting for it" (any thread).
  std::string status_line() const;
  /// Whether a tracker is open now (any thread).
  bool connected() const { return connected_.load(); }

 protected:
  Status open() override;
  Result<acquisition::Polled> poll(Pose& pose) override;
  void close() override;

 private:
  Status connect();
  Status configure();
  // One POINT and its record; none on a timeout, or when the tracker vanished (then
  // transport_ is reset).
  std::optional<std::vector<std::uint8_t>> point();
  Pose to_pose(const std::vector<std::uint8_t>& record, double received_s);
  void drain_input();
  void lost(const std::string& why);
  Result<acquisition::Polled> reopen();
  void count(const std::function<void(TrakstarCounts&)>& change);
  void set_status(std::string line);

  TrakstarOptions options_;
  BirdTransportOpener opener_;
  std::unique_ptr<BirdTransport> transport_;
  double next_reopen_s_ = 0.0;
  double next_point_s_ = 0.0;  // POINTs are paced at the measurement rate
  bool drain_ = false;         // a POINT timed out: its record may still come
  std::atomic<bool> connected_{false};
  mutable std::mutex mutex_;  // guards counts_ and status_
  TrakstarCounts counts_;
  std::string status_ = "not started";
};
/// The stream of a TrakstarPoses.
using TrakstarPoseSource = acquisition::SourceOf<TrakstarPoses>;

}  // namespace sonoshape::tracking
