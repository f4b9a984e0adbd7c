// Poses as PLUS names them (issue 39): pieces of PlusLibData recordings in data/plus/ whose
// poses are ToolToTracker (older PLUS), ProbeToReference, and a TRUS stepper's chain; the image
// orientations, .mhd + .raw, calibration results and crops that come with them.
#include "sonoshape/acquisition/pose_chain.hpp"

#include <gtest/gtest.h>
#include <unistd.h>

#include <Eigen/LU>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "sonoshape/acquisition/plus_config.hpp"
#include "sonoshape/acquisition/sequence_file.hpp"

namespace sonoshape::acquisition::pose_chain_test {
namespace {

namespace fs = std::filesystem;
const fs::path kPlus = fs::path(SONOSHAPE_DATA_DIR) / "plus";

SequenceFile read(const std::string& name) {
  auto file = read_sequence_file(kPlus / name);
  EXPECT_TRUE(file) << file.message();
  return file ? std::move(*file) : SequenceFile();
}

Eigen::Matrix4d matrix(const SequenceFile& file, const std::string& name, std::size_t k) {
  const auto m = file.transform(name, k);
  EXPECT_TRUE(m) << m.message();
  return m ? *m : Eigen::Matrix4d::Identity();
}

bool contains(const std::string& text, const std::string& part) {
  return text.find(part) != std::string::npos;
}

// A scratch directory removed at the end.
struct Scratch {
  fs::path dir = fs::temp_directory_path() / ("sonoshape_pose_chain_" + std::to_string(getpid()));
  Scratch() { fs::create_directories(dir); }
  ~Scratch() { fs::remove_all(dir); }
};

TEST(TransformName, SplitsAsPlusDoes) {
  using Pair = std::pair<std::string, std::string>;
  EXPECT_EQ(split_transform_name("ToolToTracker"), Pair("Tool", "Tracker"));
  EXPECT_EQ(split_transform_name("ProbeToTrackerTransform"), Pair("Probe", "Tracker"));
  EXPECT_EQ(split_transform_name("StepperEncoderValuesToStepperHome"),
            Pair("StepperEncoderValues", "StepperHome"));
  EXPECT_FALSE(split_transform_name("ProbeToTopToTracker"));  // ambiguous
  EXPECT_FALSE(split_transform_name("Timestamp"));
  EXPECT_FALSE(split_transform_name("probeToTracker"));
}

TEST(PoseChain, OlderPlusToolToTrackerComesFromTheHeaderDefault) {
  const SequenceFile file = read("SegmentationTest_VLCUS_RandomStepperMotionData2_6frames.igs.mha");
  const auto chain = find_pose_chain(file, "vlcus.igs.mha");
  ASSERT_TRUE(chain) << chain.message();
  EXPECT_EQ(chain->from, "Tool");
  EXPECT_EQ(chain->to, "Tracker");
  EXPECT_TRUE(contains(chain->chosen_by, "DefaultFrameTransformName = ToolToTrackerTransform"));
  EXPECT_EQ(chain->describe(), "ToolToTracker = ToolToTracker (per frame)");
  // No status field: valid when readable, as PLUS wrote it.
  for (std::size_t k = 0; k < file.frame_count(); ++k) {
    const auto pose = chain->pose(file, k);
    ASSERT_TRUE(pose) << k;
    EXPECT_EQ(*pose, matrix(file, "ToolToTracker", k));
  }
}

TEST(PoseChain, ProbeToReferenceIsTakenAsItIs) {
  const SequenceFile file = read("USTC_FrameGrabber_ProbeRotationData_4frames.igs.mha");
  const auto chain = find_pose_chain(file, "ustc.igs.mha");
  ASSERT_TRUE(chain) << chain.message();
  EXPECT_EQ(chain->describe(), "ProbeToReference = ProbeToReference (per frame)");
  EXPECT_EQ(*chain->pose(file, 1), matrix(file, "ProbeToReference", 1));
}

TEST(PoseChain, StepperChainGoesThroughStepperHomeToTheTemplate) {
  const SequenceFile file = read("USTC_3NWires_ProbeRotation_3frames.igs.mha");
  const auto chain = find_pose_chain(file, "stepper.igs.mha");
  ASSERT_TRUE(chain) << chain.message();
  EXPECT_EQ(chain->chosen_by, "default");
  EXPECT_EQ(chain->describe(),
            "ProbeToTemplate = TemplateToStepperHome^-1 * ProbeToStepperHome (per frame)");
  for (std::size_t k = 0; k < file.frame_count(); ++k) {
    const Eigen::Matrix4d expected =
        matrix(file, "TemplateToStepperHome", k).inverse() * matrix(file, "ProbeToStepperHome", k);
    EXPECT_LT((*chain->pose(file, k) - expected).cwiseAbs().maxCoeff(), 1e-12) << k;
  }
  // Named on the command line: the stepper's home as the reconstruction's frame.
  const auto home = find_pose_chain(file, "stepper.igs.mha", "ProbeToStepperHomeTransform");
  ASSERT_TRUE(home) << home.message();
  EXPECT_EQ(home->chosen_by, "--pose-transform");
  EXPECT_EQ(*home->pose(file, 2), matrix(file, "ProbeToStepperHome", 2));
}

TEST(PoseChain, DeviceSetTransformsJoinTheGraphBothWays) {
  SequenceFile file;
  Eigen::Matrix4d probe_to_tracker = Eigen::Matrix4d::Identity();
  probe_to_tracker(0, 3) = 10.0;
  for (std::size_t k = 0; k < 3; ++k) {
    file.add_frame(GreyImage(4, 4));
    file.set_transform("ProbeToTracker", k, probe_to_tracker,
                       k == 1 ? TrackingStatus::kInvalid : TrackingStatus::kValid);
  }
  PlusConfig device_set;
  PlusTransform ras_to_tracker;  // stored RasToTracker: walked inverted, Tracker -> Ras
  ras_to_tracker.from = "Ras";
  ras_to_tracker.to = "Tracker";
  ras_to_tracker.matrix(1, 3) = 5.0;
  device_set.transforms.push_back(ras_to_tracker);
  const auto chain = find_pose_chain(file, "f.igs.mha", "ProbeToRas", device_set);
  ASSERT_TRUE(chain) << chain.message();
  EXPECT_EQ(chain->describe(),
            "ProbeToRas = RasToTracker^-1[device set] * ProbeToTracker (per frame and fixed)");
  EXPECT_EQ(chain->per_frame_names(), std::vector<std::string>{"ProbeToTracker"});
  const auto pose = chain->pose(file, 0);
  ASSERT_TRUE(pose);
  EXPECT_DOUBLE_EQ((*pose)(0, 3), 10.0);
  EXPECT_DOUBLE_EQ((*pose)(1, 3), -5.0);
  EXPECT_FALSE(chain->pose(file, 1));  // ProbeToTrackerTransformStatus = INVALID

  const auto missing = find_pose_chain(file, "f.igs.mha", "ProbeToPatient", device_set);
  ASSERT_FALSE(missing);
  EXPECT_TRUE(contains(missing.message(), "sequence file f.igs.mha")) << missing.message();
  EXPECT_TRUE(contains(missing.message(), "--pose-transform asks for the pose ProbeToPatient"));
  EXPECT_TRUE(contains(missing.message(), "frames reachable from Probe: Ras, Tracker"))
      << missing.message();
  const auto malformed = find_pose_chain(file, "f.igs.mha", "probe");
  ASSERT_FALSE(malformed);
  EXPECT_TRUE(contains(malformed.message(), "is not a transform name")) << malformed.message();
}

TEST(PoseChain, AHeaderDefaultWithoutAChainIsRefusedNotGuessed) {
  SequenceFile file;
  file.add_frame(GreyImage(4, 4));
  file.set_transform("CustomToTracker", 0, Eigen::Matrix4d::Identity(), TrackingStatus::kValid);
  file.set_field("DefaultFrameTransformName", "DefaultTransformToTracker");
  const auto chain = find_pose_chain(file, "f.igs.mha");
  ASSERT_FALSE(chain);
  EXPECT_TRUE(contains(chain.message(), "DefaultFrameTransformName = DefaultTransformToTracker"))
      << chain.message();
  EXPECT_TRUE(contains(chain.message(), "CustomToTracker")) << chain.message();
  // PLUS's timing test data names a placeholder that maps a frame onto itself.
  file.set_field("DefaultFrameTransformName", "IdentityToIdentityTransform");
  const auto identity = find_pose_chain(file, "f.igs.mha");
  ASSERT_FALSE(identity);
  EXPECT_TRUE(contains(identity.message(), "maps a frame onto itself")) << identity.message();
  // Without a header default and without Probe or Tool, the default search says what it tried.
  SequenceFile plain;
  plain.add_frame(GreyImage(4, 4));
  plain.set_transform("StylusToTracker", 0, Eigen::Matrix4d::Identity(), TrackingStatus::kValid);
  const auto none = find_pose_chain(plain, "f.igs.mha");
  ASSERT_FALSE(none);
  EXPECT_TRUE(contains(none.message(),
                       "none joins Probe (or Tool) to Reference, Tracker, "
                       "Template or StepperHome"))
      << none.message();
}

TEST(Orientation, MnIsTheRowMirrorOfMf) {
  const SequenceFile stored = read("USTC_FrameGrabber_ProbeRotationData_4frames.igs.mha");
  ASSERT_EQ(stored.field("UltrasoundImageOrientation"), "MN");
  SequenceFile file = stored;
  const auto flipped = reorient_to_mf(file, "ustc.igs.mha");
  ASSERT_TRUE(flipped) << flipped.message();
  EXPECT_TRUE(*flipped);
  EXPECT_EQ(file.field("UltrasoundImageOrientation"), "MF");
  const int w = file.width(), h = file.height();
  for (std::size_t k = 0; k < file.frame_count(); ++k)
    for (int j = 0; j < h; j += 7)
      for (int i = 0; i < w; i += 5)
        ASSERT_EQ(file.image(k).at(i, j), stored.image(k).at(i, h - 1 - j)) << k << " " << i;
  // MF stays as it is; UN flips both ways; RF line data (FM) is refused.
  EXPECT_FALSE(*reorient_to_mf(file, "ustc.igs.mha"));
  SequenceFile un = stored;
  un.set_field("UltrasoundImageOrientation", "UNA");
  ASSERT_TRUE(*reorient_to_mf(un, "un.igs.mha"));
  EXPECT_EQ(un.field("UltrasoundImageOrientation"), "MFA");
  EXPECT_EQ(un.image(0).at(0, 0), stored.image(0).at(w - 1, h - 1));
  EXPECT_EQ(un.image(0).at(3, 10), stored.image(0).at(w - 4, h - 11));
  SequenceFile uf = stored;
  uf.set_field("UltrasoundImageOrientation", "UF");
  ASSERT_TRUE(*reorient_to_mf(uf, "uf.igs.mha"));
  EXPECT_EQ(uf.image(0).at(3, 10), stored.image(0).at(w - 4, 10));
  SequenceFile fm = stored;
  fm.set_field("UltrasoundImageOrientation", "FM");
  const auto refused = reorient_to_mf(fm, "fm.igs.mha");
  ASSERT_FALSE(refused);
  EXPECT_TRUE(contains(refused.message(), "sequence file fm.igs.mha: UltrasoundImageOrientation"))
      << refused.message();
}

TEST(MetaImage, MhdReadsItsRawFromItsOwnFolderOnly) {
  const SequenceFile file = read("SyntheticVideoBuffer20_2frames.igs.mhd");
  ASSERT_EQ(file.frame_count(), 2u);
  EXPECT_EQ(file.width(), 320);
  std::ifstream raw(kPlus / "SyntheticVideoBuffer20_2frames.raw", std::ios::binary);
  const std::string bytes((std::istreambuf_iterator<char>(raw)), std::istreambuf_iterator<char>());
  ASSERT_EQ(bytes.size(), 2u * 320 * 240);
  EXPECT_EQ(std::string(file.image(1).pixels.begin(), file.image(1).pixels.end()),
            bytes.substr(320 * 240));
  EXPECT_DOUBLE_EQ(*file.timestamp_s(1), 1.0);

  Scratch scratch;
  auto header = [&](const std::string& data_file) {
    const fs::path path = scratch.dir / "h.mhd";
    std::ofstream(path) << "NDims = 3\nDimSize = 2 2 1\nElementType = MET_UCHAR\n"
                           "ElementDataFile = "
                        << data_file << "\n";
    return read_sequence_file(path);
  };
  std::ofstream(scratch.dir / "h.raw") << "abcd";
  const auto ok = header("h.raw");
  ASSERT_TRUE(ok) << ok.message();
  EXPECT_EQ(ok->image(0).at(1, 1), 'd');
  for (const std::string& bad : std::vector<std::string>{
           "../h.raw", (scratch.dir / "h.raw").string(), "LIST", "h%03d.raw"}) {
    const auto refused = header(bad);
    ASSERT_FALSE(refused) << bad;
    EXPECT_TRUE(contains(refused.message(), "is not a file name in the header's folder"))
        << refused.message();
  }
  const auto missing = header("h.ra");  // a misspelt name: the message lists what is there
  ASSERT_FALSE(missing);
  EXPECT_TRUE(contains(missing.message(), "ElementDataFile = h.ra: cannot open"))
      << missing.message();
  EXPECT_TRUE(contains(missing.message(), "files there with that stem: h.raw"))
      << missing.message();
}

TEST(Calibration, PlusCalibrationResultGivesImageToProbe) {
  const auto image_to_probe =
      read_image_to_probe(kPlus / "UsTemplateCalibration_3NWires.results.xml");
  ASSERT_TRUE(image_to_probe) << image_to_probe.message();
  EXPECT_DOUBLE_EQ((*image_to_probe)(0, 0), 0.147116);
  EXPECT_DOUBLE_EQ((*image_to_probe)(1, 1), -0.140886);
  EXPECT_DOUBLE_EQ((*image_to_probe)(2, 3), 159.927);
  Scratch scratch;
  const fs::path other = scratch.dir / "other.xml";
  std::ofstream(other) << "<StylusCalibrationResult/>";
  const auto refused = read_plus_config(other);
  ASSERT_FALSE(refused);
  EXPECT_TRUE(contains(refused.message(), "the root element is <StylusCalibrationResult>"))
      << refused.message();
}

TEST(Crop, ImageToCroppedImageIsOnePixelShift) {
  SequenceFile file = read("NwirePhantomFreehandCropped.igs.mha");
  const auto crop = image_to_cropped_image(file, "cropped.igs.mha");
  ASSERT_TRUE(crop) << crop.message();
  ASSERT_TRUE(*crop);
  EXPECT_DOUBLE_EQ((**crop)(0, 3), -335.0);
  EXPECT_DOUBLE_EQ((**crop)(1, 3), -285.0);
  Eigen::Matrix4d moved = **crop;
  moved(0, 3) = -300.0;
  file.set_transform("ImageToCroppedImage", 4, moved, TrackingStatus::kValid);
  const auto refused = image_to_cropped_image(file, "cropped.igs.mha");
  ASSERT_FALSE(refused);
  EXPECT_TRUE(contains(refused.message(), "frame 4: ImageToCroppedImageTransform differs"))
      << refused.message();
  EXPECT_FALSE(*image_to_cropped_image(read("USTC_3NWires_ProbeRotation_3frames.igs.mha"), "x"));
}

TEST(Timestamps, FileWithoutThemGetsOneFrameRate) {
  SequenceFile file = read("SegmentationTest_VLCUS_RandomStepperMotionData2_6frames.igs.mha");
  ASSERT_FALSE(file.timestamp_s(0));
  EXPECT_EQ(fill_missing_timestamps(file), 10.0);
  EXPECT_DOUBLE_EQ(*file.timestamp_s(3), 0.3);
  EXPECT_FALSE(fill_missing_timestamps(file));  // now it has them
  SequenceFile rated = read("SegmentationTest_VLCUS_RandomStepperMotionData2_6frames.igs.mha");
  rated.set_field("AcquisitionFrameRate", "25");
  EXPECT_EQ(fill_missing_timestamps(rated), 25.0);
  EXPECT_DOUBLE_EQ(*rated.timestamp_s(5), 0.2);
}

}  // namespace
}  // namespace sonoshape::acquisition::pose_chain_test
