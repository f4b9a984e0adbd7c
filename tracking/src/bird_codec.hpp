#pragma once
// The Bird protocol of the Ascension / NDI 3D Guidance trackers (trakSTAR, driveBAY), as far as
// the trakSTAR backend uses it: command bytes, the 7-bits-per-byte packing of 14-bit words,
// and the POSITION/ANGLES and POSITION/MATRIX records. No I/O here, so that it is tested
// without a device.
//
// Sources (no code copied; written from the descriptions): the Ascension "Flock of Birds
// Installation and Operation Guide" (RS-232 command reference: POINT, CHANGE VALUE, EXAMINE
// VALUE, data record formats, parameter numbers) and the protocol notes of the Apache-2.0
// ATC3DGTracker Linux driver, which sends the same commands over USB bulk endpoints 0x02 (out)
// and 0x86 (in) of vendor 0x21E2. Recalled from memory; the points that a real device must
// confirm are marked ASSUMPTION below (issue 22 leaves a `hardware` test for them).
//
// Word packing (Flock manual, "Data record format"): a 16-bit two's-complement word is sent as
// its 14 most significant bits in two bytes, LS byte first. LS byte = P B8..B2 (P, bit 7, the
// "phasing bit", is 1 in the first byte of a record and 0 in every other byte), MS byte =
// 0 B15..B9. So word = (MS << 9) | ((LS & 0x7F) << 2), and the two lowest bits are always 0.
//
// Axes (Flock manual, "Position and orientation"): positions are in the transmitter's frame as
// the device reports it (for the standard transmitter: +x out of its front face, +y to its
// right, +z down). Angles are azimuth (about z), elevation (about y), roll (about x), applied
// in that order: R_tracker_sensor = Rz(azimuth) * Ry(elevation) * Rx(roll). The MATRIX record
// sends M = R_tracker_sensor^T column by column (M11 M21 M31 M12 ...), that is the rows of
// R_tracker_sensor one after the other.
#include <Eigen/Geometry>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <vector>

namespace sonoshape::tracking::bird {

// Command bytes.
inline constexpr std::uint8_t kPoint = 0x42;           ///< 'B': send one record
inline constexpr std::uint8_t kChangeValue = 0x50;     ///< 'P' PARAM VALUE...
inline constexpr std::uint8_t kExamineValue = 0x4F;    ///< 'O' PARAM: the device answers
inline constexpr std::uint8_t kPositionAngles = 0x59;  ///< 'Y': records become POSITION/ANGLES
inline constexpr std::uint8_t kPositionMatrix = 0x5A;  ///< 'Z': records become POSITION/MATRIX
/// RS232 TO FBB: 0xF0 | address (1..14) before a command sends it to that bird (sensor).
/// ASSUMPTION: the trakSTAR addresses its sensors 1..4 this way over USB as well.
inline constexpr std::uint8_t kToAddress = 0xF0;

// Parameter numbers of CHANGE VALUE / EXAMINE VALUE (two-byte values, LS byte first).
inline constexpr std::uint8_t kParamPositionScaling = 3;  ///< 0: 36 in full scale, 1: 72 in
inline constexpr std::uint8_t kParamMeasurementRate = 7;  ///< Hz * 256

/// The record formats the backend reads.
enum class RecordFormat {
  kPositionAngles,  ///< x y z, azimuth elevation roll: 6 words, 12 bytes
  kPositionMatrix,  ///< x y z, 9 matrix elements: 12 words, 24 bytes
};

/// Words in a record of `format`.
std::size_t record_words(RecordFormat format);
/// Bytes in a record of `format` (2 per word).
inline std::size_t record_bytes(RecordFormat format) { return 2 * record_words(format); }

/// The bytes of `command` sent to the bird at `address` (1..14; 0: the master, no prefix).
std::vector<std::uint8_t> addressed(int address, std::vector<std::uint8_t> command);
/// CHANGE VALUE of a two-byte parameter.
std::vector<std::uint8_t> change_value(std::uint8_t parameter, std::uint16_t value);
/// EXAMINE VALUE of a parameter (the device answers with its value, LS byte first).
std::vector<std::uint8_t> examine_value(std::uint8_t parameter);

/// Packs 16-bit words into a record (phasing bit on the first byte). The two lowest bits of
/// each word are lost, as on the wire.
std::vector<std::uint8_t> pack_words(std::span<const std::int16_t> words);
/// Unpacks a record. None when its phasing is wrong (first byte without bit 7, or a later byte
/// with it: a record cut short or run into the next) or its length is odd.
std::optional<std::vector<std::int16_t>> unpack_words(std::span<const std::uint8_t> bytes);

/// Full scale of a position word (inches): 36, or 72 with POSITION SCALING = 1.
inline double full_scale_in(bool long_range) { return long_range ? 72.0 : 36.0; }
/// Position word to millimetres.
double position_mm(std::int16_t word, double full_scale_inches);
/// Millimetres to the nearest position word (clamped to the word's range).
std::int16_t position_word(double mm, double full_scale_inches);
/// Angle word to degrees (x 180 / 32768).
double angle_deg(std::int16_t word);
/// Degrees (-180..180) to the nearest angle word.
std::int16_t angle_word(double degrees);
/// Matrix element word to its value (x 1 / 32768).
double matrix_element(std::int16_t word);
/// A matrix element (-1..1) to its word (clamped).
std::int16_t matrix_word(double value);

/// Why a record is not a usable pose.
enum class RecordFault {
  kNone,
  /// All words zero: no sensor on that port (the sensor would be at the transmitter's centre,
  /// which is inside the transmitter). ASSUMPTION: what the device reports without a sensor;
  /// see the header comment.
  kSensorNotAttached,
  /// A position word at the end of its range: the sensor is beyond full scale (saturated).
  kOutOfRange,
  /// The angles or matrix are not a rotation (corrupt record).
  kBadRotation,
};

/// "ok", "sensor not attached", "out of range", "bad rotation".
const char* to_string(RecordFault fault);

/// A decoded record: the sensor's pose in the transmitter's frame (mm) and whether it is usable.
struct Measurement {
  Eigen::Isometry3d T_tracker_sensor = Eigen::Isometry3d::Identity();
  RecordFault fault = RecordFault::kNone;
};

/// Decodes the words of one record. `words` must hold record_words(format) words.
Measurement decode_record(std::span<const std::int16_t> words, RecordFormat format,
                          double full_scale_inches);

/// Encodes a pose as the words a device would send (the tracker emulator of the tests).
std::vector<std::int16_t> encode_record(const Eigen::Isometry3d& T_tracker_sensor,
                                        RecordFormat format, double full_scale_inches);

/// Azimuth, elevation, roll (degrees) of a rotation: R = Rz(az) Ry(el) Rx(roll).
Eigen::Vector3d angles_deg(const Eigen::Matrix3d& R_tracker_sensor);
/// The rotation of azimuth, elevation, roll (degrees).
Eigen::Matrix3d rotation_from_angles_deg(double azimuth, double elevation, double roll);

/// Finds records in a byte stream that may hold garbage or cut records: a record starts at a
/// byte with the phasing bit and runs for record_bytes(format) bytes without another one.
class RecordFramer {
 public:
  explicit RecordFramer(RecordFormat format) : format_(format) {}

  /// Appends received bytes.
  void push(std::span<const std::uint8_t> bytes);
  /// The next whole record, if one is buffered; bytes skipped on the way are counted.
  std::optional<std::vector<std::uint8_t>> next();
  /// Drops what is buffered (counted as skipped): before a new POINT, a half record is stale.
  void clear();
  /// Bytes skipped: garbage before a phasing bit, records cut short.
  std::size_t skipped_bytes() const { return skipped_; }

 private:
  RecordFormat format_;
  std::vector<std::uint8_t> buffer_;
  std::size_t skipped_ = 0;
};

}  // namespace sonoshape::tracking::bird
