#pragma once
// A trakSTAR emulator for the tests: it parses the Bird commands the backend sends and answers
// them as the device would (EXAMINE VALUE, records of known poses for POINT), with a fault
// script for POINTs: garbage bytes, stalls, a detached sensor, out of range, cut records.
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <deque>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "bird_codec.hpp"
#include "sonoshape/tracking/trakstar_source.hpp"

namespace sonoshape::tracking::test {

/// What the emulator does with one POINT.
enum class PointFault {
  kNone,
  kGarbage,     ///< three garbage bytes, then the record
  kStall,       ///< no answer (the backend times out)
  kDetached,    ///< the sensor is unplugged from the unit: an all-zero record
  kOutOfRange,  ///< the sensor is beyond the full scale: saturated position words
  kCutRecord,   ///< half a record, then the whole record
};

class BirdEmulator {
 public:
  /// The pose of the n-th POINT answered (mm, transmitter frame).
  std::function<Eigen::Isometry3d(std::size_t)> pose_of = [](std::size_t n) {
    Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
    t.linear() = bird::rotation_from_angles_deg(2.0 * static_cast<double>(n), 10.0, -5.0);
    t.translation() = Eigen::Vector3d(100.0 + static_cast<double>(n), -50.0, 200.0);
    return t;
  };
  /// Faults by POINT index (absent: none).
  std::map<std::size_t, PointFault> faults;

  /// Handles one written command; its answer is appended to the reply bytes.
  void receive(const std::vector<std::uint8_t>& bytes) {
    std::lock_guard lock(mutex_);
    std::size_t i = 0;
    if (i < bytes.size() && (bytes[i] & 0xF0) == bird::kToAddress)
      last_address_ = bytes[i++] & 0x0F;
    else
      last_address_ = 0;
    if (i >= bytes.size()) return;
    const std::uint8_t command = bytes[i];
    if (command == bird::kChangeValue && i + 3 < bytes.size()) {
      values_[bytes[i + 1]] = static_cast<std::uint16_t>(bytes[i + 2] | (bytes[i + 3] << 8));
    } else if (command == bird::kExamineValue && i + 1 < bytes.size()) {
      const std::uint16_t v = values_[bytes[i + 1]];
      reply_.push_back(static_cast<std::uint8_t>(v & 0xFF));
      reply_.push_back(static_cast<std::uint8_t>(v >> 8));
    } else if (command == bird::kPositionMatrix) {
      format_ = bird::RecordFormat::kPositionMatrix;
    } else if (command == bird::kPositionAngles) {
      format_ = bird::RecordFormat::kPositionAngles;
    } else if (command == bird::kPoint) {
      point();
    }
  }
  /// Takes up to `max` reply bytes.
  std::vector<std::uint8_t> take(std::size_t max) {
    std::lock_guard lock(mutex_);
    const std::size_t n = std::min(max, reply_.size());
    std::vector<std::uint8_t> out(reply_.begin(), reply_.begin() + static_cast<long>(n));
    reply_.erase(reply_.begin(), reply_.begin() + static_cast<long>(n));
    return out;
  }
  std::uint16_t value(std::uint8_t parameter) {
    std::lock_guard lock(mutex_);
    return values_[parameter];
  }
  int last_address() {
    std::lock_guard lock(mutex_);
    return last_address_;
  }
  /// The poses of the valid records sent, in order.
  std::vector<Eigen::Isometry3d> sent() {
    std::lock_guard lock(mutex_);
    return sent_;
  }
  std::size_t points() {
    std::lock_guard lock(mutex_);
    return points_;
  }

 private:
  void point() {
    const std::size_t n = points_++;
    const auto found = faults.find(n);
    const PointFault fault = found == faults.end() ? PointFault::kNone : found->second;
    const double scale = bird::full_scale_in(values_[bird::kParamPositionScaling] == 1);
    Eigen::Isometry3d pose = pose_of(n);
    if (fault == PointFault::kStall) return;
    if (fault == PointFault::kOutOfRange) pose.translation().x() = 2.0 * scale * 25.4;
    std::vector<std::int16_t> words = bird::encode_record(pose, format_, scale);
    round_to_wire(words);
    if (fault == PointFault::kDetached) words.assign(words.size(), 0);
    const auto record = bird::pack_words(words);
    if (fault == PointFault::kGarbage) reply_.insert(reply_.end(), {0x13, 0x00, 0x7E});
    if (fault == PointFault::kCutRecord)
      reply_.insert(reply_.end(), record.begin(), record.begin() + 7);
    reply_.insert(reply_.end(), record.begin(), record.end());
    if (fault == PointFault::kNone || fault == PointFault::kGarbage ||
        fault == PointFault::kCutRecord)
      sent_.push_back(pose);
  }

  // A device reports its measurement to the nearest value its 14-bit words carry. pack_words
  // drops the two lowest bits (truncation), which would bias every element by half a step
  // (0.056 mm at 36 in full scale) if the words were not rounded to a multiple of 4 first.
  static void round_to_wire(std::vector<std::int16_t>& words) {
    for (std::int16_t& w : words)
      w = static_cast<std::int16_t>(std::clamp(4.0 * std::round(w / 4.0), -32768.0, 32764.0));
  }

  std::mutex mutex_;
  std::map<std::uint8_t, std::uint16_t> values_;
  bird::RecordFormat format_ = bird::RecordFormat::kPositionAngles;
  std::deque<std::uint8_t> reply_;
  std::vector<Eigen::Isometry3d> sent_;
  std::size_t points_ = 0;
  int last_address_ = 0;
};

// A plugged-in tracker with an emulator behind it, as a BirdTransport; `plugged = false` makes
// every transfer and every open fail as a vanished device does.
struct FakeDevice {
  BirdEmulator emulator;
  std::atomic<bool> plugged{true};
  std::atomic<int> opens{0};
};

class FakeTransport final : public BirdTransport {
 public:
  explicit FakeTransport(FakeDevice& device) : device_(device) {}
  UsbIo write(std::span<const std::uint8_t> bytes, double) override {
    if (!device_.plugged) return UsbIo::kGone;
    device_.emulator.receive({bytes.begin(), bytes.end()});
    return UsbIo::kOk;
  }
  UsbIo read(std::span<std::uint8_t> buffer, std::size_t& received, double timeout_s) override {
    received = 0;
    if (!device_.plugged) return UsbIo::kGone;
    const auto bytes = device_.emulator.take(buffer.size());
    if (bytes.empty()) {
      std::this_thread::sleep_for(std::chrono::duration<double>(std::min(timeout_s, 0.002)));
      return UsbIo::kTimeout;
    }
    std::copy(bytes.begin(), bytes.end(), buffer.begin());
    received = bytes.size();
    return UsbIo::kOk;
  }

 private:
  FakeDevice& device_;
};

inline BirdTransportOpener opener(FakeDevice& device) {
  return [&device](std::string& error) -> std::unique_ptr<BirdTransport> {
    ++device.opens;
    if (!device.plugged) {
      error = "no tracker";
      return nullptr;
    }
    return std::make_unique<FakeTransport>(device);
  };
}

}  // namespace sonoshape::tracking::test
