// Every frame of the real PLUS fCal recording (188 frames of 820x616; ~15 s, so labelled
// `long`; SegmentSweep.RealFCalRecordingEveryTenthFrame is the quick subset): at least 95% of
// the frames give a slice and the whole set passes validate_slice_set.
#include <gtest/gtest.h>

#include <filesystem>
#include <optional>
#include <stdexcept>

#include "sonoshape/acquisition/sequence_file.hpp"
#include "sonoshape/core/slice_io.hpp"
#include "sonoshape/segmentation/sweep.hpp"

namespace sonoshape::segmentation::real_recording_long_test {
namespace {

const std::filesystem::path kData = SONOSHAPE_DATA_DIR;

TEST(RealRecording, FCalEveryFrame) {
  const auto path = kData / "plus" / "fCal_Test_Calibration_3NWires.igs.mha";
  const auto file = acquisition::read_sequence_file(path);
  ASSERT_TRUE(file) << file.message();
  const auto setup = prepare_sweep(*file, path, std::optional<std::filesystem::path>{},
                                   kData / "plus" / "PlusDeviceSet_Server_Sim_NwirePhantom.xml");
  ASSERT_TRUE(setup) << setup.message();
  const SweepSegmentation result = segment_sweep(*file, *setup);
  EXPECT_EQ(result.considered, 188u);
  EXPECT_GE(result.slices.slices.size() + result.coincident, (95u * 188u + 99u) / 100u)
      << result.failed << " failed, " << result.invalid_pose << " with an INVALID pose";
  EXPECT_TRUE(result.repairs.empty());
  const Status valid = validate_slice_set(result.slices, "fCal");
  EXPECT_TRUE(valid) << valid.message();
}

}  // namespace
}  // namespace sonoshape::segmentation::real_recording_long_test
