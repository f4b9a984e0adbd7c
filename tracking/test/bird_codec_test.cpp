// The Bird protocol codec: word packing, phasing, scaling, records of known poses, framing.
#include "bird_codec.hpp"

#include <gtest/gtest.h>

#include <array>

namespace sonoshape::tracking::bird::bird_codec_test {
namespace {

// One position step (mm) at 36 in full scale: 4 / 32768 of 36 in (the two lowest bits are not
// sent), and its double at 72 in.
constexpr double kStep36Mm = 4.0 / 32768.0 * 36.0 * 25.4;

Eigen::Isometry3d pose(double x, double y, double z, double az, double el, double roll) {
  Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
  t.linear() = rotation_from_angles_deg(az, el, roll);
  t.translation() = Eigen::Vector3d(x, y, z);
  return t;
}

TEST(BirdWords, PackingMatchesTheManualsByteLayout) {
  // 0x1234 = 0b0001'0010'0011'0100: LS byte carries bits 8..2 (0b0001101 = 0x0D), MS byte bits
  // 15..9 (0b0001001 = 0x09); the first byte has the phasing bit.
  const std::array<std::int16_t, 2> words = {0x1234, -4};
  const auto bytes = pack_words(words);
  ASSERT_EQ(bytes.size(), 4u);
  EXPECT_EQ(bytes[0], 0x80 | 0x0D);
  EXPECT_EQ(bytes[1], 0x09);
  EXPECT_EQ(bytes[2], 0x7F);  // -4 = 0xFFFC: bits 8..2 all ones
  EXPECT_EQ(bytes[3], 0x7F);
  const auto back = unpack_words(bytes);
  ASSERT_TRUE(back);
  EXPECT_EQ((*back)[0], 0x1234);
  EXPECT_EQ((*back)[1], -4);
}

TEST(BirdWords, TheTwoLowestBitsAreLostOnTheWire) {
  const std::array<std::int16_t, 3> words = {0x1237, -32768, 32767};
  const auto back = unpack_words(pack_words(words));
  ASSERT_TRUE(back);
  EXPECT_EQ((*back)[0], 0x1234);
  EXPECT_EQ((*back)[1], -32768);
  EXPECT_EQ((*back)[2], 32764);
}

TEST(BirdWords, WrongPhasingIsRefused) {
  const std::array<std::int16_t, 2> words = {100, 200};
  auto bytes = pack_words(words);
  auto no_start = bytes;
  no_start[0] &= 0x7F;
  EXPECT_FALSE(unpack_words(no_start));
  auto second_start = bytes;
  second_start[2] |= 0x80;  // the next record began inside this one
  EXPECT_FALSE(unpack_words(second_start));
  EXPECT_FALSE(unpack_words(std::span(bytes).first(3)));  // odd length
  EXPECT_FALSE(unpack_words({}));
}

TEST(BirdScaling, PositionFullScaleIs36Or72Inches) {
  EXPECT_DOUBLE_EQ(position_mm(16384, 36.0), 18.0 * 25.4);
  EXPECT_DOUBLE_EQ(position_mm(16384, 72.0), 36.0 * 25.4);
  EXPECT_DOUBLE_EQ(position_mm(-32768, 36.0), -36.0 * 25.4);
  EXPECT_EQ(position_word(18.0 * 25.4, 36.0), 16384);
  EXPECT_EQ(position_word(18.0 * 25.4, 72.0), 8192);
  EXPECT_EQ(position_word(5000.0, 36.0), 32764);  // clamped to the largest word sent
  EXPECT_DOUBLE_EQ(angle_deg(16384), 90.0);
  EXPECT_DOUBLE_EQ(angle_deg(-32768), -180.0);
  EXPECT_EQ(angle_word(180.0), -32768);  // +180 is -180
  EXPECT_EQ(angle_word(-45.0), -8192);
}

TEST(BirdRecord, KnownPosesRoundTripInBothFormats) {
  const std::array poses = {pose(100.0, -250.0, 300.0, 30.0, -20.0, 10.0),
                            pose(-500.0, 0.5, 12.0, -170.0, 80.0, -100.0),
                            pose(0.0, 0.0, 400.0, 0.0, 0.0, 0.0)};
  for (const auto format : {RecordFormat::kPositionAngles, RecordFormat::kPositionMatrix}) {
    for (const double scale : {36.0, 72.0}) {
      for (const auto& expected : poses) {
        const auto bytes = pack_words(encode_record(expected, format, scale));
        ASSERT_EQ(bytes.size(), record_bytes(format));
        const auto words = unpack_words(bytes);
        ASSERT_TRUE(words);
        const Measurement m = decode_record(*words, format, scale);
        ASSERT_EQ(m.fault, RecordFault::kNone);
        const double step_mm = kStep36Mm * scale / 36.0;
        EXPECT_LT((m.T_tracker_sensor.translation() - expected.translation()).cwiseAbs().maxCoeff(),
                  step_mm);
        // Angles: 180 / 8192 degrees per step; matrix elements 1 / 8192.
        EXPECT_LT((m.T_tracker_sensor.linear() - expected.linear()).cwiseAbs().maxCoeff(), 1e-3);
        EXPECT_NEAR(m.T_tracker_sensor.linear().determinant(), 1.0, 1e-9);
      }
    }
  }
}

TEST(BirdRecord, MatrixRecordCarriesTheRowsOfTheRotation) {
  // Azimuth 90 degrees: the sensor's x axis points along the transmitter's y axis.
  const auto words = encode_record(pose(0, 0, 100, 90, 0, 0), RecordFormat::kPositionMatrix, 36);
  // Row 0 of R = (0, -1, 0); row 1 = (1, 0, 0).
  EXPECT_EQ(words[3], 0);
  EXPECT_EQ(words[4], -32768);
  EXPECT_EQ(words[6], 32764);
  const Measurement m = decode_record(words, RecordFormat::kPositionMatrix, 36);
  EXPECT_NEAR((m.T_tracker_sensor.linear() * Eigen::Vector3d::UnitX()).y(), 1.0, 1e-6);
}

TEST(BirdRecord, SensorNotAttachedOutOfRangeAndBadRotationAreFaults) {
  const std::vector<std::int16_t> zeros(12, 0);
  EXPECT_EQ(decode_record(zeros, RecordFormat::kPositionMatrix, 36).fault,
            RecordFault::kSensorNotAttached);
  // 1000 mm is beyond 36 in (914.4 mm) and within 72 in.
  const auto far = pose(1000.0, 0.0, 0.0, 0, 0, 0);
  EXPECT_EQ(decode_record(encode_record(far, RecordFormat::kPositionMatrix, 36),
                          RecordFormat::kPositionMatrix, 36)
                .fault,
            RecordFault::kOutOfRange);
  EXPECT_EQ(decode_record(encode_record(far, RecordFormat::kPositionMatrix, 72),
                          RecordFormat::kPositionMatrix, 72)
                .fault,
            RecordFault::kNone);
  auto sheared = encode_record(pose(10, 10, 10, 0, 0, 0), RecordFormat::kPositionMatrix, 36);
  sheared[4] = 16384;  // R(0,1) = 0.5: not orthonormal
  EXPECT_EQ(decode_record(sheared, RecordFormat::kPositionMatrix, 36).fault,
            RecordFault::kBadRotation);
  EXPECT_STREQ(to_string(RecordFault::kSensorNotAttached), "sensor not attached");
}

TEST(BirdFramer, FindsRecordsBetweenGarbageAndCutRecords) {
  const auto record =
      pack_words(encode_record(pose(50, 60, 70, 1, 2, 3), RecordFormat::kPositionAngles, 36.0));
  RecordFramer framer(RecordFormat::kPositionAngles);
  const std::array<std::uint8_t, 3> garbage = {0x01, 0x7F, 0x33};
  framer.push(garbage);
  framer.push(std::span(record).first(5));  // arrives in two pieces
  EXPECT_FALSE(framer.next());
  framer.push(std::span(record).subspan(5));
  auto got = framer.next();
  ASSERT_TRUE(got);
  EXPECT_EQ(*got, record);
  EXPECT_EQ(framer.skipped_bytes(), 3u);
  // A record cut after 4 bytes, then a whole one: the cut one is skipped.
  framer.push(std::span(record).first(4));
  framer.push(record);
  got = framer.next();
  ASSERT_TRUE(got);
  EXPECT_EQ(*got, record);
  EXPECT_EQ(framer.skipped_bytes(), 7u);
  EXPECT_FALSE(framer.next());
  framer.push(std::span(record).first(2));
  framer.clear();
  EXPECT_EQ(framer.skipped_bytes(), 9u);
}

TEST(BirdCommands, AddressedChangeAndExamineValue) {
  EXPECT_EQ(addressed(2, {kPoint}), (std::vector<std::uint8_t>{0xF2, 0x42}));
  EXPECT_EQ(addressed(0, {kPoint}), (std::vector<std::uint8_t>{0x42}));
  // 80 Hz x 256 = 20480 = 0x5000, LS byte first.
  EXPECT_EQ(change_value(kParamMeasurementRate, 20480),
            (std::vector<std::uint8_t>{0x50, 7, 0x00, 0x50}));
  EXPECT_EQ(examine_value(kParamPositionScaling), (std::vector<std::uint8_t>{0x4F, 3}));
}

}  // namespace
}  // namespace sonoshape::tracking::bird::bird_codec_test
