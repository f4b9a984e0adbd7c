#include "bird_codec.hpp"

#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <numbers>

namespace sonoshape::tracking::bird {
namespace {

constexpr double kMmPerInch = 25.4;
constexpr double kWordScale = 32768.0;
// The largest and smallest words on the wire (the two lowest bits are not sent).
constexpr int kMaxWord = 32764;
constexpr int kMinWord = -32768;
// A decoded matrix is a rotation to the words' resolution (4 / 32768 ~ 1.2e-4 per element);
// more than this off is a corrupt record, not rounding.
constexpr double kRotationTolerance = 0.01;

std::int16_t clamp_word(double value) {
  const double rounded = std::round(value);
  return static_cast<std::int16_t>(std::clamp(rounded, double{kMinWord}, double{kMaxWord}));
}

bool is_rotation(const Eigen::Matrix3d& r) {
  const double orthonormal =
      (r.transpose() * r - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff();
  return r.allFinite() && orthonormal < kRotationTolerance && r.determinant() > 0.0;
}

// The nearest rotation to an almost-orthonormal matrix (the words are rounded).
Eigen::Matrix3d nearest_rotation(const Eigen::Matrix3d& m) {
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(m, Eigen::ComputeFullU | Eigen::ComputeFullV);
  return svd.matrixU() * svd.matrixV().transpose();
}

}  // namespace

std::size_t record_words(RecordFormat format) {
  return format == RecordFormat::kPositionAngles ? 6 : 12;
}

std::vector<std::uint8_t> addressed(int address, std::vector<std::uint8_t> command) {
  if (address > 0) command.insert(command.begin(), static_cast<std::uint8_t>(kToAddress | address));
  return command;
}

std::vector<std::uint8_t> change_value(std::uint8_t parameter, std::uint16_t value) {
  return {kChangeValue, parameter, static_cast<std::uint8_t>(value & 0xFF),
          static_cast<std::uint8_t>(value >> 8)};
}

std::vector<std::uint8_t> examine_value(std::uint8_t parameter) {
  return {kExamineValue, parameter};
}

std::vector<std::uint8_t> pack_words(std::span<const std::int16_t> words) {
  std::vector<std::uint8_t> bytes;
  bytes.reserve(2 * words.size());
  for (const std::int16_t word : words) {
    const auto bits = static_cast<std::uint16_t>(word);
    bytes.push_back(static_cast<std::uint8_t>((bits >> 2) & 0x7F));
    bytes.push_back(static_cast<std::uint8_t>((bits >> 9) & 0x7F));
  }
  if (!bytes.empty()) bytes[0] |= 0x80;
  return bytes;
}

std::optional<std::vector<std::int16_t>> unpack_words(std::span<const std::uint8_t> bytes) {
  if (bytes.empty() || bytes.size() % 2 != 0 || (bytes[0] & 0x80) == 0) return std::nullopt;
  if (std::any_of(bytes.begin() + 1, bytes.end(), [](std::uint8_t b) { return (b & 0x80) != 0; }))
    return std::nullopt;
  std::vector<std::int16_t> words;
  words.reserve(bytes.size() / 2);
  for (std::size_t i = 0; i < bytes.size(); i += 2) {
    const auto bits = static_cast<std::uint16_t>((bytes[i + 1] << 9) | ((bytes[i] & 0x7F) << 2));
    words.push_back(static_cast<std::int16_t>(bits));
  }
  return words;
}

double position_mm(std::int16_t word, double full_scale_inches) {
  return word * full_scale_inches / kWordScale * kMmPerInch;
}

std::int16_t position_word(double mm, double full_scale_inches) {
  return clamp_word(mm / kMmPerInch / full_scale_inches * kWordScale);
}

double angle_deg(std::int16_t word) { return word * 180.0 / kWordScale; }

std::int16_t angle_word(double degrees) {
  // +180 and -180 are one angle; the word holds -180 only.
  long value = std::lround(degrees * kWordScale / 180.0);
  if (value >= 32768) value -= 65536;
  return clamp_word(static_cast<double>(value));
}

double matrix_element(std::int16_t word) { return word / kWordScale; }

std::int16_t matrix_word(double value) { return clamp_word(value * kWordScale); }

const char* to_string(RecordFault fault) {
  switch (fault) {
    case RecordFault::kNone:
      return "ok";
    case RecordFault::kSensorNotAttached:
      return "sensor not attached";
    case RecordFault::kOutOfRange:
      return "out of range";
    case RecordFault::kBadRotation:
      return "bad rotation";
  }
  return "unknown";
}

Eigen::Matrix3d rotation_from_angles_deg(double azimuth, double elevation, double roll) {
  constexpr double kRad = std::numbers::pi / 180.0;
  return (Eigen::AngleAxisd(azimuth * kRad, Eigen::Vector3d::UnitZ()) *
          Eigen::AngleAxisd(elevation * kRad, Eigen::Vector3d::UnitY()) *
          Eigen::AngleAxisd(roll * kRad, Eigen::Vector3d::UnitX()))
      .toRotationMatrix();
}

Eigen::Vector3d angles_deg(const Eigen::Matrix3d& r) {
  constexpr double kDeg = 180.0 / std::numbers::pi;
  const double elevation = std::asin(std::clamp(-r(2, 0), -1.0, 1.0));
  const double azimuth = std::atan2(r(1, 0), r(0, 0));
  const double roll = std::atan2(r(2, 1), r(2, 2));
  return {azimuth * kDeg, elevation * kDeg, roll * kDeg};
}

Measurement decode_record(std::span<const std::int16_t> words, RecordFormat format,
                          double full_scale_inches) {
  Measurement out;
  if (std::all_of(words.begin(), words.end(), [](std::int16_t w) { return w == 0; })) {
    out.fault = RecordFault::kSensorNotAttached;
    return out;
  }
  for (int i = 0; i < 3; ++i) {
    if (words[i] >= kMaxWord || words[i] <= kMinWord) out.fault = RecordFault::kOutOfRange;
    out.T_tracker_sensor.translation()[i] = position_mm(words[i], full_scale_inches);
  }
  Eigen::Matrix3d r;
  if (format == RecordFormat::kPositionAngles) {
    r = rotation_from_angles_deg(angle_deg(words[3]), angle_deg(words[4]), angle_deg(words[5]));
  } else {
    // M = R^T sent column by column: the rows of R one after the other.
    for (int row = 0; row < 3; ++row)
      for (int col = 0; col < 3; ++col) r(row, col) = matrix_element(words[3 + 3 * row + col]);
    if (!is_rotation(r)) {
      out.fault = RecordFault::kBadRotation;
      return out;
    }
    r = nearest_rotation(r);
  }
  out.T_tracker_sensor.linear() = r;
  return out;
}

std::vector<std::int16_t> encode_record(const Eigen::Isometry3d& T_tracker_sensor,
                                        RecordFormat format, double full_scale_inches) {
  std::vector<std::int16_t> words;
  for (int i = 0; i < 3; ++i)
    words.push_back(position_word(T_tracker_sensor.translation()[i], full_scale_inches));
  const Eigen::Matrix3d r = T_tracker_sensor.linear();
  if (format == RecordFormat::kPositionAngles) {
    const Eigen::Vector3d angles = angles_deg(r);
    for (int i = 0; i < 3; ++i) words.push_back(angle_word(angles[i]));
  } else {
    for (int row = 0; row < 3; ++row)
      for (int col = 0; col < 3; ++col) words.push_back(matrix_word(r(row, col)));
  }
  return words;
}

void RecordFramer::push(std::span<const std::uint8_t> bytes) {
  buffer_.insert(buffer_.end(), bytes.begin(), bytes.end());
}

std::optional<std::vector<std::uint8_t>> RecordFramer::next() {
  const std::size_t size = record_bytes(format_);
  while (true) {
    // Garbage before the first phasing bit.
    const auto start = std::find_if(buffer_.begin(), buffer_.end(),
                                    [](std::uint8_t b) { return (b & 0x80) != 0; });
    skipped_ += static_cast<std::size_t>(start - buffer_.begin());
    buffer_.erase(buffer_.begin(), start);
    if (buffer_.size() < size) {
      // A phasing bit inside the partial record means it was cut short: drop it now.
      const auto again = std::find_if(buffer_.begin() + (buffer_.empty() ? 0 : 1), buffer_.end(),
                                      [](std::uint8_t b) { return (b & 0x80) != 0; });
      if (again == buffer_.end()) return std::nullopt;
      skipped_ += static_cast<std::size_t>(again - buffer_.begin());
      buffer_.erase(buffer_.begin(), again);
      continue;
    }
    const auto cut = std::find_if(buffer_.begin() + 1, buffer_.begin() + size,
                                  [](std::uint8_t b) { return (b & 0x80) != 0; });
    if (cut != buffer_.begin() + size) {
      skipped_ += static_cast<std::size_t>(cut - buffer_.begin());
      buffer_.erase(buffer_.begin(), cut);
      continue;
    }
    std::vector<std::uint8_t> record(buffer_.begin(), buffer_.begin() + size);
    buffer_.erase(buffer_.begin(), buffer_.begin() + size);
    return record;
  }
}

void RecordFramer::clear() {
  skipped_ += buffer_.size();
  buffer_.clear();
}

}  // namespace sonoshape::tracking::bird
