#include "sonoshape/tracking/trakstar_source.hpp"

#include <time.h>

#include <algorithm>
#include <array>
#include <charconv>
#include <chrono>
#include <cmath>
#include <sstream>
#include <thread>
#include <utility>

#include "bird_codec.hpp"
#include "sonoshape/core/log.hpp"

namespace sonoshape::tracking {
namespace {

constexpr auto kFormat = bird::RecordFormat::kPositionMatrix;

// CLOCK_MONOTONIC (s): the clock V4L2 stamps frames with (V4L2_BUF_FLAG_TIMESTAMP_MONOTONIC).
double clock_monotonic_s() {
  timespec now{};
  clock_gettime(CLOCK_MONOTONIC, &now);
  return static_cast<double>(now.tv_sec) + 1e-9 * static_cast<double>(now.tv_nsec);
}

std::optional<double> parse_number(std::string_view text) {
  double value = 0.0;
  const auto [end, error] = std::from_chars(text.data(), text.data() + text.size(), value);
  if (error != std::errc() || end != text.data() + text.size() || !std::isfinite(value))
    return std::nullopt;
  return value;
}

Status set_option(TrakstarOptions& options, std::string_view key, std::string_view value) {
  const auto bad = [&](const std::string& takes) {
    return Status::error("--tracker usb:trakstar: '" + std::string(key) + "=" + std::string(value) +
                         "' is invalid; " + std::string(key) + " takes " + takes);
  };
  if (key == "product") {
    unsigned id = 0;
    const bool hex = value.starts_with("0x") || value.starts_with("0X");
    const std::string_view digits = hex ? value.substr(2) : value;
    const auto [end, error] =
        std::from_chars(digits.data(), digits.data() + digits.size(), id, hex ? 16 : 10);
    if (digits.empty() || error != std::errc() || end != digits.data() + digits.size() ||
        id > 0xFFFF)
      return bad("a USB product id, e.g. 0x0007");
    options.product_id = static_cast<std::uint16_t>(id);
    return Status::ok();
  }
  const auto number = parse_number(value);
  if (key == "sensor") {
    if (!number || *number < 1 || *number > 14 || *number != std::floor(*number))
      return bad("the sensor's port (bird address), 1..14");
    options.sensor = static_cast<int>(*number);
  } else if (key == "rate") {
    if (!number || *number < 20.0 || *number > 255.0) return bad("a rate in Hz, 20..255");
    options.rate_hz = *number;
  } else if (key == "range") {
    if (!number || (*number != 36.0 && *number != 72.0)) return bad("36 or 72 (inches)");
    options.long_range = *number == 72.0;
  } else if (key == "latency_ms") {
    if (!number || *number < 0.0 || *number > 1000.0) return bad("milliseconds, 0..1000");
    options.latency_s = 1e-3 * *number;
  } else {
    return Status::error("--tracker usb:trakstar: unknown option '" + std::string(key) +
                         "'; the options are sensor=1..14, rate=HZ, range=36|72, "
                         "latency_ms=MS, product=0xID");
  }
  return Status::ok();
}

}  // namespace

Result<TrakstarOptions> parse_trakstar_options(std::string_view text) {
  TrakstarOptions options;
  while (!text.empty()) {
    const std::size_t comma = text.find(',');
    const std::string_view item = text.substr(0, comma);
    text = comma == std::string_view::npos ? std::string_view() : text.substr(comma + 1);
    const std::size_t equals = item.find('=');
    if (equals == std::string_view::npos)
      return Status::error("--tracker usb:trakstar: '" + std::string(item) +
                           "' is not KEY=VALUE (e.g. usb:trakstar:sensor=2,rate=80)");
    if (Status set = set_option(options, item.substr(0, equals), item.substr(equals + 1)); !set)
      return set;
  }
  return options;
}

TrakstarPoses::TrakstarPoses(TrakstarOptions options, BirdTransportOpener opener)
    : options_(options), opener_(opener ? std::move(opener) : libusb_trakstar_opener(options)) {}

std::string TrakstarPoses::describe() const {
  std::ostringstream text;
  text << "usb:trakstar sensor " << options_.sensor << " at " << options_.rate_hz << " Hz";
  return text.str();
}

TrakstarCounts TrakstarPoses::counts() const {
  std::lock_guard lock(mutex_);
  return counts_;
}

std::string TrakstarPoses::status_line() const {
  std::lock_guard lock(mutex_);
  return status_;
}

void TrakstarPoses::count(const std::function<void(TrakstarCounts&)>& change) {
  std::lock_guard lock(mutex_);
  change(counts_);
}

void TrakstarPoses::set_status(std::string line) {
  std::lock_guard lock(mutex_);
  status_ = std::move(line);
}

Status TrakstarPoses::open() {
  if (Status connected = connect(); !connected) return connected;
  set_status("connected");
  connected_.store(true);
  return Status::ok();
}

Status TrakstarPoses::connect() {
  std::string error;
  transport_ = opener_(error);
  if (!transport_) return Status::error(describe() + ": " + error);
  if (Status configured = configure(); !configured) {
    transport_.reset();
    return configured;
  }
  return Status::ok();
}

// Range, rate and record format, then EXAMINE VALUE of the range: an answer proves the device
// speaks the Bird protocol.
Status TrakstarPoses::configure() {
  drain_input();  // what the device sent before (a reopened handle) answers nothing now
  const auto rate = static_cast<std::uint16_t>(std::lround(options_.rate_hz * 256.0));
  const std::uint16_t scaling = options_.long_range ? 1 : 0;
  const std::array commands = {
      bird::addressed(options_.sensor, bird::change_value(bird::kParamPositionScaling, scaling)),
      bird::change_value(bird::kParamMeasurementRate, rate),
      bird::addressed(options_.sensor, {bird::kPositionMatrix}),
      bird::addressed(options_.sensor, bird::examine_value(bird::kParamPositionScaling)),
  };
  for (const auto& command : commands)
    if (transport_->write(command, options_.reply_timeout_s) != UsbIo::kOk)
      return Status::error(describe() +
                           ": writing the setup commands failed (check the cable "
                           "and that no other program holds the tracker)");
  // Reads a whole packet each time: a buffer shorter than the device's packet overflows.
  std::vector<std::uint8_t> answer;
  std::array<std::uint8_t, 64> buffer{};
  const double deadline_s = clock_monotonic_s() + 5 * options_.reply_timeout_s;
  while (answer.size() < 2 && clock_monotonic_s() < deadline_s) {
    std::size_t received = 0;
    const UsbIo io = transport_->read(buffer, received, options_.reply_timeout_s);
    if (io == UsbIo::kGone || io == UsbIo::kError) break;
    answer.insert(answer.end(), buffer.begin(), buffer.begin() + static_cast<long>(received));
  }
  const std::size_t have = answer.size();
  if (have < 2 || answer[0] != scaling || answer[1] != 0)
    return Status::error(describe() +
                         ": the device does not answer the Bird protocol (EXAMINE VALUE "
                         "POSITION SCALING got " +
                         std::to_string(have) +
                         " of 2 bytes or the wrong value); is it a "
                         "trakSTAR/driveBAY, powered, with its transmitter attached?");
  return Status::ok();
}

void TrakstarPoses::drain_input() {
  std::array<std::uint8_t, 64> buffer{};
  std::size_t received = 0;
  std::size_t drained = 0;
  while (transport_->read(buffer, received, 0.002) == UsbIo::kOk && received > 0)
    drained += received;
  count([&](TrakstarCounts& c) { c.skipped_bytes += drained; });
}

// The status and counts change before connected() does: a thread that sees the tracker gone
// sees why.
void TrakstarPoses::lost(const std::string& why) {
  transport_.reset();
  next_reopen_s_ = clock_monotonic_s();
  const std::string line = why + "; waiting for the tracker to come back";
  set_status(line);
  count([](TrakstarCounts& c) { ++c.unplugged; });
  set_condition(line);  // the scan reports it while the source runs on
  connected_.store(false);
  log_warning(describe() + ": " + line);
}

Result<acquisition::Polled> TrakstarPoses::reopen() {
  const double now_s = clock_monotonic_s();
  if (now_s < next_reopen_s_) {
    std::this_thread::sleep_for(
        std::chrono::duration<double>(std::min(next_reopen_s_ - now_s, 0.05)));
    return acquisition::Polled::kNothing;
  }
  next_reopen_s_ = now_s + options_.reopen_interval_s;
  if (!connect()) return acquisition::Polled::kNothing;
  count([](TrakstarCounts& c) { ++c.reopened; });
  set_status("connected (reopened after an unplug)");
  set_condition("");
  connected_.store(true);
  log_info(describe() + ": the tracker is back; poses continue");
  return acquisition::Polled::kNothing;
}

Result<acquisition::Polled> TrakstarPoses::poll(Pose& pose) {
  if (!transport_) return reopen();
  // One POINT per measurement period: the device answers with its latest measurement.
  if (const double early_s = next_point_s_ - clock_monotonic_s(); early_s > 0.0) {
    std::this_thread::sleep_for(std::chrono::duration<double>(std::min(early_s, 0.05)));
    return acquisition::Polled::kNothing;
  }
  next_point_s_ = std::max(next_point_s_ + 1.0 / options_.rate_hz, clock_monotonic_s());
  if (drain_) {
    // The record of a POINT that timed out must not answer this one.
    drain_input();
    drain_ = false;
  }
  const auto record = point();
  if (!transport_) return acquisition::Polled::kNothing;  // unplugged during the POINT
  if (!record) {
    count([](TrakstarCounts& c) { ++c.timeouts; });
    drain_ = true;
    return acquisition::Polled::kNothing;
  }
  pose = to_pose(*record, clock_monotonic_s());
  return acquisition::Polled::kItem;
}

std::optional<std::vector<std::uint8_t>> TrakstarPoses::point() {
  const UsbIo wrote =
      transport_->write(bird::addressed(options_.sensor, {bird::kPoint}), options_.reply_timeout_s);
  if (wrote == UsbIo::kGone || wrote == UsbIo::kError) {
    lost("the tracker was unplugged (or failed) during POINT");
    return std::nullopt;
  }
  bird::RecordFramer framer(kFormat);
  std::optional<std::vector<std::uint8_t>> record;
  std::array<std::uint8_t, 64> buffer{};
  const double deadline_s = clock_monotonic_s() + options_.reply_timeout_s;
  for (bool first = true; !record && wrote == UsbIo::kOk; first = false) {
    // One read at least: a thread descheduled past the deadline must not count a timeout.
    const double left_s = deadline_s - clock_monotonic_s();
    if (left_s <= 0.0 && !first) break;
    std::size_t received = 0;
    const UsbIo io = transport_->read(buffer, received, std::max(left_s, 0.001));
    if (io == UsbIo::kGone || io == UsbIo::kError) {
      lost("the tracker was unplugged (or failed) while reading");
      return std::nullopt;
    }
    if (io == UsbIo::kStalled) count([](TrakstarCounts& c) { ++c.stalls; });
    framer.push(std::span(buffer).first(received));
    record = framer.next();
  }
  framer.clear();  // anything after the record belongs to no POINT
  count([&](TrakstarCounts& c) { c.skipped_bytes += framer.skipped_bytes(); });
  return record;
}

Pose TrakstarPoses::to_pose(const std::vector<std::uint8_t>& record, double received_s) {
  const auto words = bird::unpack_words(record);  // the framer checked the phasing
  const bird::Measurement m =
      bird::decode_record(*words, kFormat, bird::full_scale_in(options_.long_range));
  Pose pose;
  pose.timestamp_s = received_s - options_.latency_s;
  pose.T_reference_probe = m.T_tracker_sensor;
  pose.status =
      m.fault == bird::RecordFault::kNone ? TrackingStatus::kValid : TrackingStatus::kInvalid;
  count([&](TrakstarCounts& c) {
    switch (m.fault) {
      case bird::RecordFault::kNone:
        ++c.valid;
        break;
      case bird::RecordFault::kSensorNotAttached:
        ++c.not_attached;
        break;
      case bird::RecordFault::kOutOfRange:
        ++c.out_of_range;
        break;
      case bird::RecordFault::kBadRotation:
        ++c.bad_rotation;
        break;
    }
  });
  return pose;
}

void TrakstarPoses::close() {
  transport_.reset();
  connected_.store(false);
}

}  // namespace sonoshape::tracking
